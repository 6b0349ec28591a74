"""`ranad eval` with one output layer left as the noisy input (a diagnostic, session 24): which layer's kernels make
the glass scenes worse than their input at high spp. Usage: python ev_keep_layer.py LAYER EVAL ARGS...
(LAYER: diffuse, specular, alpha or depth; the model's reconstruction of it is replaced by its noisy values)"""
import sys

from ranad_core.model.ranad import RaNAD

layer = sys.argv[1]
real = RaNAD.reconstruct_layer
RaNAD.reconstruct_layer = lambda self, name, emb, inputs, values: (
    values if name == layer else real(self, name, emb, inputs, values))

from ranad_cli.main import cli  # noqa: E402

cli.main(["eval", *sys.argv[2:]])
