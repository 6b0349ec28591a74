"""Diagnostic (session 29): would taking the low frequencies of ranad's flat image from flat OIDN's (its prior) help?
Flat FLIP over a set's deep-Z pairs per spp, as a ratio to flat OIDN's, of ranad times g = box_R(L_oidn) /
box_R(L_ranad) (luminance, clamped to [1/G, G]) and of ranad times the same ratio per RGB channel, for several R.
A per-pixel gain keeps every bin a (scaled) combination of the noisy values, so AOV reuse and sums stay exact.
Usage: python lf_diag.py SET [MODEL|-] [G]   (G: the clamp, default 1.5; - for the default model)"""
import sys
import collections
import numpy as np
from ranad_core.exr import read_deep
from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.denoise import denoise_window
from ranad_core.train.data import find_pairs
from ranad_core.model.store import load_model
from ranad_core.model.prior import LUMA

from ranad_core.lightmatch import box_mean as box  # the product's summed-area box mean

model = load_model(sys.argv[2] if len(sys.argv) > 2 and sys.argv[2] != "-" else None).model
luma = np.asarray(LUMA, np.float64)
RS = (1, 2, 4, 8, 16)
G = float(sys.argv[3]) if len(sys.argv) > 3 else 1.5
acc = collections.defaultdict(list)
for p in find_pairs([sys.argv[1]]):
    if p.kind != "deepz":
        continue
    noisy, ref = read_deep(p.noisy), read_deep(p.reference)
    fr, fo = metrics.flat_rgb(ref), oidn_flat(noisy)
    fn = metrics.flat_rgb(denoise_window(model, [noisy], 0, light_match=False).image)   # as before lightmatch
    lo, ln = (np.maximum(f.astype(np.float64) @ luma, 0) for f in (fo, fn))
    row = [metrics.flip(fr, fo), metrics.flip(fr, fn)]
    for r in RS:
        g = np.clip(box(lo, r) / np.maximum(box(ln, r), 1e-8), 1 / G, G)
        row.append(metrics.flip(fr, fn * g[..., None].astype(np.float32)))
    for r in RS:
        g = np.stack([np.clip(box(np.maximum(fo[..., c], 0).astype(np.float64), r)
                              / np.maximum(box(np.maximum(fn[..., c], 0).astype(np.float64), r), 1e-8), 1 / G, G)
                      for c in range(3)], -1)
        row.append(metrics.flip(fr, fn * g.astype(np.float32)))
    acc[p.spp].append(row)
print("columns: ranad, luminance gain R=" + "/".join(map(str, RS)), "| RGB gain R=" + "/".join(map(str, RS)),
      "(ratios to OIDN)")
for spp in sorted(acc):
    m = np.mean(acc[spp], axis=0)
    k = len(RS)
    print(sys.argv[1], spp, f"{m[1] / m[0]:.3f} |", " ".join(f"{x / m[0]:.3f}" for x in m[2:2 + k]), "|",
          " ".join(f"{x / m[0]:.3f}" for x in m[2 + k:]))
