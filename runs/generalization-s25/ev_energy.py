"""`ranad eval` with energy-normalised reconstruction kernels (a diagnostic, session 25): for the layers named, each
noisy value is divided by the total weight the layer's reconstruction gives it over all outputs (its column sum,
from autograd of the output's sum, floored at CMIN) before the reconstruction runs, so the output's sum over the
bins equals the input's (up to the floor) and a bright bin's energy goes to the bins that read it, in proportion,
instead of being averaged away. Still linear in the values. Usage: python ev_energy.py CMIN LAYERS EVAL ARGS..."""
import sys

import torch

from ranad_core.model.ranad import RaNAD

cmin, which = float(sys.argv[1]), sys.argv[2].split(",")
real = RaNAD.reconstruct_layer


def normalised(self, name, emb, inputs, values):
    if name not in which:
        return real(self, name, emb, inputs, values)
    with torch.enable_grad():
        v = values.detach().clone().requires_grad_(True)
        out = real(self, name, emb.detach(), inputs, v)
        c = torch.autograd.grad(out.sum(), v)[0]
    return real(self, name, emb, inputs, values / c.clamp(min=cmin))


RaNAD.reconstruct_layer = normalised
torch.inference_mode = lambda *a, **k: torch.no_grad()   # tensors autograd may use (the same values otherwise)
from ranad_cli.main import cli  # noqa: E402
cli.main(["eval", *sys.argv[3:]])
