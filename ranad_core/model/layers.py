"""The RaNAD building blocks on ragged bins (paper Sec. 4.1): multi-head RaNA, the RaNA block, bin dropout.

Features are per-bin tensors [N, C] in a layout given by ragged offsets over an H x W grid (one convention
everywhere, see DESIGN.md). Projections write q, k and v channel-major (the Linear output viewed as [N, d, H],
then transposed to the op's [N, H, d]): the C++ kernels stream that layout without a copy, and any fixed order of
a learned layer's outputs is as good as another.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
from torch import nn

from ..rana import bin_pixels, disc, rana
from . import fused


@dataclass
class Layout:
    """Bins of one scale: offsets [H*W+1] over the grid, and each bin's (y, x) (cached: every layer needs it).
    `dropouts` keeps bin_dropout's results for this layout: the reconstructions drop the bins the backbone's first
    U-Net already dropped (the same pattern and level), five times per tile."""
    offsets: torch.Tensor
    height: int
    width: int
    pixels: torch.Tensor
    dropouts: dict = field(default_factory=dict, repr=False, compare=False)
    gathers: dict = field(default_factory=dict, repr=False, compare=False)   # kept_rows' results

    @classmethod
    def of(cls, offsets: torch.Tensor, height: int, width: int) -> "Layout":
        offsets = torch.as_tensor(offsets, dtype=torch.int64)
        return cls(offsets, height, width, bin_pixels(offsets, width))

    @property
    def size(self) -> tuple[int, int]:
        return (self.height, self.width)

    @property
    def bins(self) -> int:
        return int(self.offsets[-1])

    def to(self, device) -> "Layout":
        return Layout(self.offsets.to(device), self.height, self.width, self.pixels.to(device))


def lattice_parity(y: torch.Tensor, x: torch.Tensor, level: int) -> torch.Tensor:
    """The pixel term of bin dropout's parity at down-sampling `level` (1: the first): a quincunx pyramid, so the
    single-bin pixels a level keeps form a lattice twice as sparse as the level above's, never an empty one.
    Level 1: y + x (a checkerboard); level 2: x (on the checkerboard's pixels, the even-even lattice or one of
    its shifts); level 3: y//2 + x//2; level 4: x//2; ..."""
    k = (level - 1) // 2
    return (y >> k) + (x >> k) if level % 2 else x >> k


def bin_dropout(layout: Layout, pattern: int, level: int = 1, lattice: bool = False) -> tuple[torch.Tensor, Layout]:
    """Deterministic bin dropout (down-sampling): bin b of pixel (y, x) is kept when b + c + pattern is even,
    c the pixel's parity term.

    Every pixel keeps about half of its bins; pattern 0/1 alternate between U-Nets so no bin is always dropped.
    With `lattice` (configs with dropout_lattice), c = lattice_parity(y, x, level), so single-bin pixels survive
    in ever sparser lattices and each level holds about half the bins of the one above. Without it (the first
    models), c = y + x at every level: a second level keeps no single-bin pixel at all (the checkerboard's pixels
    all fail the other pattern), so on a typical frame it holds a few percent of the bins, those of multi-bin
    pixels only. Returns (kept row indices into the fine layout, the coarse layout).
    """
    key = _dropout_key(pattern, level, lattice)
    if key not in layout.dropouts:
        layout.dropouts[key] = _bin_dropout(layout, pattern, level, lattice)
    return layout.dropouts[key]


def _dropout_key(pattern: int, level: int, lattice: bool) -> tuple:
    """The cache key of a dropout on a layout: without the lattice, every level drops alike."""
    return (pattern, level if lattice else 1, lattice)


def kept_rows(layout: Layout, pattern: int, level: int, lattice: bool, feat: torch.Tensor) -> torch.Tensor:
    """feat[kept] for bin_dropout(layout, pattern, level, lattice)'s kept bins. At inference the rows are gathered
    once per layout, dropout and feature tensor: every output layer's reconstruction gathers the same embeddings'
    rows for its pyramid (four gathers of one [N, dim] tensor per scale, 0.3 s of a 2.9 M-bin frame)."""
    kept = bin_dropout(layout, pattern, level, lattice)[0]
    if torch.is_grad_enabled():
        return feat[kept]
    key = _dropout_key(pattern, level, lattice)
    hit = layout.gathers.get(key)
    if hit is not None and hit[0] is feat:
        return hit[1]
    rows = feat[kept]
    layout.gathers[key] = (feat, rows)
    return rows


