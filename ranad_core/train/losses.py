"""Losses (paper Sec. 5): SMAPE on the bins of each radiance layer; on the composited (flattened) colour, SMAPE
plus an SSIM term on the tone-mapped image (structure the per-pixel terms miss: blotches, lost edges); L1 on
alpha and relative L1 on depth."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ..deep import flatten_torch

WEIGHTS = {"diffuse": 1.0, "specular": 1.0, "composite": 1.0, "composite_ssim": 0.5, "alpha": 0.5, "depth": 0.2}


def smape(pred: torch.Tensor, target: torch.Tensor, eps: float = 1e-2) -> torch.Tensor:
    return ((pred - target).abs() / (pred.abs() + target.abs() + eps)).mean()


def composite(layers: dict, offsets: torch.Tensor) -> torch.Tensor:
    """Flattened colour [P, 3] of diffuse + specular (premultiplied) with alpha, front to back."""
    rgb = layers["diffuse"] + layers["specular"]
    values = torch.cat([rgb, layers["alpha"]], dim=1)
    return flatten_torch(values, offsets, 3)[:, :3]


def _gaussian(size: int = 7, sigma: float = 1.5) -> torch.Tensor:
    x = torch.arange(size, dtype=torch.float32) - (size - 1) / 2
    g = torch.exp(-x * x / (2 * sigma * sigma))
    return g / g.sum()


def ssim(a: torch.Tensor, b: torch.Tensor, data_range: float = 1.0) -> torch.Tensor:
    """Mean SSIM of two [C, H, W] images (Gaussian window 7x7, sigma 1.5, borders reflected)."""
    c = a.shape[0]
    g = _gaussian().to(a)
    win = (g[:, None] * g[None, :]).expand(c, 1, -1, -1)
    pad = win.shape[-1] // 2

    def blur(x):
        return F.conv2d(F.pad(x[None], (pad,) * 4, mode="reflect" if min(x.shape[1:]) > pad else "replicate"),
                        win, groups=c)[0]

    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    ma, mb = blur(a), blur(b)
    va, vb, cov = blur(a * a) - ma * ma, blur(b * b) - mb * mb, blur(a * b) - ma * mb
    s = ((2 * ma * mb + c1) * (2 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2))
    return s.mean()


def tonemap(rgb: torch.Tensor) -> torch.Tensor:
    """HDR -> [0, 1): x / (1 + x), so highlights do not dominate and darks keep their detail."""
    x = rgb.clamp(min=0)
    return x / (1 + x)


def total_loss(pred: dict, ref: dict, offsets: torch.Tensor, size: tuple[int, int]) -> tuple[torch.Tensor, dict]:
    h, w = size
    parts = {"diffuse": smape(pred["diffuse"], ref["diffuse"]), "specular": smape(pred["specular"], ref["specular"]),
             "alpha": (pred["alpha"] - ref["alpha"]).abs().mean(),
             "depth": ((pred["depth"] - ref["depth"]).abs() / (ref["depth"].abs() + 1e-3)).mean()}
    cp, cr = composite(pred, offsets), composite(ref, offsets)
    parts["composite"] = smape(cp, cr)
    if h >= 4 and w >= 4:
        img = lambda x: tonemap(x).T.reshape(3, h, w)  # noqa: E731
        parts["composite_ssim"] = 1 - ssim(img(cp), img(cr))
    loss = sum(WEIGHTS[k] * v for k, v in parts.items())
    return loss, {k: v.item() for k, v in parts.items()}
