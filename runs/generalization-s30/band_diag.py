"""Session 30 diagnostic: at which spatial scales is ranad's error larger than flat OIDN's? The flat luminance
error (denoised - reference, tone-mapped by L / (1 + L) so that highlights do not dominate) split into bands by
differences of box means (radius 0 | 1 | 3 | 8 | 16 | beyond), its energy summed over the set's deep-Z frames at
one spp; prints the energy of each band for ranad (the default, light matching on) and OIDN and their ratio.
Usage: python band_diag.py SET SPP [MODEL]   (from the data folder)"""
import sys

import numpy as np

from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.lightmatch import box_mean
from ranad_core.model.prior import LUMA
from ranad_core.model.store import load_model
from ranad_core.train.data import find_pairs

RADII = (1, 3, 8, 16)


def bands(err: np.ndarray) -> list:
    """Energies of err in the bands between successive box means (the first: err minus its 3x3 mean)."""
    levels = [err] + [box_mean(err, r) for r in RADII]
    out = [float(((levels[i] - levels[i + 1]) ** 2).sum()) for i in range(len(RADII))]
    return out + [float((levels[-1] ** 2).sum())]


def tone(rgb: np.ndarray) -> np.ndarray:
    lum = np.maximum(np.asarray(rgb, np.float64) @ LUMA, 0)
    return lum / (1 + lum)


model = load_model(sys.argv[3] if len(sys.argv) > 3 else None).model
spp = int(sys.argv[2])
tot = {"ranad": np.zeros(len(RADII) + 1), "oidn": np.zeros(len(RADII) + 1), "noisy": np.zeros(len(RADII) + 1)}
for p in find_pairs([sys.argv[1]]):
    if p.kind != "deepz" or p.spp != spp:
        continue
    noisy, ref = read_deep(p.noisy), read_deep(p.reference)
    tr = tone(metrics.flat_rgb(ref))
    outs = {"ranad": metrics.flat_rgb(denoise_window(model, [noisy], 0).image), "oidn": oidn_flat(noisy),
            "noisy": metrics.flat_rgb(noisy)}
    for name, img in outs.items():
        tot[name] += bands(tone(img) - tr)
labels = ["<1 px", "1-3 px", "3-8 px", "8-16 px", ">16 px"]
print(f"{sys.argv[1]} {spp} spp: band energies (x1e3) ranad / OIDN / noisy, ratio ranad/OIDN")
for i, lab in enumerate(labels):
    print(f"  {lab:8s} {tot['ranad'][i] * 1e3:9.3f} {tot['oidn'][i] * 1e3:9.3f} {tot['noisy'][i] * 1e3:9.3f}  "
          f"{tot['ranad'][i] / tot['oidn'][i]:.3f}")
