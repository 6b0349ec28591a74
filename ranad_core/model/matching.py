"""The matching temporal step (configs *-xm): each centre bin averages the window's bins at its own
(motion-compensated) pixel, weighted by how well each candidate matches it.

Why not the dot-product kernel of the other temporal steps: a kernel logit q·k cannot express a distance between
a query and a key (-|q - k|² needs a per-key -|k|² term that no q·k has), and motion compensation moves bins by
whole pixels, so a neighbour's bin at the same pixel is often a slightly different patch of texture, an edge's
other side, or a refracted view that moved differently. A measured case (issue 25): constant-gated blends of the
dot-product kernel's result made held-out glass shots 1.5-2.5x worse. Here each (query, candidate) pair is scored
by a small MLP of the element-wise difference and product of their embeddings, so "same surface, same shading"
and "different" are easy to tell apart.

Still a softmax-weighted average of the values with weights that come from the embeddings only, so the output is
linear in the values (AOVs reuse it, light groups still sum to the beauty). Radius 0 only: the candidates are the
key bins of the query's own pixel (the query's own bin among them, as the window's key layout holds the centre's
bins).
"""

from __future__ import annotations

import torch
from torch import nn

from . import fused
from .inputs import GUIDE_LAYOUT, exact_row_kernels
from .layers import Layout

PAIR_DIM = 16    # width of each bin's projection the pair scores compare
SELF_BONUS = 3.0  # initial logit bonus of the query's own bin: the step starts mostly as the identity (0.8 of the
                  # weight on the bin itself with ~5 candidates), so the scores train at full gradient from the start


def pixel_pairs(q_pixels: torch.Tensor, keys: Layout) -> tuple[torch.Tensor, torch.Tensor]:
    """Every (query row, key row) pair that shares a pixel: q_pixels [Nq, 2] (y, x) -> (qi [P], kj [P]), grouped
    by query in ascending order (the reference RaNA's pairs for a disc of radius 0)."""
    hk, wk = keys.size
    y, x = q_pixels[:, 0], q_pixels[:, 1]
    inside = (y >= 0) & (y < hk) & (x >= 0) & (x < wk)
    p = torch.where(inside, y * wk + x, torch.zeros_like(y))
    start = keys.offsets[p]
    count = torch.where(inside, keys.offsets[p + 1] - start, torch.zeros_like(start))
    total = int(count.sum())
    # neighbour_pairs for a disc of one pixel, without its disc offsets (72 -> 31 ms for a 960x540 tile's queries)
    qi = torch.repeat_interleave(torch.arange(count.numel(), device=count.device), count, output_size=total)
    kj = start[qi] + torch.arange(total, device=count.device) - (torch.cumsum(count, 0) - count)[qi]
    return qi, kj


def pair_features(a: torch.Tensor, b: torch.Tensor, qi: torch.Tensor, kj: torch.Tensor) -> torch.Tensor:
    """[P, 2 d] the pair scores' input: [|a[qi] - b[kj]|, a[qi] * b[kj]] for rows a [Nq, d] and b [Nk, d]. Float32
    CPU tensors without gradients by the C++ kernels' one pass over the pairs where they are built (torch's gathers,
    difference, absolute value, product and concatenation took 86 ms per layer of a 960x540 tile's 0.63 M pairs),
    the same values; others (GPU, autograd) by torch."""
    ext = exact_row_kernels((a, b), (qi, kj))
    if ext is None:
        x, y = a[qi], b[kj]
        return torch.cat([(x - y).abs(), x * y], 1)
    return ext.rows_pair_features(a.contiguous(), b.contiguous(), qi.contiguous(), kj.contiguous())


def pair_sum(w: torch.Tensor, values: torch.Tensor, qi: torch.Tensor, kj: torch.Tensor, queries: int) -> torch.Tensor:
    """[queries, C]: each query's sum of w[p] * values[kj[p]] over its pairs p (qi ascending), torch's
    zeros.index_add(0, qi, w[:, None] * values[kj]); by the C++ kernels' one pass where they are built and nothing
    wants gradients (torch's gather, product and index_add took 22 ms per layer of a 960x540 tile), the same
    values."""
    ext = exact_row_kernels((w, values), (qi, kj))
    if ext is None:
        return values.new_zeros(queries, values.shape[1]).index_add(0, qi, w.unsqueeze(1).to(values.dtype) * values[kj])
    return ext.rows_pair_sum(w.contiguous(), values.contiguous(), qi.contiguous(), kj.contiguous(), queries)


