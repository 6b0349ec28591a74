"""A negative result (runs/dark-s16/README.md, section 4): keep alpha at exactly 1 for the front bin of pixels whose front bins in the 3x3 window all have
noisy alpha exactly 1. usage: python runs/dark-s16/alpha_keep.py SET"""
import sys, numpy as np
import ranad_core.evaluate as ev
from ranad_core.model.store import load_model
orig = ev.denoise_window
def patched(model, images, centre, **kw):
    res = orig(model, images, centre, **kw)
    img = images[centre]; out = res.image
    a = img.channel("A"); first = img.offsets[:-1]; cnt = img.counts
    h, w = img.height, img.width
    front1 = np.zeros(h * w, bool)
    has = cnt > 0
    front1[has] = a[first[has]] >= 1.0
    f = front1.reshape(h, w)
    p = np.pad(f, 1, constant_values=True)
    allw = np.ones_like(f)
    for dy in range(3):
        for dx in range(3):
            allw &= p[dy:dy + h, dx:dx + w]
    keep_px = np.flatnonzero(allw.reshape(-1) & has)
    vals = out.values.copy()
    vals[first[keep_px], out.channels.index("A")] = 1.0
    res.image = out.with_values(vals)
    return res
ev.denoise_window = patched
model = load_model(None).model
r = ev.evaluate(sys.argv[1], model, None, ["deepz"], None, 0, None, (0,), ("glass", "layers"))
import collections
d = collections.defaultdict(list)
for row in r.rows:
    d[(row["method"], row["spp"])].append(row["comp_flip"])
for k in sorted(d):
    if k[0] in ("ranad", "recolour"):
        print(k, np.nanmean(d[k]))
