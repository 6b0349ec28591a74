"""`ranad ...` with the layer gate's strength (reconstruction.GATE_STRENGTH, lambda = strength / half-width^2)
set to K for this process: the sensitivity check of README.md.

Usage: python runs/layer-gate-s14/eval_strength.py K eval SET -o OUT --model M [options of ranad eval]"""
import sys

import ranad_core.model.reconstruction as reconstruction

reconstruction.GATE_STRENGTH = float(sys.argv[1])
from ranad_cli.main import cli  # noqa: E402

cli.main(sys.argv[2:], standalone_mode=True)
