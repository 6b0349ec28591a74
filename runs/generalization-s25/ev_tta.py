"""`ranad eval` with ranad's output averaged over K flips of the input (test-time ensemble; a diagnostic, session 25).
Usage: python ev_tta.py K EVAL ARGS...   (K: 1, 2 = identity + flip x, 4 = the four flips)"""
import sys
import numpy as np
import ranad_core.evaluate as ev
from ranad_core.train.data import transform

K = int(sys.argv[1])
FLIPS = [(False, False), (True, False), (False, True), (True, True)][:K]
real = ev.denoise_window


def ensembled(model, images, centre, **kw):
    first = None
    acc = None
    for fx, fy in FLIPS:
        if not (fx or fy):
            res = real(model, images, centre, **kw)
            out = res.image
        else:
            img = images[centre]
            t = transform(img, fx, fy, False)
            t.header, t.data_window, t.display_window = img.header, img.data_window, img.display_window
            o = real(model, [t], 0, **kw).image
            back = transform(o, fx, fy, False)
            assert np.array_equal(back.offsets, img.offsets) and back.channels == o.channels
            out = back
        if first is None:
            first, acc = res, out.values.astype(np.float64)
            base = out
        else:
            assert out.channels == base.channels and np.array_equal(out.offsets, base.offsets)
            acc += out.values
    base.values = (acc / len(FLIPS)).astype(np.float32)
    return first


ev.denoise_window = ensembled
from ranad_cli.main import cli  # noqa: E402
cli.main(["eval", *sys.argv[2:]])
