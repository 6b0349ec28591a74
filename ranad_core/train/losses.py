"""Losses (paper Sec. 5): SMAPE on the bins of each radiance layer; on the composited (flattened) colour, SMAPE
plus an SSIM term on the tone-mapped image (structure the per-pixel terms miss: blotches, lost edges); L1 on
alpha and relative L1 on depth; optionally (weight 0 by default) depth-separation terms: SMAPE (`separation`) and
the SSIM term (`separation_ssim`) of the composites of the bins in front of and behind the crop's median reference
depth, each flattened alone, which is what a compositor's holdout or insertion sees (colour moved between depth
layers, wrong alpha; blotches within one layer that the full composite hides); and (weight 0 by default) the
compositing edit itself, as `ranad eval` scores it (metrics.composite_edit): the front bins recoloured, a
semi-transparent layer inserted at the median depth, then flattened; SMAPE (`edit`) and the SSIM term
(`edit_ssim`) on it. The edit weighs the front composite's alpha (how much of the inserted layer and the back shows
through), which the per-bin alpha L1 and the separation terms see only indirectly. For cross-frame
training on consecutive frames, a temporal term: L1 between the change of the tone-mapped composite from one frame
to the next and the reference's change (the flicker that `ranad eval --temporal` measures). And (weight 0 by
default) `composite_grad`: L1 between the tone-mapped composite's differences of neighbouring pixels and the
reference's, the fine detail (an edge seen through a pane) that FLIP weighs and that the SMAPE terms trade for
residual noise once the noise is low (runs/generalization-s24, section 4). And (weight 0 by default)
`composite_coarse`: SMAPE between the linear composites averaged over blocks of 4 x 4 and 8 x 8 pixels, which
charges energy a prediction loses (a firefly or caustic speckle dimmed rather than spread over its neighbours: the
held-out glass scenes lost 4-31% of their input's energy, runs/generalization-s25) while the per-pixel terms
cannot tell a dimmed speckle from a kept one. And (weight 0 by default) `flip`: HDR-FLIP of the composite
(flip_loss.py), the perceptual difference `ranad eval` scores, which charges low-frequency blotches in smooth
regions that the per-pixel terms hardly see (runs/generalization-s28); `edit_flip` the same on the compositing
edit's image, the figure the issue's edit targets are set in."""

from __future__ import annotations

import torch

from ..deep import flatten_torch
from ..metrics import INSERT_ALPHA, INSERT_COLOUR, RECOLOUR_GAIN, ssim, tonemap
from .flip_loss import hdr_flip
from .weights import WEIGHTS


def smape(pred: torch.Tensor, target: torch.Tensor, eps: float = 1e-2) -> torch.Tensor:
    return ((pred - target).abs() / (pred.abs() + target.abs() + eps)).mean()


