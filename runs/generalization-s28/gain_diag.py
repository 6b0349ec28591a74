"""Diagnostic (session 28): does ranad lose light, and would keeping each region's light as the noisy input has it
help? Flat FLIP over a set's deep-Z pairs per spp, as a ratio to flat OIDN's, of: ranad; ranad times the oracle
global gain (reference light / ranad light); ranad times g = box_R(L_noisy) / box_R(L_ranad) (clamped to [1/G, G]),
for several R. Usage: python gain_diag.py SET [MODEL]"""
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
from ranad_core.lightmatch import box_mean as box   # the summed-area box mean


model = load_model(sys.argv[2] if len(sys.argv) > 2 else None).model
luma = np.asarray(LUMA, np.float64)
RS, G = (2, 4, 8, 16, 32), 1.25
acc = collections.defaultdict(list)
for p in find_pairs([sys.argv[1]]):
    if p.kind != "deepz":
        continue
    noisy, ref = read_deep(p.noisy), read_deep(p.reference)
    fr, fo, fz = metrics.flat_rgb(ref), oidn_flat(noisy), metrics.flat_rgb(noisy)
    fn = metrics.flat_rgb(denoise_window(model, [noisy], 0).image)
    lr, ln, lz = (np.maximum(f.astype(np.float64) @ luma, 0) for f in (fr, fn, fz))
    row = [metrics.flip(fr, fo), metrics.flip(fr, fn), metrics.flip(fr, fn * (lr.mean() / max(ln.mean(), 1e-9)))]
    for r in RS:
        g = np.clip(box(lz, r) / np.maximum(box(ln, r), 1e-8), 1 / G, G)
        row.append(metrics.flip(fr, fn * g[..., None].astype(np.float32)))
    acc[p.spp].append(row + [ln.mean() / lr.mean(), lz.mean() / lr.mean()])
print("columns: ranad, oracle global gain, noisy-light gain R=" + "/".join(map(str, RS)), "(ratios to OIDN); light")
for spp in sorted(acc):
    m = np.mean(acc[spp], axis=0)
    print(sys.argv[1], spp, " ".join(f"{x / m[0]:.3f}" for x in m[1:-2]),
          f"| ranad light {m[-2]:.4f} noisy {m[-1]:.4f}")
