"""How far ranad's output moves when a file's guide conventions differ from `ranad synth`'s (world-space unit
normals, the first surface's albedo): the same noisy frames with their guides rewritten, scored against the same
references. Variants: base (as rendered); rot (normals turned by one fixed random rotation: camera-space
normals, or another world up); n01 (normals stored as 0.5 n + 0.5, the [0, 1] encoding some pipelines write);
alb1 (albedo 1 everywhere: renderers without a denoising albedo AOV that write white). OIDN gets the unchanged
guides (its score is the baseline only).

    python runs/production-renders-s19/probe.py DATASET [--model M] [--scenes N] [--spp 4,16]
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.channels import ALBEDO, NORMAL
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model
from ranad_core.train.data import find_pairs

VARIANTS = ("base", "rot", "n01", "alb1")


def rotation(seed: int = 5) -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q.astype(np.float32)


def variant(img, name: str, rot: np.ndarray):
    """`img` with its guides rewritten as variant `name` says (unpremultiplied guides, as ranad synth writes)."""
    if name == "base":
        return img
    vals, ch = img.values.copy(), list(img.channels)
    normal, albedo = [ch.index(c) for c in NORMAL], [ch.index(c) for c in ALBEDO]
    if name == "rot":
        vals[:, normal] = vals[:, normal] @ rot.T
    elif name == "n01":
        vals[:, normal] = vals[:, normal] * 0.5 + 0.5
    elif name == "alb1":
        vals[:, albedo] = 1.0
    return img.with_values(vals)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset")
    ap.add_argument("--model", default=None)
    ap.add_argument("--scenes", type=int, default=8)
    ap.add_argument("--spp", default="4,16")
    ap.add_argument("--kind", default="deepz")
    args = ap.parse_args()
    torch.set_num_threads(2)
    model = load_model(args.model).model
    spps = [int(s) for s in args.spp.split(",")]
    pairs = [p for p in find_pairs(args.dataset) if p.kind == args.kind and p.spp in spps]
    scenes = sorted({p.scene for p in pairs})[:args.scenes]
    rot = rotation()
    rows = {n: [] for n in ("oidn",) + VARIANTS}
    for p in (p for p in pairs if p.scene in scenes):
        noisy, ref = read_deep(p.noisy), read_deep(p.reference)
        z, flat_ref = metrics.split_depth(ref), metrics.flat_rgb(ref)
        rows["oidn"].append((p.spp, metrics.flip(flat_ref, oidn_flat(noisy)), np.nan))
        for name in VARIANTS:
            out = denoise_window(model, [variant(noisy, name, rot)], 0).image
            rows[name].append((p.spp, metrics.flip(flat_ref, metrics.flat_rgb(out)),
                               metrics.deep_scores(ref, out, z)["comp_flip"]))
    print(f"{args.dataset}: {len(scenes)} scenes, {args.kind}; mean flat FLIP / edit FLIP per spp")
    print("| variant | " + " | ".join(f"{s} spp" for s in spps) + " |")
    print("|---|" + "---|" * len(spps))
    for name, r in rows.items():
        a = np.array(r)
        cells = [f"{a[a[:, 0] == s, 1].mean():.4f} / {a[a[:, 0] == s, 2].mean():.4f}" for s in spps]
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
