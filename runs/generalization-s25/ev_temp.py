"""`ranad eval` with the reconstruction kernels' content logits scaled by TAU (a diagnostic, session 25): every
KernelAttention's q projection times TAU (the relative-position bias and the layer gate's terms unchanged), in the
layers named (comma list of output layer names, or "all"). Usage: python ev_temp.py TAU LAYERS EVAL ARGS..."""
import sys

import torch

import ranad_core.model.store as store
from ranad_core.model.reconstruction import KernelAttention

tau, which = float(sys.argv[1]), sys.argv[2]
real = store.load_model


def load(*a, **k):
    loaded = real(*a, **k)
    n = 0
    with torch.no_grad():
        for name, mod in loaded.model.named_modules():
            if isinstance(mod, KernelAttention) and (which == "all" or any(f".{w}." in f".{name}." for w in
                                                                           which.split(","))):
                mod.q.weight.mul_(tau)
                mod.q.bias.mul_(tau)
                n += 1
    print(f"scaled {n} kernel modules by {tau}", file=sys.stderr)
    return loaded


store.load_model = load
from ranad_cli.main import cli  # noqa: E402
cli.main(["eval", *sys.argv[3:]])
