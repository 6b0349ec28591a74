"""Fireflies that survive (session 25): per scene and spp, the share of covered pixels whose flat luminance is more
than 4x the reference's and above the reference frame's 99th percentile (bright outliers), and the share below 1/4 of
the reference's where the reference is above its median (dark dots), for the noisy input, ranad and flat OIDN.
Usage: python fireflies.py SET MODEL [SCENES...]"""
import sys

import numpy as np

from frames import luminances

root, spec, want = sys.argv[1], sys.argv[2], set(sys.argv[3:])
print("| scene | spp | bright: noisy | ranad | OIDN | dark: noisy | ranad | OIDN |")
print("|---|---|---|---|---|---|---|---|")
for sc, spp, lr, lums in luminances(root, spec, want):
    cov = lr > 0
    hi, med = np.percentile(lr[cov], 99), np.median(lr[cov])
    cells = []
    for kind in ("bright", "dark"):
        for lum in lums:
            bad = (lum > 4 * lr) & (lum > hi) if kind == "bright" else (lum < lr / 4) & (lr > med)
            cells.append(f"{100 * bad[cov].mean():.2f}%")
    print(f"| {sc} | {spp} | " + " | ".join(cells) + " |", flush=True)
