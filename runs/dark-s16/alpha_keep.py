"""A negative result (runs/dark-s16/README.md, section 4): the default's output with the front bin's alpha set
back to exactly 1 where the noisy front bins of the pixel's whole 3x3 window are exactly opaque, scored by
`ranad eval`'s compositing edit (deep-Z, the held-out families glass and layers).
usage: python runs/dark-s16/alpha_keep.py SET"""
import collections
import sys

import numpy as np

import ranad_core.evaluate as ev
from ranad_core.model.store import load_model

plain = ev.denoise_window


def opaque_kept(model, images, centre, **kw):
    res = plain(model, images, centre, **kw)
    img, out = images[centre], res.image
    first, has = img.offsets[:-1], img.counts > 0
    h, w = img.height, img.width
    front = np.zeros(h * w, bool)
    front[has] = img.channel("A")[first[has]] >= 1.0
    padded = np.pad(front.reshape(h, w), 1, constant_values=True)
    window = np.ones((h, w), bool)
    for dy in range(3):
        for dx in range(3):
            window &= padded[dy:dy + h, dx:dx + w]
    keep = np.flatnonzero(window.reshape(-1) & has)
    vals = out.values.copy()
    vals[first[keep], out.channels.index("A")] = 1.0
    res.image = out.with_values(vals)
    return res


ev.denoise_window = opaque_kept
result = ev.evaluate(sys.argv[1], load_model(None).model, None, ["deepz"], None, 0, None, (0,), ("glass", "layers"))
edit = collections.defaultdict(list)
for row in result.rows:
    edit[(row["method"], row["spp"])].append(row["comp_flip"])
for (method, spp), v in sorted(edit.items()):
    if method in ("ranad", "recolour"):
        print(f"{method} {spp} spp: edit FLIP {np.nanmean(v):.4f}")
