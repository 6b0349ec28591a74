"""Session 30 diagnostic: where does ranad lose the light of a glass scene, and could the noisy render's own light
give it back? For one deep-Z frame: ranad's flat luminance (v8, light matching on) against the reference's and the
noisy input's, box means of radius R (light matching's 16); prints the light ratios, the spread of the
box-mean gains that would restore the reference's light (oracle) and of those the noisy render suggests, and how
far each stays inside light matching's 2% clamp; then the same with a clamp from the noisy box mean's own standard
error (K standard errors, pixels taken as independent, as in a box-filtered render).
Usage: python glass_light.py NOISY.exr REFERENCE.exr [K]   (from the data folder)"""
import sys

import numpy as np

from ranad_core import metrics
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.lightmatch import CLAMP, RADIUS, box_mean
from ranad_core.model.prior import LUMA
from ranad_core.model.store import load_model

noisy, ref = read_deep(sys.argv[1]), read_deep(sys.argv[2])
k = float(sys.argv[3]) if len(sys.argv) > 3 else 2.0
model = load_model(None).model
lum = lambda img: np.maximum(np.asarray(metrics.flat_rgb(img), np.float64) @ LUMA, 0)  # noqa: E731
ln, lr = lum(noisy), lum(ref)
lo = lum(denoise_window(model, [noisy], 0).image)
print(f"light over the reference's: noisy {ln.sum() / lr.sum():.4f}, ranad {lo.sum() / lr.sum():.4f}")
bo, br, bn = (box_mean(x, RADIUS) for x in (lo, lr, ln))
ok = bo > 1e-6
oracle, hint = br[ok] / bo[ok], bn[ok] / bo[ok]
for name, g in (("oracle (reference)", oracle), ("noisy render", hint)):
    q = np.quantile(g, [0.01, 0.1, 0.5, 0.9, 0.99])
    print(f"{name:20s} gain quantiles 1/10/50/90/99%: " + " ".join(f"{v:.3f}" for v in q)
          + f"; outside the clamp: {np.mean((g > CLAMP) | (g < 1 / CLAMP)):.1%}")
h, w = ln.shape   # pixels in each box, cut at the frame's edges as box_mean cuts it
ny = np.clip(np.arange(h) + RADIUS + 1, 0, h) - np.clip(np.arange(h) - RADIUS, 0, h)
nx = np.clip(np.arange(w) + RADIUS + 1, 0, w) - np.clip(np.arange(w) - RADIUS, 0, w)
n = ny[:, None] * nx[None, :]
se = (np.sqrt(np.maximum(box_mean(ln * ln, RADIUS) - bn * bn, 0) / n) / np.maximum(bo, 1e-12))[ok]
lim = np.maximum(CLAMP - 1, k * se)
g_se = np.clip(hint, 1 - lim, 1 + lim)
g_02 = np.clip(hint, 1 / CLAMP, CLAMP)
w = bo[ok] / bo[ok].sum()   # light-weighted error of the gains against the oracle's
for name, g in (("2% clamp", g_02), (f"{k:g} standard errors", g_se)):
    print(f"{name:20s} light after: {(g * bo[ok]).sum() / br[ok].sum():.4f}, light-weighted |gain - oracle| "
          f"{(w * np.abs(g - oracle)).sum():.4f}")
print(f"(no gain: light {bo[ok].sum() / br[ok].sum():.4f}, |1 - oracle| {(w * np.abs(1 - oracle)).sum():.4f}; the "
      f"box means of ranad's own output already carry light matching)")
