"""The RaNA neighbourhood: the pixelated L2 disc of the paper's Eq. 2 and its relative-position bias grid.

A query centred at pixel (y, x) attends to every key bin of every pixel (y+dy, x+dx) with
dy^2 + dx^2 <= r^2. The disc is stored as rows (dy, dx0, dx1) because the bins of one row of pixels are one
contiguous range in the ragged layout: kernels walk a few contiguous ranges instead of single pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import torch


@dataclass(frozen=True)
class Disc:
    radius: float
    R: int  # floor(radius); the bias is [heads, 2R+1, 2R+1]
    dy: tuple[int, ...]
    dx0: tuple[int, ...]
    dx1: tuple[int, ...]

    @property
    def side(self) -> int:
        return 2 * self.R + 1

    @property
    def size(self) -> int:
        """Number of pixels in the disc."""
        return sum(b - a + 1 for a, b in zip(self.dx0, self.dx1))

    def offsets(self) -> list[tuple[int, int]]:
        """Every (dy, dx) of the disc, row by row (the order kernels visit keys in)."""
        return [(dy, dx) for dy, a, b in zip(self.dy, self.dx0, self.dx1) for dx in range(a, b + 1)]

    def tensors(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return _disc_tensors(self.radius)


@lru_cache(maxsize=None)
def disc(radius: float) -> Disc:
    """The disc of pixels within ``radius`` (>= 0) of the centre, including the centre itself."""
    if not radius >= 0 or not math.isfinite(radius):
        raise ValueError(f"radius must be a finite number >= 0, got {radius}")
    R = int(math.floor(radius))
    r2 = radius * radius
    dy, dx0, dx1 = [], [], []
    for y in range(-R, R + 1):
        w = int(math.floor(math.sqrt(max(r2 - y * y, 0.0)) + 1e-9))
        if y * y <= r2:
            dy.append(y)
            dx0.append(-w)
            dx1.append(w)
    return Disc(float(radius), R, tuple(dy), tuple(dx0), tuple(dx1))


@lru_cache(maxsize=None)
def _disc_tensors(radius: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    d = disc(radius)
    return tuple(torch.tensor(t, dtype=torch.int32) for t in (d.dy, d.dx0, d.dx1))
