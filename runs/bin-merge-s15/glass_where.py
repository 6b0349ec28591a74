"""Where the default's flat FLIP loses to the noisy input on one family: the per-pixel HDR-FLIP maps of noisy and
denoised against the reference, summed by the reference pixel's luminance band (black, the dimmest non-black
half, the brighter non-black half, the brightest 10% of non-black pixels). usage: glass_where.py SET SPP FAMILY"""
import json
import sys
from pathlib import Path

import flip_evaluator
import numpy as np

from ranad_core import metrics
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model

root, spp, family = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
model = load_model(None).model
bands = {"black": [0, 0, 0], "dim half": [0, 0, 0], "bright half": [0, 0, 0], "brightest 10%": [0, 0, 0]}


def flip_map(ref, test):
    ref32, test32 = (np.ascontiguousarray(np.maximum(x, 0), np.float32) for x in (ref, test))
    return np.asarray(flip_evaluator.evaluate(ref32, test32, "HDR", applyMagma=False)[0]).reshape(ref.shape[:2])


for scene in sorted(root.glob("scene_*")):
    if json.loads((scene / "manifest.json").read_text())["preset"] != family:
        continue
    noisy = read_deep(scene / f"deepz/noisy_spp{spp}.0000.exr")
    ref = metrics.flat_rgb(read_deep(scene / f"deepz/reference_spp{spp}.0000.exr"))
    fn = flip_map(ref, metrics.flat_rgb(noisy))
    fd = flip_map(ref, metrics.flat_rgb(denoise_window(model, [noisy], 0).image))
    lum = ref.mean(-1)
    lit = lum > 0
    mid, top = (np.quantile(lum[lit], [0.5, 0.9]) if lit.any() else (0.0, 0.0))
    masks = {"black": ~lit, "dim half": lit & (lum <= mid), "bright half": lit & (lum > mid) & (lum <= top),
             "brightest 10%": lit & (lum > top)}
    for name, mask in masks.items():
        bands[name][0] += int(mask.sum())
        bands[name][1] += float(fn[mask].sum())
        bands[name][2] += float(fd[mask].sum())
excess = sum(b[2] - b[1] for b in bands.values())
for name, (n, sn, sd) in bands.items():
    print(f"{name:14s} {n:7d} px: FLIP noisy {sn / max(n, 1):.3f}, ranad {sd / max(n, 1):.3f}; "
          f"share of ranad's excess {(sd - sn) / excess:+.2f}")
