"""Kernel reuse for AOVs: 16 light groups denoised with the cached kernels, against the primary denoise pass and
against denoising each light group separately (a primary pass per group), all in the same run.

The frame is the bundled example's centre frame tiled to SIZE x SIZE; its beauty is split per bin into 16 light
groups with random positive shares (so they sum to the beauty, as real light groups do).
Usage: python bench/aov.py [--size 256] [--groups 16] [--model M] [--threads 2]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def main() -> None:
    from ranad_core import heap

    heap.keep_freed_memory()   # as the ranad CLI does
    import torch

    from denoise import tile_to  # bench/denoise.py
    from ranad_core.aov import aov_layers, denoise_aovs
    from ranad_core.channels import detect
    from ranad_core.denoise import denoise_window
    from ranad_core.exr import read_deep
    from ranad_core.model.store import load_model

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--groups", type=int, default=16)
    ap.add_argument("--model", default=None)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    src = read_deep(os.path.join(ROOT, "examples", "synth_shot", "noisy_spp16.0001.exr"))
    img = tile_to(src, a.size, a.size)
    keep = [c for c in img.channels if not c.startswith("lg_")]
    img = img.select(keep)
    rng = np.random.default_rng(0)
    shares = rng.dirichlet(np.ones(a.groups), size=img.num_bins).astype(np.float32)     # [N, G]
    rgb = img.values[:, [img.channels.index(c) for c in "RGB"]]
    names = [f"lg_{g:02d}.{c}" for g in range(a.groups) for c in "RGB"]
    cols = (shares[:, :, None] * rgb[:, None, :]).reshape(img.num_bins, -1)
    img = img.with_values(np.concatenate([img.values, cols], 1), keep + names)
    model = load_model(a.model).model
    mapping = detect(img)
    layers = aov_layers(img.channels, "lg_*")
    denoise_window(model, [img], 0)                       # warm-up (kernel build, allocator)

    t = time.perf_counter()
    res = denoise_window(model, [img], 0, mapping, want_embeddings=True)
    primary = time.perf_counter() - t
    t = time.perf_counter()
    out = denoise_aovs(model, [img], 0, mapping, layers, res.embeddings, res.perms, res.offsets, None, res.merge_gap,
                       res.merges, res.split, res.dark_radius, res.gain)
    reuse = time.perf_counter() - t
    t = time.perf_counter()
    for g in range(a.groups):                              # each group as the beauty of its own primary pass
        vals = img.values.copy()
        for i, c in enumerate("RGB"):
            vals[:, img.channels.index(c)] = cols[:, 3 * g + i]
        single = img.with_values(vals).select(["R", "G", "B", "A", "Z", "ZBack", "albedo.R", "albedo.G",
                                               "albedo.B", "N.X", "N.Y", "N.Z"])
        denoise_window(model, [single], 0)
    separate = time.perf_counter() - t
    lg = sum(out[k] for k in layers)
    err = np.abs(lg - res.image.values[:, [res.image.channels.index(c) for c in "RGB"]]).max()
    print(f"{a.size}x{a.size}, {img.num_bins} bins, {a.groups} light groups, {a.threads} threads")
    print(f"  primary denoise pass          {primary:7.2f} s  (1.00x)")
    print(f"  + {a.groups} groups, kernel reuse   {reuse:7.2f} s  ({reuse / primary:.2f}x the primary pass; "
          f"primary + groups = {(primary + reuse) / primary:.2f}x)")
    print(f"  {a.groups} groups denoised separately {separate:7.2f} s  ({separate / primary:.2f}x the primary pass)")
    print(f"  max |sum of denoised groups - denoised beauty| = {err:.2e}")


if __name__ == "__main__":
    main()
