"""glass_grid.png (session 25): heldout_g1w4_r4k scenes 0 and 6 at 4 and 64 spp (rows), columns the noisy input,
v7's output, the 4096-spp reference and flat OIDN, tone-mapped x / (1 + x) with gamma 2.2, each pixel 2 x 2; prints
each column's flat FLIP against the reference. Usage (in the data folder): python glass_grid.py OUT.png"""
import sys

import numpy as np
import OpenImageIO as oiio

from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model

model = load_model("cpu-small-pdl-gza-v7").model
rows = []
for sc in ("scene_0000", "scene_0006"):
    for spp in (4, 64):
        noisy = read_deep(f"heldout_g1w4_r4k/{sc}/deepz/noisy_spp{spp}.0000.exr")
        ref = read_deep(f"heldout_g1w4_r4k/{sc}/deepz/reference_spp{spp}.0000.exr")
        out = denoise_window(model, [noisy], 0).image
        flats = [metrics.flat_rgb(x) for x in (noisy, out, ref)] + [oidn_flat(noisy)]
        rows.append(np.concatenate([np.clip((np.maximum(f, 0) / (1 + np.maximum(f, 0))) ** (1 / 2.2), 0, 1)
                                    for f in flats], 1))
        print(sc, spp, [round(float(metrics.flip(flats[2], f)), 4) for f in flats])
img = np.repeat(np.repeat(np.concatenate(rows, 0).astype(np.float32), 2, 0), 2, 1)
dst = oiio.ImageOutput.create(sys.argv[1])
dst.open(sys.argv[1], oiio.ImageSpec(img.shape[1], img.shape[0], 3, "uint8"))
dst.write_image(img)
dst.close()
