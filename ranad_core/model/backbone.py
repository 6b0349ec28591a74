"""The multi-U-Net backbone (paper Sec. 4.1.2): U-Nets of RaNA blocks chained, alternating bin-dropout patterns.

Down-sampling keeps a deterministic half of the bins (layers.bin_dropout) and lets them attend to all bins of the
finer scale (sparse queries over dense keys); up-sampling lets the finer bins attend to the coarser scale
(dense queries over sparse keys) and merges the result with the encoder's skip features through an FC layer.
Radii grow with the scale, since coarser scales hold fewer bins per area.
"""

from __future__ import annotations

import torch
from torch import nn

from . import fused
from .layers import Layout, MultiHeadRaNA, RaNABlock, bin_dropout


class UNet(nn.Module):
    def __init__(self, dim: int, levels: int, blocks_per_level: int, heads: int, head_dim: int,
                 radius: float, radius_growth: float, pattern: int, backend: str = "auto", lattice: bool = False):
        super().__init__()
        self.levels, self.pattern, self.lattice = levels, pattern, lattice
        radii = [radius + radius_growth * lv for lv in range(levels + 1)]

        def stage(r):
            return nn.ModuleList(RaNABlock(dim, heads, head_dim, r, backend=backend) for _ in range(blocks_per_level))

        self.enc = nn.ModuleList(stage(radii[lv]) for lv in range(levels))
        self.mid = stage(radii[levels])
        self.dec = nn.ModuleList(stage(radii[lv]) for lv in range(levels))
        self.down = nn.ModuleList(MultiHeadRaNA(dim, dim, dim, heads, head_dim, radii[lv + 1], backend)
                                  for lv in range(levels))
        self.up = nn.ModuleList(MultiHeadRaNA(dim, dim, dim, heads, head_dim, radii[lv + 1], backend)
                                for lv in range(levels))
        self.merge = nn.ModuleList(nn.Linear(2 * dim, dim) for _ in range(levels))
        self.norms = nn.ModuleList(nn.LayerNorm(dim) for _ in range(2 * levels))

    def forward(self, feat: torch.Tensor, layout: Layout) -> torch.Tensor:
        skips, layouts = [], [layout]
        quick = fused.active(feat, self.down[0].backend if self.levels else "auto")   # inference (fused.py)
        for lv in range(self.levels):
            for blk in self.enc[lv]:
                feat = blk(feat, layouts[-1])
            skips.append(feat)
            kept, coarse = bin_dropout(layouts[-1], (lv + self.pattern) % 2, lv + 1, self.lattice)
            norm, down = self.norms[2 * lv], self.down[lv]
            if quick:
                sub = feat[kept]
                (q,), (k, v) = fused.ln_linear(sub, norm, [down.q]), fused.ln_linear(feat, norm, [down.k, down.v])
                feat = fused.linear_residual(sub, down.attend(q, k, v, coarse.pixels, layouts[-1]), down.out)
            else:
                x = norm(feat)
                feat = feat[kept] + down(x[kept], x, coarse.pixels, layouts[-1])
            layouts.append(coarse)
        for blk in self.mid:
            feat = blk(feat, layouts[-1])
        for lv in reversed(range(self.levels)):
            fine, norm, up = layouts[lv], self.norms[2 * lv + 1], self.up[lv]
            if quick:
                (q,), (k, v) = fused.ln_linear(skips[lv], norm, [up.q]), fused.ln_linear(feat, None, [up.k, up.v])
                feat = fused.merge_residual(skips[lv], up.attend(q, k, v, fine.pixels, layouts[lv + 1]), up.out,
                                            self.merge[lv])
            else:
                y = up(norm(skips[lv]), feat, fine.pixels, layouts[lv + 1])
                feat = skips[lv] + self.merge[lv](torch.cat([skips[lv], y], dim=1))
            for blk in self.dec[lv]:
                feat = blk(feat, fine)
        return feat


class MultiUNet(nn.Module):
    """U-Nets in a chain; each one's output is the next one's input, dropout patterns alternate."""

    def __init__(self, dim: int, unets: int, levels: int, blocks_per_level: int, heads: int, head_dim: int,
                 radius: float, radius_growth: float, backend: str = "auto", lattice: bool = False):
        super().__init__()
        self.unets = nn.ModuleList(UNet(dim, levels, blocks_per_level, heads, head_dim, radius, radius_growth,
                                        pattern=i % 2, backend=backend, lattice=lattice) for i in range(unets))

    def forward(self, feat: torch.Tensor, layout: Layout) -> torch.Tensor:
        for u in self.unets:
            feat = u(feat, layout)
        return feat
