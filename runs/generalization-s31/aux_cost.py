"""What the prefiltered guides would cost the flat prior at 1080p: OIDN's albedo and normal filters and the beauty
filter with cleanAux, against the plain beauty filter, on the held-out 1080p frame's flattened images (the inputs
prior.flat_images gives OIDN), each timed in this process after one warm-up run of each.

Usage: python aux_cost.py FRAME (bench/denoise.py's make_1080p output)"""
import sys
import time
from pathlib import Path

import numpy as np
import pyoidn

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from ranad_core.baselines import composite_groups, prefiltered  # noqa: E402
from ranad_core.channels import ALBEDO, NORMAL  # noqa: E402
from ranad_core.exr import read_deep  # noqa: E402
from ranad_core.model.prior import beauty  # noqa: E402

img, _ = read_deep(sys.argv[1]).sorted()
h, w = img.height, img.width
flat, alb, nrm = composite_groups(img, [(np.maximum(beauty(img), 0), True), (img.columns(list(ALBEDO)), False),
                                        (img.columns(list(NORMAL)), False)])
im = lambda x: np.ascontiguousarray(x.reshape(h, w, 3), np.float32)  # noqa: E731
colour, albedo, normal = im(flat), im(np.clip(alb, 0, 1)), im(np.clip(nrm, -1, 1))
jobs = {"beauty (raw guides)": lambda: pyoidn.denoise(colour, albedo, normal, hdr=True),
        "albedo filter": lambda: prefiltered(pyoidn, "albedo", albedo),
        "normal filter": lambda: prefiltered(pyoidn, "normal", normal),
        "beauty (cleanAux)": lambda: pyoidn.denoise(colour, albedo, normal, hdr=True, clean_aux=True)}
for name, job in jobs.items():
    job()
    t = time.perf_counter()
    job()
    print(f"{name}: {time.perf_counter() - t:.2f} s")
