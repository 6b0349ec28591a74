"""The measured tile halo of a model: the smallest halo whose tiled output matches the whole frame.

The default halo is the receptive-field bound (denoise.receptive_field: every attention radius on the longest
path added up, 80 px for cpu-small), which no trained model comes near: attention weights fall off long before
the disc edges. Every pixel of halo is computed again by the neighbouring tile, so a tight halo is the cheapest
speed-up there is. `measure_halo` denoises frames whole and in small tiles with growing halos and returns the
first halo (a multiple of denoise.ALIGN) whose output matches the whole frame's: every bin's difference relative
to its own magnitude plus its channel's mean magnitude, at most MEAN_TOL on average and MAX_TOL at worst (relative
to the channel mean alone, a bright bin of a dim channel, a specular highlight, turned its 1e-4 rounding into
"7%"). Even the bound does not match exactly: tiles of other sizes sum in another order, and the float16 rounding
of the embeddings (the AOV cache's precision) turns those 1e-7 differences into 1e-3 ones in a few bins (measured
on cpu-small-p-v1, 128x128 held-out frames: at the bound, mean 1.5e-6, worst 7e-3; with no halo, mean 2e-3 to
6e-3, worst 2 to 45). `ranad export --measure-halo FRAMES` stores the halo in the model's metadata ("halo"), which
denoise.halo_for then uses.

A cross-frame model is measured on single-frame windows; what those skip (the T-Mix blocks' radii and the temporal
kernel steps', once, or twice with the output mix) is added to the measured halo before it is rounded up to ALIGN.
"""

from __future__ import annotations

import math

import numpy as np

MEAN_TOL = 1e-5       # mean relative difference: a few times the bound's own rounding noise, 1/200 of no halo
MAX_TOL = 0.01        # worst bin: 1% of its value (a seam moves bins by their whole magnitude)


def mismatch(tiled: np.ndarray, whole: np.ndarray) -> tuple[float, float]:
    """(mean, worst) of |tiled - whole| / (|whole| + the channel's mean magnitude) over bins and channels."""
    if not whole.size:
        return 0.0, 0.0
    whole = whole.astype(np.float64)
    scale = np.abs(whole) + np.maximum(np.abs(whole).mean(axis=0), 1e-6)
    d = np.abs(tiled.astype(np.float64) - whole) / scale
    return float(d.mean()), float(d.max())


def measure_halo(model, images: list, tile: int = 32, progress=None) -> tuple[int, list]:
    """(the smallest halo that matches on every image, [(halo, worst mean mismatch, worst bin)] per halo tried)."""
    from .denoise import ALIGN, denoise_frame, halo_for_bound, temporal_reach

    bound = halo_for_bound(model)
    wholes = [denoise_frame(model, img).image.values for img in images]
    extra = temporal_reach(model)   # what the single-frame windows measured here skip
    tried = []
    for halo in range(ALIGN, bound + 1, ALIGN):
        found = [mismatch(denoise_frame(model, img, tile=tile, halo=halo).image.values, whole)
                 for img, whole in zip(images, wholes)]
        mean, worst = max(f[0] for f in found), max(f[1] for f in found)
        tried.append((halo, mean, worst))
        if progress:
            progress(halo, mean, worst)
        if mean <= MEAN_TOL and worst <= MAX_TOL:
            return min(bound, int(math.ceil((halo + extra) / ALIGN) * ALIGN)), tried
    return bound, tried
