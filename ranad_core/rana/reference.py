"""The plain-torch RaNA: gather the pairs, segment softmax, scatter. The oracle for every other backend.

Differentiable through ordinary autograd (gathers, ``index_add``). Work is split into chunks of queries so
that the materialised (query, key) pair list stays within ``max_pairs`` pairs at a time.
"""

from __future__ import annotations

import math

import torch

from .neighborhood import disc


def neighbour_pairs(q_pixels: torch.Tensor, k_offsets: torch.Tensor, k_size: tuple[int, int], radius: float):
    """All (query, key bin, disc offset index) pairs, query-major, keys in disc-row order.

    Returns (qi, kj, oy, ox): int64 [P] each; (oy, ox) index the bias grid ([0, 2R]).
    """
    d = disc(radius)
    Hk, Wk = k_size
    offs = torch.tensor(d.offsets(), dtype=torch.int64, device=q_pixels.device).reshape(-1, 2)  # [D, 2]
    y = q_pixels[:, None, 0] + offs[None, :, 0]
    x = q_pixels[:, None, 1] + offs[None, :, 1]
    inside = (y >= 0) & (y < Hk) & (x >= 0) & (x < Wk)
    p = torch.where(inside, y * Wk + x, torch.zeros_like(y))
    start = k_offsets[p]
    count = torch.where(inside, k_offsets[p + 1] - start, torch.zeros_like(start))
    flat_count = count.reshape(-1)
    total = int(flat_count.sum())
    combo = torch.repeat_interleave(torch.arange(flat_count.numel(), device=q_pixels.device), flat_count,
                                    output_size=total)
    first = torch.cumsum(flat_count, 0) - flat_count
    within = torch.arange(total, device=q_pixels.device) - first[combo]
    kj = start.reshape(-1)[combo] + within
    qi = combo // offs.shape[0]
    o = combo % offs.shape[0]
    return qi, kj, offs[o, 0] + d.R, offs[o, 1] + d.R


def rana_reference(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, q_pixels: torch.Tensor,
                   k_offsets: torch.Tensor, k_size: tuple[int, int], radius: float,
                   bias: torch.Tensor | None = None, max_pairs: int = 1 << 20) -> torch.Tensor:
    """out [Nq, heads, dv]: softmax over each query's disc of q.k/sqrt(d) (+ bias), applied to v.

    A query whose disc holds no key bins gets zeros.
    """
    nq, H, d = q.shape
    dv = v.shape[2]
    scale = 1.0 / math.sqrt(d)
    nd = disc(radius).size
    mean_bins = max(1.0, float(k_offsets[-1]) / max(1, k_size[0] * k_size[1]))
    chunk = max(1, int(max_pairs / (nd * mean_bins)))
    outs = []
    for i0 in range(0, nq, chunk):
        i1 = min(nq, i0 + chunk)
        qi, kj, oy, ox = neighbour_pairs(q_pixels[i0:i1], k_offsets, k_size, radius)
        n = i1 - i0
        logits = (q[i0:i1][qi] * k[kj]).sum(-1) * scale  # [P, H]
        if bias is not None:
            logits = logits + bias[:, oy, ox].T
        # the max only stabilises the exponentials; softmax does not depend on it, so it carries no gradient
        m = torch.full((n, H), -math.inf, dtype=q.dtype, device=q.device)
        m = m.scatter_reduce(0, qi[:, None].expand(-1, H), logits.detach(), "amax")
        e = torch.exp(logits - m[qi])
        den = torch.zeros((n, H), dtype=q.dtype, device=q.device).index_add(0, qi, e)
        num = torch.zeros((n, H, dv), dtype=q.dtype, device=q.device).index_add(0, qi, e[..., None] * v[kj])
        outs.append(torch.where(den[..., None] > 0, num / den.clamp_min(torch.finfo(q.dtype).tiny)[..., None],
                                torch.zeros_like(num)))
    if not outs:
        return q.new_zeros((0, H, dv))
    return torch.cat(outs)