def gradient_l1(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Mean L1 between the horizontal and vertical differences of neighbouring pixels of two [C, H, W] images."""
    dx = (a[:, :, 1:] - a[:, :, :-1]) - (b[:, :, 1:] - b[:, :, :-1])
    dy = (a[:, 1:, :] - a[:, :-1, :]) - (b[:, 1:, :] - b[:, :-1, :])
    return (dx.abs().mean() + dy.abs().mean()) / 2


def coarse_smape(a: torch.Tensor, b: torch.Tensor, blocks: tuple = (4, 8)) -> torch.Tensor:
    """Mean over the block sizes of SMAPE between two [C, H, W] images averaged over blocks of that many pixels a
    side (partial blocks at the edges averaged over the pixels they hold)."""
    pool = lambda x, k: torch.nn.functional.avg_pool2d(x[None], k, k, ceil_mode=True)[0]  # noqa: E731
    return sum(smape(pool(a, k), pool(b, k)) for k in blocks) / len(blocks)


def composite_rgba(layers: dict, offsets: torch.Tensor) -> torch.Tensor:
    """Flattened colour and alpha [P, 4] of diffuse + specular (premultiplied) with alpha, front to back."""
    rgb = layers["diffuse"] + layers["specular"]
    return flatten_torch(torch.cat([rgb, layers["alpha"]], dim=1), offsets, 3)


def composite(layers: dict, offsets: torch.Tensor) -> torch.Tensor:
    """Flattened colour [P, 3] (composite_rgba without its alpha)."""
    return composite_rgba(layers, offsets)[:, :3]


def depth_slices(pred: dict, ref: dict, offsets: torch.Tensor) -> list:
    """[(pred, ref)] composites [P, 4] (colour, alpha) of the bins in front of and behind the crop's median
    reference depth, each flattened alone (the split follows the reference so both sides hold the same bins): what
    a compositor's holdout or insertion sees."""
    z = ref["depth"][:, 0]
    front = (z < torch.quantile(z, 0.5)).to(z.dtype)[:, None]   # the median as metrics.split_depth takes it
    return [(composite_rgba(_masked(pred, m), offsets), composite_rgba(_masked(ref, m), offsets))
            for m in (front, 1 - front)]


def separation(slices: list) -> torch.Tensor:
    """Mean SMAPE of the front and back composites' colour (depth_slices)."""
    return sum(smape(p[:, :3], r[:, :3]) for p, r in slices) / len(slices)


def edit_image(front: torch.Tensor, back: torch.Tensor, scale: float = 1.0) -> torch.Tensor:
    """[P, 3]: metrics.composite_edit from the two depth_slices composites [P, 4] of one image: the front
    recoloured, then over the inserted layer, then over the back. `scale`: the frame's exposure scale; the colours
    are divided by it first, so the inserted layer sits at the same place relative to the scene's brightness
    whatever the render's exposure."""
    gain = front.new_tensor(RECOLOUR_GAIN)
    layer = front.new_tensor(INSERT_COLOUR)
    behind = layer + (1 - INSERT_ALPHA) * back[:, :3] / scale
    return gain * front[:, :3] / scale + (1 - front[:, 3:4]) * behind


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
    # [P, 3] per pixel -> [3, h, w] planes; tone-mapped for the image terms
    planes = lambda x: x.T.reshape(3, h, w)  # noqa: E731
    shaped = lambda x: planes(tonemap(x))  # noqa: E731
    img = lambda x: shaped(x / scale)  # noqa: E731
    structure = h >= 4 and w >= 4                             # SSIM needs its window
    wants = {k: weights[k] > 0 and (structure or not k.endswith("ssim"))
             for k in ("separation", "separation_ssim", "edit", "edit_ssim", "edit_flip")}
    if any(wants.values()):
        slices = depth_slices(pred, ref, offsets)
        if wants["separation"]:
            parts["separation"] = separation(slices)
        if wants["separation_ssim"]:
            parts["separation_ssim"] = sum(1 - ssim(img(p[:, :3]), img(r[:, :3])) for p, r in slices) / len(slices)
        if wants["edit"] or wants["edit_ssim"] or wants["edit_flip"]:
            (fp, fr), (bp, br) = slices
            ep, er = edit_image(fp, bp, scale), edit_image(fr, br, scale)
            if wants["edit"]:
                parts["edit"] = smape(ep, er)
            if wants["edit_ssim"]:
                parts["edit_ssim"] = 1 - ssim(shaped(ep), shaped(er))   # edit_image divided by scale already
            if wants["edit_flip"]:
                parts["edit_flip"] = hdr_flip(planes(er), planes(ep))
    cp, cr = composite(pred, offsets), composite(ref, offsets)
    parts["composite"] = smape(cp, cr)
    grad = weights["composite_grad"] > 0 and h >= 2 and w >= 2
    if weights["composite_coarse"] > 0:
        parts["composite_coarse"] = coarse_smape(planes(cp), planes(cr))
    if weights["flip"] > 0:
        parts["flip"] = hdr_flip(planes(cr / scale), planes(cp / scale))
    if structure or grad:
        ip, ir = img(cp), img(cr)                              # tone-mapped once for both image terms
        if structure:
            parts["composite_ssim"] = 1 - ssim(ip, ir)
        if grad:
            parts["composite_grad"] = gradient_l1(ip, ir)
    loss = sum(weights[k] * v for k, v in parts.items())
    return loss, {k: v.item() for k, v in parts.items()}


def temporal_loss(preds: list, refs: list, offsets: list) -> torch.Tensor:
    """|(T(o[1]) - T(o[0])) - (T(r[1]) - T(r[0]))| averaged over pixels, T the tone map, o and r the composites of
    two consecutive frames' outputs and references (same crop): penalises flicker the reference does not have,
    not a static error."""
    out = [tonemap(composite(p, o)) for p, o in zip(preds, offsets)]
    ref = [tonemap(composite(r, o)) for r, o in zip(refs, offsets)]
    return ((out[1] - out[0]) - (ref[1] - ref[0])).abs().mean()
