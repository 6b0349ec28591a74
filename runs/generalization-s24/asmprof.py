"""cProfile of denoise._assemble on one frame (session 24 investigation).
Usage: python asmprof.py FRAME.exr [DENOISE OPTIONS]"""
import cProfile, pstats, sys
import ranad_core.denoise as D
real = D._assemble
def wrapped(*a, **k):
    pr = cProfile.Profile(); pr.enable()
    try:
        return real(*a, **k)
    finally:
        pr.disable(); pstats.Stats(pr).sort_stats("tottime").print_stats(8)
D._assemble = wrapped
from ranad_cli.main import cli
try:
    cli.main(["denoise", sys.argv[1], "-o", "/tmp/asm_out.exr"] + sys.argv[2:], standalone_mode=False)
except SystemExit:
    pass
