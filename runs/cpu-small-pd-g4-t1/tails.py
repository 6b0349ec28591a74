"""Outlier tails of the flattened image: per-pixel |log1p(lum / s) - log1p(lum_ref / s)| (s: the reference's median
luminance) at the 99th and 99.9th percentile, its maximum and the share of pixels above 0.5, for ranad, flat OIDN
and the noisy input, per scene of a set (deep-Z). Whether fireflies or dark dots survive more than OIDN's.

Usage: python runs/cpu-small-pd-g4-t1/tails.py DATASET MODEL SPP   (e.g. heldout_g1u cpu-small-pd-v1 16)
"""
import glob
import os
import sys

import numpy as np

from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.denoise import denoise_frame
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model

LUMA = np.array([0.2126, 0.7152, 0.0722])


def main(dataset: str, model_name: str, spp: str) -> None:
    model = load_model(model_name).model
    for scene in sorted(glob.glob(os.path.join(dataset, "scene_*"))):
        noisy = read_deep(f"{scene}/deepz/noisy_spp{spp}.0000.exr")
        ref = metrics.flat_rgb(read_deep(f"{scene}/deepz/reference_spp{spp}.0000.exr")) @ LUMA
        s = np.median(ref[ref > 0]) if (ref > 0).any() else 1.0
        outs = {"ranad": metrics.flat_rgb(denoise_frame(model, noisy).image), "oidn": oidn_flat(noisy),
                "noisy": metrics.flat_rgb(noisy)}
        cols = []
        for name, img in outs.items():
            e = np.abs(np.log1p(np.maximum(img @ LUMA, 0) / s) - np.log1p(np.maximum(ref, 0) / s)).ravel()
            cols.append(f"{name}: p99 {np.quantile(e, 0.99):.3f} p99.9 {np.quantile(e, 0.999):.3f} "
                        f"max {e.max():.2f} >0.5 {(e > 0.5).mean() * 1e3:.1f}/1000")
        print(os.path.basename(scene), " | ".join(cols))


if __name__ == "__main__":
    main(*sys.argv[1:4])
