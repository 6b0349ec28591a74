"""Where a model's compositing-edit error comes from: the edit HDR-FLIP (metrics.composite_edit, as `ranad eval`
scores it) of the model's output with one part replaced by the reference's: every bin's alpha; the colour of the
single-bin pixels; of the multi-bin pixels; of the bins in front of / behind the split depth. The larger the drop
from the model's own score, the more of the error that part holds. Deep-Z, the scenes of one set.

Usage: python runs/cpu-small-pd-g4-t1/oracle.py DATASET MODEL SPP   (e.g. heldout_g1u cpu-small-pd-v2 16)
"""
import glob
import os
import sys

import numpy as np

from ranad_core.channels import ALPHA, DEPTH, RGB
from ranad_core.denoise import denoise_frame
from ranad_core.exr import read_deep
from ranad_core.metrics import composite_edit, flip, split_depth, with_depths_of
from ranad_core.model.store import load_model


def swapped(img, ref, mask: np.ndarray, channels) -> object:
    """`img` with `channels` of the bins in `mask` taken from `ref` (same bin layout)."""
    vals = img.values.copy()
    for c in channels:
        vals[mask, img.channels.index(c)] = ref.channel(c)[mask]
    return img.with_values(vals)


def main(dataset: str, model_name: str, spp: str) -> None:
    model = load_model(model_name).model
    totals, n = {}, 0
    for scene in sorted(glob.glob(os.path.join(dataset, "scene_*"))):
        noisy = read_deep(f"{scene}/deepz/noisy_spp{spp}.0000.exr")
        ref = read_deep(f"{scene}/deepz/reference_spp{spp}.0000.exr")
        out = with_depths_of(denoise_frame(model, noisy).image, ref)   # as the eval scores the edit
        z = split_depth(ref)
        counts = np.diff(ref.offsets)
        multi, front = np.repeat(counts > 1, counts), ref.channel(DEPTH) < z
        every = np.ones(ref.num_bins, bool)
        cases = {"model": out, "ref alpha": swapped(out, ref, every, [ALPHA]),
                 "ref colour single-bin px": swapped(out, ref, ~multi, RGB),
                 "ref colour multi-bin px": swapped(out, ref, multi, RGB),
                 "ref colour front": swapped(out, ref, front, RGB), "ref colour back": swapped(out, ref, ~front, RGB)}
        target = composite_edit(ref, z)
        row = {k: flip(target, composite_edit(v, z)) for k, v in cases.items()}
        print(os.path.basename(scene), f"multi-bin pixels {np.mean(counts > 1):.2f}",
              " | ".join(f"{k} {v:.4f}" for k, v in row.items()), flush=True)
        for k, v in row.items():
            totals[k] = totals.get(k, 0.0) + v
        n += 1
    print("mean", " | ".join(f"{k} {v / max(n, 1):.4f}" for k, v in totals.items()))


if __name__ == "__main__":
    main(*sys.argv[1:4])
