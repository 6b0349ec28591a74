"""Fireflies that survive (session 25): per scene and spp, the share of covered pixels whose flat luminance is more
than 4x the reference's and above the reference frame's 99th percentile (bright outliers), and the share below 1/4 of
the reference's where the reference is above its median (dark dots), for the noisy input, ranad and flat OIDN.
Usage: python fireflies.py SET MODEL [SCENES...]"""
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
print("| scene | spp | bright: noisy | ranad | OIDN | dark: noisy | ranad | OIDN |")
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
        cov = lr > 0
        hi, med = np.percentile(lr[cov], 99), np.median(lr[cov])
        cells = []
        for kind in ("bright", "dark"):
            for f in (metrics.flat_rgb(noisy), metrics.flat_rgb(out), oidn_flat(noisy)):
                lum = f @ LUMA
                bad = (lum > 4 * lr) & (lum > hi) if kind == "bright" else (lum < lr / 4) & (lr > med)
                cells.append(f"{100 * bad[cov].mean():.2f}%")
        print(f"| {sc} | {spp} | " + " | ".join(cells) + " |", flush=True)