def _bin_dropout(layout: Layout, pattern: int, level: int, lattice: bool) -> tuple[torch.Tensor, Layout]:
    offs = layout.offsets
    counts = offs[1:] - offs[:-1]
    pix = layout.pixels[:, 0] * layout.width + layout.pixels[:, 1]
    first = torch.repeat_interleave(offs[:-1], counts, output_size=layout.bins)
    within = torch.arange(layout.bins, device=offs.device) - first
    y, x = layout.pixels[:, 0], layout.pixels[:, 1]
    parity = lattice_parity(y, x, level) if lattice else y + x
    keep = (within + parity + pattern) % 2 == 0
    kept = torch.nonzero(keep, as_tuple=False).flatten()
    coarse = torch.bincount(pix[kept], minlength=counts.numel())
    coarse_offs = torch.cat([coarse.new_zeros(1), torch.cumsum(coarse, 0)])
    return kept, Layout(coarse_offs, layout.height, layout.width, layout.pixels[kept])


class MultiHeadRaNA(nn.Module):
    """Eq. 5: q from the query bins' features, k and v from the key bins', RaNA per head, heads concatenated
    and projected. A learned relative-position bias per head (zero at start) adds the position awareness a
    disc of bins otherwise lacks."""

    def __init__(self, q_dim: int, kv_dim: int, out_dim: int, heads: int, head_dim: int, radius: float,
                 backend: str = "auto"):
        super().__init__()
        self.heads, self.head_dim, self.radius, self.backend = heads, head_dim, float(radius), backend
        inner = heads * head_dim
        self.q = nn.Linear(q_dim, inner)
        self.k = nn.Linear(kv_dim, inner)
        self.v = nn.Linear(kv_dim, inner)
        self.out = nn.Linear(inner, out_dim)
        side = disc(radius).side
        self.bias = nn.Parameter(torch.zeros(heads, side, side))

    def _heads(self, x: torch.Tensor) -> torch.Tensor:
        return x.view(x.shape[0], self.head_dim, self.heads).transpose(1, 2)  # channel-major [N, H, d] view

    def forward(self, q_feat: torch.Tensor, kv_feat: torch.Tensor, q_pixels: torch.Tensor,
                keys: Layout) -> torch.Tensor:
        return self.out(self.attend(self.q(q_feat), self.k(kv_feat), self.v(kv_feat), q_pixels, keys))

    def attend(self, q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, q_pixels: torch.Tensor,
               keys: Layout) -> torch.Tensor:
        """The attention between the projections: q [Nq, heads*d], k and v [Nk, heads*d] -> [Nq, heads*d] (before
        the output projection; the fused inference path projects around it itself)."""
        q, k, v = self._heads(q), self._heads(k), self._heads(v)
        y = rana(q, k, v, q_pixels, keys.offsets, keys.size, self.radius, self.bias, backend=self.backend)
        return y.reshape(y.shape[0], self.heads * self.head_dim)


class RaNABlock(nn.Module):
    """Fig. 4 / Eq. 5-7: z = F + MHRaNA(F), out = z + FC2(ReLU(FC1(z))), with a LayerNorm before each branch
    (pre-norm: the residual stream stays unnormalised, which keeps deep stacks trainable)."""

    def __init__(self, dim: int, heads: int, head_dim: int, radius: float, mlp_ratio: float = 2.0,
                 backend: str = "auto"):
        super().__init__()
        self.norm1 = nn.LayerNorm(dim)
        self.attn = MultiHeadRaNA(dim, dim, dim, heads, head_dim, radius, backend)
        self.norm2 = nn.LayerNorm(dim)
        hidden = int(dim * mlp_ratio)
        self.mlp = nn.Sequential(nn.Linear(dim, hidden), nn.ReLU(), nn.Linear(hidden, dim))

    def forward(self, feat: torch.Tensor, layout: Layout) -> torch.Tensor:
        a = self.attn
        if fused.active(feat, a.backend):   # inference: the same maths, row by row (fused.py)
            q, k, v = fused.ln_linear(feat, self.norm1, [a.q, a.k, a.v])
            z = fused.linear_residual(feat, a.attend(q, k, v, layout.pixels, layout), a.out)
            return fused.mlp(z, self.norm2, self.mlp[0], self.mlp[2], residual=True)
        x = self.norm1(feat)
        z = feat + a(x, x, layout.pixels, layout)
        return z + self.mlp(self.norm2(z))
