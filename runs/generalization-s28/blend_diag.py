"""Diagnostic (session 28): flat FLIP of (1-a) ranad + a OIDN (linear blend of the flat images), mean over a set's
deep-Z scenes per spp, divided by flat OIDN's. Usage: python blend_diag.py SET [MODEL]"""
import sys
import collections
import numpy as np
from ranad_core.exr import read_deep
from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.denoise import denoise_window
from ranad_core.train.data import find_pairs
from ranad_core.model.store import load_model

model = load_model(sys.argv[2] if len(sys.argv) > 2 else None).model
alphas = (0.0, 0.25, 0.5, 0.75, 1.0)
acc = collections.defaultdict(list)
for p in find_pairs([sys.argv[1]]):
    if p.kind != "deepz":
        continue
    noisy, ref = read_deep(p.noisy), read_deep(p.reference)
    fr = metrics.flat_rgb(ref)
    fo = oidn_flat(noisy)
    fn = metrics.flat_rgb(denoise_window(model, [noisy], 0).image)
    scores = [metrics.flip(fr, (1 - a) * fn + a * fo) for a in alphas]
    acc[p.spp].append(scores + [metrics.flip(fr, metrics.flat_rgb(noisy))])
for spp in sorted(acc):
    m = np.mean(acc[spp], axis=0)
    print(sys.argv[1], spp, "ratio to OIDN by a=" + "/".join(map(str, alphas)),
          " ".join(f"{x / m[-2]:.3f}" for x in m[:-1]), f"| OIDN {m[-2]:.4f} noisy {m[-1]:.4f}")
