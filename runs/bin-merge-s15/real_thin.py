"""Thin bins in other renderers' real files: how many ranad denoise merges (default gap), how far apart the members
are in depth, their alphas and how much their unpremultiplied colours (G) differ from their group's mean.
usage: real_thin.py FILE.exr ..."""
import sys

import numpy as np

from ranad_core import binmerge
from ranad_core.exr import read_deep

for path in sys.argv[1:]:
    img = read_deep(path)
    srt, perm = img.sorted()
    g = binmerge.groups_of(srt, img, perm)
    if g is None:
        print(f"{path}: no thin bins")
        continue
    idx = g.index
    a = srt.channel("A").astype(np.float64)
    col = srt.channel("G").astype(np.float64)
    z = srt.channel("Z").astype(np.float64)
    seen = a > 1e-3
    un = np.where(seen, col / np.maximum(a, 1e-3), 0.0)
    sizes = np.bincount(idx)
    multi = sizes[idx] > 1
    same = np.r_[False, idx[1:] == idx[:-1]]
    gap = (z[1:] - z[:-1])[same[1:]] / np.maximum(z[:-1][same[1:]], 1e-9)
    mean = np.bincount(idx, un * seen) / np.maximum(np.bincount(idx, seen.astype(float)), 1)
    spread = (np.abs(un - mean[idx]) / np.maximum(np.abs(mean[idx]), 1e-6))[multi & seen]
    share = 100 * (1 - g.merged / img.num_bins)
    print(f"{path}: {img.num_bins - g.merged} of {img.num_bins} bins merge away ({share:.1f}%),"
          f" groups of up to {sizes.max()}; depth gap median {np.median(gap):.4f}; member alpha median "
          f"{np.median(a[multi]):.3f}; colour spread median {np.median(spread):.3f}, 90th percentile "
          f"{np.percentile(spread, 90):.3f}")
