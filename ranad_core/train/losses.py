"""Losses (paper Sec. 5): SMAPE on the bins of each radiance layer; on the composited (flattened) colour, SMAPE
plus an SSIM term on the tone-mapped image (structure the per-pixel terms miss: blotches, lost edges); L1 on
alpha and relative L1 on depth; optionally (weight 0 by default) depth-separation terms: SMAPE (`separation`) and
the SSIM term (`separation_ssim`) of the composites of the bins in front of and behind the crop's median reference
depth, each flattened alone, which is what a compositor's holdout or insertion sees (colour moved between depth
layers, wrong alpha; blotches within one layer that the full composite hides). For cross-frame
training on consecutive frames, a temporal term: L1 between the change of the tone-mapped composite from one frame
to the next and the reference's change (the flicker that `ranad eval --temporal` measures)."""

from __future__ import annotations

import torch

from ..deep import flatten_torch
from ..metrics import ssim, tonemap
from .weights import WEIGHTS


def smape(pred: torch.Tensor, target: torch.Tensor, eps: float = 1e-2) -> torch.Tensor:
    return ((pred - target).abs() / (pred.abs() + target.abs() + eps)).mean()


def composite(layers: dict, offsets: torch.Tensor) -> torch.Tensor:
    """Flattened colour [P, 3] of diffuse + specular (premultiplied) with alpha, front to back."""
    rgb = layers["diffuse"] + layers["specular"]
    values = torch.cat([rgb, layers["alpha"]], dim=1)
    return flatten_torch(values, offsets, 3)[:, :3]


def depth_slices(pred: dict, ref: dict, offsets: torch.Tensor) -> list:
    """[(pred, ref)] composites [P, 3] of the bins in front of and behind the crop's median reference depth, each
    flattened alone (the split follows the reference so both sides hold the same bins): what a compositor's
    holdout or insertion sees."""
    z = ref["depth"][:, 0]
    front = (z < torch.quantile(z, 0.5)).to(z.dtype)[:, None]   # the median as metrics.split_depth takes it
    return [(composite(_masked(pred, m), offsets), composite(_masked(ref, m), offsets)) for m in (front, 1 - front)]


def separation(slices: list) -> torch.Tensor:
    """Mean SMAPE of the front and back composites (depth_slices)."""
    return sum(smape(p, r) for p, r in slices) / len(slices)


def _masked(layers: dict, mask: torch.Tensor) -> dict:
    """The colour and alpha layers with the bins outside `mask` made empty (transparent black)."""
    return {k: layers[k] * mask for k in ("diffuse", "specular", "alpha")}


def total_loss(pred: dict, ref: dict, offsets: torch.Tensor, size: tuple[int, int],
               scale: float = 1.0, weights: dict | None = None) -> tuple[torch.Tensor, dict]:
    """`scale`: the frame's exposure scale; the SSIM term tone-maps the composite divided by it (so the loss, like
    the other terms, does not depend on the render's brightness). `weights`: overrides of WEIGHTS by name; terms
    of weight 0 are not computed."""
    weights = {**WEIGHTS, **(weights or {})}
    h, w = size
    parts = {"diffuse": smape(pred["diffuse"], ref["diffuse"]), "specular": smape(pred["specular"], ref["specular"]),
             "alpha": (pred["alpha"] - ref["alpha"]).abs().mean(),
             "depth": ((pred["depth"] - ref["depth"]).abs() / (ref["depth"].abs() + 1e-3)).mean()}
    img = lambda x: tonemap(x / scale).T.reshape(3, h, w)  # noqa: E731
    structure = h >= 4 and w >= 4                             # SSIM needs its window
    if weights["separation"] > 0 or (weights["separation_ssim"] > 0 and structure):
        slices = depth_slices(pred, ref, offsets)
        if weights["separation"] > 0:
            parts["separation"] = separation(slices)
        if weights["separation_ssim"] > 0 and structure:
            parts["separation_ssim"] = sum(1 - ssim(img(p), img(r)) for p, r in slices) / len(slices)
    cp, cr = composite(pred, offsets), composite(ref, offsets)
    parts["composite"] = smape(cp, cr)
    if structure:
        parts["composite_ssim"] = 1 - ssim(img(cp), img(cr))
    loss = sum(weights[k] * v for k, v in parts.items())
    return loss, {k: v.item() for k, v in parts.items()}


def temporal_loss(preds: list, refs: list, offsets: list) -> torch.Tensor:
    """|(T(o[1]) - T(o[0])) - (T(r[1]) - T(r[0]))| averaged over pixels, T the tone map, o and r the composites of
    two consecutive frames' outputs and references (same crop): penalises flicker the reference does not have,
    not a static error."""
    out = [tonemap(composite(p, o)) for p, o in zip(preds, offsets)]
    ref = [tonemap(composite(r, o)) for r, o in zip(refs, offsets)]
    return ((out[1] - out[0]) - (ref[1] - ref[0])).abs().mean()
