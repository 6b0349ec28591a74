"""Denoising a deep frame with a RaNAD model: the model's layers go back into the file's channels.

The model sees bins front to back (its bin-index encoding assumes it); results are put back in the file's bin
order, so the output has exactly the input's pixels, bins, order, ids and header. Denoised channels: the
diffuse and specular layers, alpha (A) and depth (Z; ZBack keeps each bin's thickness); the beauty R, G, B is
rebuilt as diffuse + specular + emission (emission passes through). Every denoised value is a softmax-weighted
average of noisy values of the same layer, so alpha stays in [0, 1] and depth within the neighbourhood's range.
"""

from __future__ import annotations

import numpy as np
import torch

from .deep import DeepImage, unsort
from .model.inputs import prepare

RADIANCE = ("diffuse", "specular")


def denoise_frame(model, img: DeepImage) -> DeepImage:
    """The denoised image (same layout and channels as `img`); `model` is a RaNAD in eval mode."""
    srt, perm = img.sorted()
    if srt.num_bins == 0:
        return img
    inputs = prepare(srt)
    with torch.inference_mode():
        out = {k: v.numpy() for k, v in model(inputs).items()}
    vals = srt.values.copy()
    ch = srt.channels
    for layer in RADIANCE:
        names = [f"{layer}.{c}" for c in "RGB"]
        if layer in out and all(n in ch for n in names):
            vals[:, [ch.index(n) for n in names]] = out[layer]
    if all(f"{layer}.{c}" in ch for layer in RADIANCE for c in "RGB") and all(c in ch for c in "RGB"):
        rgb = out["diffuse"] + out["specular"]
        if all(f"emission.{c}" in ch for c in "RGB"):
            rgb = rgb + srt.values[:, [ch.index(f"emission.{c}") for c in "RGB"]]
        vals[:, [ch.index(c) for c in "RGB"]] = rgb
    if "alpha" in out and "A" in ch:
        vals[:, ch.index("A")] = np.clip(out["alpha"][:, 0], 0, 1)
    if "depth" in out and "Z" in ch:
        z_old = srt.values[:, ch.index("Z")]
        z_new = np.maximum(out["depth"][:, 0], 0)
        vals[:, ch.index("Z")] = z_new
        if "ZBack" in ch:
            zb = ch.index("ZBack")
            vals[:, zb] = z_new + np.maximum(srt.values[:, zb] - z_old, 0)
    return img.with_values(unsort(vals, perm))
