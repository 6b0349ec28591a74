"""`ranad eval` with ranad run twice (a diagnostic, session 27): the second pass denoises the first pass's output
(radiance channels replaced by the first pass's, every other channel of the noisy frame kept), with weight B of
the first output and 1 - B of the noisy values in its input. Still linear in the noisy values (two kernels in a
row), so AOV reuse would hold if both kernels were cached. Usage: python ev_twice.py B EVAL_ARGS..."""
import dataclasses
import sys

import numpy as np

import ranad_core.evaluate as ev

B = float(sys.argv[1])
real = ev.denoise_window


def twice(model, images, centre, **kw):
    res = real(model, images, centre, **kw)
    noisy, out = images[centre], res.image
    assert out.values.shape[0] == noisy.values.shape[0], "the first pass changed the bin layout"
    vals = noisy.values.copy()
    for c in ev.radiance_channels(noisy.channels):
        i, j = noisy.channels.index(c), out.channels.index(c)
        vals[:, i] = B * out.values[:, j] + (1 - B) * noisy.values[:, i]
    second = real(model, [noisy.with_values(vals)], 0, **kw)
    return second


ev.denoise_window = twice
from ranad_cli.main import cli  # noqa: E402
cli.main(["eval", *sys.argv[2:]])
