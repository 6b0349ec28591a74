"""`ranad eval` with ranad's output brought to the flat OIDN prior's regional light (a diagnostic, session 26):
each pixel's radiance channels (all its bins alike) times g = box(L_oidn) / box(L_ranad), the two flat
luminances averaged over a (2R+1)^2 box, g clamped to [1/G, G]. Still linear in the values for a given g (the
same g would scale every AOV), but g reads OIDN. Usage: python ev_gain.py R G EVAL_ARGS..."""
import dataclasses
import sys

import numpy as np

import ranad_core.evaluate as ev
from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.lightmatch import box_mean as box   # the summed-area box mean
from ranad_core.model.prior import LUMA

real = ev.denoise_window


def gained(model, images, centre, R: int = 1, G: float = 4.0, **kw):
    res = real(model, images, centre, **kw)
    img = res.image
    luma = np.asarray(LUMA, np.float64)
    lr = np.maximum(metrics.flat_rgb(img).astype(np.float64) @ luma, 0)
    lo = np.maximum(oidn_flat(images[centre]).astype(np.float64) @ luma, 0)
    g = np.clip(box(lo, R) / np.maximum(box(lr, R), 1e-8), 1 / G, G).reshape(-1)
    vals = img.values.copy()
    per_bin = g[img.pixel_index()].astype(np.float32)
    for c in ev.radiance_channels(img.channels):
        vals[:, img.channels.index(c)] *= per_bin
    return dataclasses.replace(res, image=img.with_values(vals))


if __name__ == "__main__":   # importable (runs/generalization-s28/gain_diag.py reads box)
    import functools

    from ranad_cli.main import cli

    ev.denoise_window = functools.partial(gained, R=int(sys.argv[1]), G=float(sys.argv[2]))
    cli.main(["eval", *sys.argv[3:]])
