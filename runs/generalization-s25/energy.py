"""Where the glass scenes' energy goes (session 25): per scene and spp, the flat luminance summed over the pixels a
4096-spp (or the set's) reference shows bright (above its median over covered pixels) and over the whole frame, for
the noisy input, ranad and flat OIDN, each over the reference's. Usage: python energy.py SET MODEL [SCENES...]"""
import os
import sys

import numpy as np

from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model

LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
root, spec = sys.argv[1], sys.argv[2]
want = set(sys.argv[3:])
model = load_model(spec).model
print("| scene | spp | bright region: noisy | ranad | OIDN | frame: noisy | ranad | OIDN |")
print("|---|---|---|---|---|---|---|---|")
for sc in sorted(os.listdir(root)):
    if want and sc not in want or not os.path.isdir(os.path.join(root, sc, "deepz")):
        continue
    for spp in (4, 16, 64):
        p = os.path.join(root, sc, "deepz", f"noisy_spp{spp}.0000.exr")
        if not os.path.exists(p):
            continue
        noisy = read_deep(p)
        ref = read_deep(os.path.join(root, sc, "deepz", f"reference_spp{spp}.0000.exr"))
        out = denoise_window(model, [noisy], 0).image
        lr = metrics.flat_rgb(ref) @ LUMA
        bright = lr > np.median(lr[lr > 0])
        lums = [f @ LUMA for f in (metrics.flat_rgb(noisy), metrics.flat_rgb(out), oidn_flat(noisy))]
        cells = ([f"{x[bright].sum() / lr[bright].sum():.3f}" for x in lums]
                 + [f"{x.sum() / lr.sum():.3f}" for x in lums])
        print(f"| {sc} | {spp} | " + " | ".join(cells) + " |", flush=True)