def segment_softmax(logits: torch.Tensor, seg: torch.Tensor, segments: int) -> torch.Tensor:
    """Softmax of logits [P] within each segment (seg [P] in 0..segments-1)."""
    top = logits.new_full((segments,), float("-inf")).scatter_reduce(0, seg, logits, "amax")
    e = torch.exp(logits - top[seg])
    return e / logits.new_zeros(segments).index_add(0, seg, e)[seg]


# The guard (configs with `temporal_guard`): a neighbour's bin is a candidate only where it shows what the query
# bin shows: every guide within its tolerance (max abs difference over the group's columns of inputs.guides: the
# standardised log depth, albedo and normal; the flat prior compared as a ratio, log((a + floor) / (b + floor)) of
# the exposure-normalised prior, catching shading that changed, refraction and misaligned texture; and blackness:
# a bin whose samples were all black takes nothing from bins that were not, as metrics such as HDR-FLIP see even
# 1e-7 of light leaked onto exact black). Rules, not learned scores: they mean the same on scenes unlike the
# training ones, where the learned scores alone blended what they should not (issue 25).
GUARD = {"depth": 0.25, "albedo": 0.1, "normal": 0.25, "black": 0.5}
PRIOR_TOLERANCE = 0.2     # |log ratio| of the priors: about 20%
PRIOR_FLOOR = 0.01        # in units of the frame's exposure scale: below it, differences count as equal


def consistent(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """[P] whether guide rows a [P, GUIDE_WIDTH] and b (inputs.guides) agree within GUARD and PRIOR_TOLERANCE."""
    ok = torch.ones(a.shape[0], dtype=torch.bool, device=a.device)
    for name, tol in GUARD.items():
        cols = GUIDE_LAYOUT[name]
        ok &= (a[:, cols] - b[:, cols]).abs().amax(1) <= tol
    prior = GUIDE_LAYOUT["prior"]
    pa, pb = (torch.expm1(x[:, prior].clamp(min=0)) + PRIOR_FLOOR for x in (a, b))
    return ok & (torch.log(pa / pb).abs().amax(1) <= PRIOR_TOLERANCE)


class MatchKernel(nn.Module):
    """The kernel: pair logit = MLP(|a - b|, a * b) of the two bins' projected embeddings, plus a learned bonus
    for the query's own bin."""

    def __init__(self, dim: int, hidden: int = PAIR_DIM):
        super().__init__()
        self.proj = nn.Linear(dim, PAIR_DIM)
        self.score = nn.Sequential(nn.Linear(2 * PAIR_DIM, hidden), nn.ReLU(), nn.Linear(hidden, 1))
        self.self_bonus = nn.Parameter(torch.tensor(SELF_BONUS))

    def forward(self, q_feat, k_feat, q_pixels, keys: Layout, values: torch.Tensor,
                own: torch.Tensor | None = None, pairs=None) -> torch.Tensor:
        """values [Nk, C] -> [Nq, C] (the signature of KernelAttention); own [Nq]: each query's own row among the
        keys (None: no bonus); pairs: the (qi, kj) that take part, grouped by query, each query's own bin among
        them (None: pixel_pairs(q_pixels, keys), all of them)."""
        qi, kj = pixel_pairs(q_pixels, keys) if pairs is None else pairs
        logits = fused.relu_mlp(self.score, pair_features(self.proj(q_feat), self.proj(k_feat), qi, kj)).squeeze(1)
        if own is not None:
            logits = logits + self.self_bonus * (kj == own[qi]).to(logits.dtype)
        return pair_sum(segment_softmax(logits, qi, q_feat.shape[0]), values, qi, kj, q_feat.shape[0])
