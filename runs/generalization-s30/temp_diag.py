"""Session 30 diagnostic: are the reconstruction's kernels too peaky on renders unlike the training data? Runs
`ranad eval` with every reconstruction kernel's logits, all but the relative-position bias, scaled by T (q times T,
which carries the range and gate columns too): T < 1 flattens the kernels, so that blotches from kernels that
average too few neighbours in smooth regions would shrink, at the edges' expense.

Usage: python temp_diag.py T SET OUT [ranad eval options...]   (from the data folder)"""
import sys

import torch

from ranad_core.model import reconstruction

T = float(sys.argv[1])
_rana = reconstruction.rana


def tempered(q, k, v, *args, **kwargs):
    return _rana(q * T, k, v, *args, **kwargs)


reconstruction.rana = tempered
torch.set_num_threads(2)
from ranad_cli.main import cli  # noqa: E402

sys.argv = ["ranad", "eval", sys.argv[2], "-o", sys.argv[3], "--held-out", "glass,layers,interior,fog",
            "--grid", "0", *sys.argv[4:]]
cli(prog_name="ranad")
