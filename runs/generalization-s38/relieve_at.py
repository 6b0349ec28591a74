"""`ranad` with heap.RELIEVE_AT set: python relieve_at.py FRACTION ranad-arguments... (session 38's memory runs)."""
import sys
import ranad_core.heap as heap
heap.RELIEVE_AT = float(sys.argv[1])
from ranad_cli.main import main
sys.argv = ["ranad"] + sys.argv[2:]
main()
