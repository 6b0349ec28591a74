"""Where the glass scenes' energy goes (session 25): per scene and spp, the flat luminance summed over the pixels a
4096-spp (or the set's) reference shows bright (above its median over covered pixels) and over the whole frame, for
the noisy input, ranad and flat OIDN, each over the reference's. Usage: python energy.py SET MODEL [SCENES...]"""
import sys

import numpy as np

from frames import luminances

root, spec, want = sys.argv[1], sys.argv[2], set(sys.argv[3:])
print("| scene | spp | bright region: noisy | ranad | OIDN | frame: noisy | ranad | OIDN |")
print("|---|---|---|---|---|---|---|---|")
for sc, spp, lr, lums in luminances(root, spec, want):
    bright = lr > np.median(lr[lr > 0])
    cells = [f"{x[bright].sum() / lr[bright].sum():.3f}" for x in lums] + [f"{x.sum() / lr.sum():.3f}" for x in lums]
    print(f"| {sc} | {spp} | " + " | ".join(cells) + " |", flush=True)
