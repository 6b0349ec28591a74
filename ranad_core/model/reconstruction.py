"""Multi-scale kernel reconstruction (paper Sec. 4.1.3, Fig. 7): the denoised layer is attention applied to noisy
values, so it is linear in them, and the same weights denoise any AOV batched into the value channels.

Stage 1 (pyramid): bin dropout picks sparser query bins; RaNA with those bins' embeddings as queries, the finer
scale's embeddings as keys and its (blurred) layer as values gives the next, blurrier scale, with the radius
growing per scale. Stage 2 (per-scale denoising): full-resolution embeddings query each scale's embeddings, with
that scale's layer as values. Stage 3: a scale mixer (FC + softmax over scales) weights the per-scale results.
Every step is a softmax-weighted average of values, so output(a x + b y) = a output(x) + b output(y).

Demodulation (`demodulated`, configs with `demodulate`): the values divided per bin by a modulation (the albedo
guide, inputs.modulation) before the kernels and the result multiplied by the query bin's: still linear in the
values (the same operator denoises AOVs, and light groups still sum to the beauty), but no longer a convex
combination of them.

Layer gate (configs with `layer_gate`; its guides come from the function `layer_gate`): the kernels of a gated
layer keep to the bins' own depth layers, a range term -(lambda_q + lambda_k) (log z_q - log z_k)^2, each lambda
set by half that bin's depth gap to the nearest other bin of its pixel (0 in single-bin pixels): a query of a
layer stack reads only its own layer, and no query reads a key of a stack across that key's layers (the
pyramid's blurred keys stay on their layers too). It only reweights, so the output stays a combination of the
noisy values.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from ..rana import rana
from . import fused
from .layers import Layout, bin_dropout, kept_rows

GATE_WIDTH_FLOOR = 0.02   # narrowest gate half-width in log depth (2%): keeps lambda |log z|^2 within fp32's reach
GATE_STRENGTH = 4.0       # lambda = GATE_STRENGTH / half-width^2: a bin one gap away (the other layer) gets e^-16


def layer_gate(depth: torch.Tensor, layout: Layout) -> tuple[torch.Tensor, torch.Tensor]:
    """(a [N, 2], b [N, 2]), both (log z, lambda) per bin, of bins in depth order within each pixel (the order
    denoise and training prepare them in): the layer gate's guides for the bins as queries and as keys. log z is
    centred on its mean over the bins (the range term does not depend on the centre; small values keep the
    logits' cancellation exact enough). lambda = GATE_STRENGTH / h^2, h half the log-depth gap to the nearest
    other bin of the pixel (at least GATE_WIDTH_FLOOR); 0 in single-bin pixels."""
    lz = torch.log(torch.clamp(depth[:, :1].float(), min=1e-4))
    lz = lz - lz.mean() if lz.numel() else lz
    pix = layout.pixels[:, 0] * layout.width + layout.pixels[:, 1]
    n = lz.shape[0]
    gap = torch.full((n,), float("inf"), dtype=lz.dtype, device=lz.device)
    if n > 1:
        same = pix[1:] == pix[:-1]
        d = torch.where(same, (lz[1:, 0] - lz[:-1, 0]).abs(), gap.new_tensor(float("inf")))
        gap[1:] = torch.minimum(gap[1:], d)
        gap[:-1] = torch.minimum(gap[:-1], d)
    h = torch.clamp(gap / 2, min=GATE_WIDTH_FLOOR)
    lam = torch.where(torch.isfinite(gap), GATE_STRENGTH / (h * h), torch.zeros_like(h))
    g = torch.cat([lz, lam[:, None]], 1)
    return g, g


def gate_terms(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The layer gate's columns of the wide operands, q's [Nq, 5] and k's [Nk, 5], from layer_gate's guides (log z
    and lambda in the last two columns of a and b): q's (2 lambda_q za, -lambda_q, za^2, za, 1) against k's (zb,
    zb^2, -lambda_k, 2 lambda_k zb, -lambda_k zb^2), whose products sum to -(lambda_q + lambda_k) (za - zb)^2 less
    its terms of the query alone."""
    za, lq, zb, lk = a[:, -2:-1], a[:, -1:], b[:, -2:-1], b[:, -1:]
    return (torch.cat([2 * lq * za, -lq, za * za, za, torch.ones_like(za)], 1),
            torch.cat([zb, zb * zb, -lk, 2 * lk * zb, -lk * zb * zb], 1))


def wide_dim(d: int, extra: int) -> int:
    """The head size the kernels compile that holds d channels and `extra` term columns."""
    return next(w for w in (8, 16, 32, 64, 128) if w >= d + extra)


class KernelAttention(nn.Module):
    """Single-purpose RaNA whose values are the noisy layer itself (no value projection): the kernel weights
    come from the embeddings, the values pass through untouched, which is what keeps the output linear."""

    def __init__(self, dim: int, heads: int, head_dim: int, radius: float, backend: str = "auto",
                 prior_range: bool = False, gated: bool = False):
        super().__init__()
        from ..rana import disc

        self.heads, self.head_dim, self.radius, self.backend = heads, head_dim, float(radius), backend
        self.gated = gated   # the guides end with the layer gate's columns (layer_gate)
        self.q = nn.Linear(dim, heads * head_dim)
        self.k = nn.Linear(dim, heads * head_dim)
        self.bias = nn.Parameter(torch.zeros(heads, disc(radius).side, disc(radius).side))
        self.head_mix = nn.Parameter(torch.zeros(heads))  # softmax over heads: a convex mix of head kernels
        # per head, lambda of the range term -lambda |a_q - b_k|^2 (ModelConfig.prior_range); 0: no effect
        self.range = nn.Parameter(torch.zeros(heads)) if prior_range else None

    def forward(self, q_feat, k_feat, q_pixels, keys: Layout, values: torch.Tensor, guide=None) -> torch.Tensor:
        """values [Nk, C] -> [Nq, C]: each head's kernel applied to all C value channels, heads mixed convexly.
        `guide`: (a [Nq, *], b [Nk, *]): for a prior-range module first the query's flat prior and the key's noisy
        flat (3 columns each), then for a gated one layer_gate's (2 columns each)."""
        H, d = self.heads, self.head_dim
        if fused.active(q_feat, self.backend):
            return self._fused_forward(q_feat, k_feat, q_pixels, keys, values, guide)
        q = self.q(q_feat).view(q_feat.shape[0], d, H).transpose(1, 2)   # channel-major, as the kernels stream it
        k = self.k(k_feat).view(k_feat.shape[0], d, H).transpose(1, 2)
        q, k = self._with_range(q, k, guide)
        v = values.unsqueeze(1).expand(-1, H, -1)
        y = rana(q, k, v, q_pixels, keys.offsets, keys.size, self.radius, self.bias, backend=self.backend)
        return (y * torch.softmax(self.head_mix, 0)[None, :, None]).sum(1)

    def _with_range(self, q: torch.Tensor, k: torch.Tensor, guide) -> tuple[torch.Tensor, torch.Tensor]:
        """q [Nq, H, d], k [Nk, H, d] extended so that the op's q'.k' / sqrt(d') is q.k / sqrt(d) minus the range
        terms (plus terms of the query alone, which the softmax ignores). Prior range, -lambda_h |a - b|^2 with
        the head's learned lambda, a the query's prior, b the key's noisy flat: q's columns (2 lambda a, -lambda)
        against k's (b, |b|^2). Layer gate, -(lambda_q + lambda_k) (za - zb)^2 with layer_gate's log depths and
        lambdas: q's (2 lambda_q za, -lambda_q, za^2, za, 1) against k's (zb, zb^2, -lambda_k, 2 lambda_k zb,
        -lambda_k zb^2). q' = sqrt(d') [q / sqrt(d), terms, 0...], k' = [k, terms, 0...], d' the next head size
        the kernels compile (16 for d = 8 and either term, 32 for both)."""
        if self.range is None and not self.gated:
            return q, k
        if guide is None:
            raise ValueError("a prior-range or gated reconstruction needs its guides (prior features, depths)")
        a, b = guide
        nq, nk, H, d = q.shape[0], k.shape[0], self.heads, self.head_dim
        qs, ks = [], []   # [N, H or 1, c] blocks of columns, written once into the wide operands below
        if self.range is not None:
            lam = self.range[None, :, None]
            qs += [2 * lam * a[:, None, :3], (-lam).expand(1, H, 1)]
            ks += [b[:, None, :3], (b[:, :3] * b[:, :3]).sum(1)[:, None, None]]
        if self.gated:   # -(lambda_q + lambda_k) (za - zb)^2 without its terms of the query alone
            tq, tk = gate_terms(a, b)
            qs.append(tq[:, None, :])
            ks.append(tk[:, None, :])
        extra = sum(t.shape[2] for t in qs)
        wide = wide_dim(d, extra)
        s = math.sqrt(wide)
        if self.range is None and fused.active(q, self.backend):   # the gate's columns alone: one C++ pass each
            return (fused.wide_operand(q.transpose(1, 2).reshape(nq, d * H), H, s / math.sqrt(d), qs[0][:, 0], s, wide),
                    fused.wide_operand(k.transpose(1, 2).reshape(nk, d * H), H, 1.0, ks[0][:, 0], 1.0, wide))
        # written channel-major ([N, d', H], returned as its [N, H, d'] view), the layout the kernels stream
        # without a copy, as the projections themselves are (layers.py)
        qa, ka = q.new_empty(nq, wide, H), k.new_empty(nk, wide, H)
        qa[:, :d] = q.transpose(1, 2) * (s / math.sqrt(d))
        ka[:, :d] = k.transpose(1, 2)
        at = d
        for tq, tk in zip(qs, ks):
            c = tq.shape[2]
            qa[:, at:at + c] = tq.transpose(1, 2) * s
            ka[:, at:at + c] = tk.transpose(1, 2)
            at += c
        qa[:, at:] = 0
        ka[:, at:] = 0
        qa, ka = qa.transpose(1, 2), ka.transpose(1, 2)
        return qa, ka

    def _fused_forward(self, q_feat, k_feat, q_pixels, keys: Layout, values: torch.Tensor, guide=None
                       ) -> torch.Tensor:
        """forward for inference: q and k from the fused projection, v made channel-major (the layout the kernels
        stream), so the op copies no operand."""
        H, d = self.heads, self.head_dim
        (q,), (k,) = fused.ln_linear(q_feat, None, [self.q]), fused.ln_linear(k_feat, None, [self.k])
        q, k = (x.view(len(x), d, H).transpose(1, 2) for x in (q, k))
        q, k = self._with_range(q, k, guide)
        v = values[:, :, None].expand(-1, -1, H).contiguous().transpose(1, 2)   # channel-major [N, H, C]
        y = rana(q, k, v, q_pixels, keys.offsets, keys.size, self.radius, self.bias, backend=self.backend)
        mix = torch.softmax(self.head_mix, 0)
        out = y[:, 0] * mix[0]
        for h in range(1, H):
            out += y[:, h] * mix[h]
        return out


class Reconstruction(nn.Module):
    """One output layer's reconstruction module (number of scales, radii and dropout pattern per layer).

    `residual` (ModelConfig.alpha_residual, alpha's module only): the kernels' result plus a per-bin correction, a
    small MLP of the bin's embedding whose last layer starts at zero (the module begins as the plain one). The one
    output that is not a combination of the noisy values: it can move a bin's alpha where all its neighbours are
    off the same way, which no kernel can (runs/edit-oracles-s12). Only for a layer that carries no AOVs."""

    def __init__(self, dim: int, scales: int = 3, heads: int = 2, head_dim: int = 8, radius: float = 2.5,
                 radius_growth: float = 1.0, backend: str = "auto", lattice: bool = False, prior_range: bool = False,
                 residual: bool = False, gated: bool = False):
        super().__init__()
        self.residual = None
        if residual:
            self.residual = nn.Sequential(nn.Linear(dim, dim), nn.ReLU(), nn.Linear(dim, 1))
            nn.init.zeros_(self.residual[2].weight)
            nn.init.zeros_(self.residual[2].bias)
        self.scales, self.lattice, self.gated = scales, lattice, gated
        radii = [radius + radius_growth * s for s in range(scales)]
        self.down = nn.ModuleList(KernelAttention(dim, heads, head_dim, radii[s], backend, prior_range, gated)
                                  for s in range(scales - 1))
        self.per_scale = nn.ModuleList(KernelAttention(dim, heads, head_dim, radii[s], backend, prior_range, gated)
                                       for s in range(scales))
        self.mixer = nn.Linear(dim, scales)

    def forward(self, feat: torch.Tensor, layout: Layout, noisy: torch.Tensor, guide=None) -> torch.Tensor:
        """feat [N, dim] backbone embeddings, noisy [N, C] layer values (any C: AOVs batch here) -> [N, C].
        `guide`: (a [N, *], b [N, *]) per bin, for prior-range or gated modules (KernelAttention.forward)."""
        feats, layouts, images = [feat], [layout], [noisy]
        guides = [guide]
        for s in range(self.scales - 1):  # stage 1: the pyramid of blurred layers
            kept, coarse = bin_dropout(layouts[-1], s % 2, s + 1, self.lattice)
            q_feat = kept_rows(layouts[-1], s % 2, s + 1, self.lattice, feats[-1])   # shared by the layers
            g = guides[-1]
            images.append(self.down[s](q_feat, feats[-1], coarse.pixels, layouts[-1], images[-1],
                                       None if g is None else (g[0][kept], g[1])))
            feats.append(q_feat)
            layouts.append(coarse)
            guides.append(None if g is None else (g[0][kept], g[1][kept]))
        outs = [self.per_scale[s](feat, feats[s], layout.pixels, layouts[s], images[s],
                                  None if guide is None else (guide[0], guides[s][1]))  # stage 2
                for s in range(self.scales)]
        # stage 3: per-bin convex mix of the scales, a softmax over each bin's row of 2-3 scales. (Over the scales of
        # the [scales, N] view torch vectorises over the bins, 1.6x as fast, but splits the bins among the threads
        # with vector and scalar tails at the splits: the weights then changed with the thread count, by an ulp.)
        # Inference on the CPU: the mixer, the softmax and the mix in one C++ pass, a row per thread (fused.py).
        if fused.active(feat, self.per_scale[0].backend):
            out = fused.scale_mix(feat, self.mixer, outs)
        else:
            w = torch.softmax(self.mixer(feat), dim=1).t()
            out = sum(w[s, :, None] * outs[s] for s in range(self.scales))
        if self.residual is not None:
            if out.shape[1] != 1:
                raise ValueError(f"a residual reconstruction has one channel (alpha), got values of {out.shape[1]}")
            out = out + fused.relu_mlp(self.residual, feat)
        return out


def demodulated(rec: Reconstruction, feat: torch.Tensor, layout: Layout, values: torch.Tensor,
                modulation: torch.Tensor | None, guide=None) -> torch.Tensor:
    """rec on values / modulation, times the modulation: values [N, 3k] (k RGB triplets, e.g. AOVs batched),
    modulation [N, 3] or None (then rec alone); `guide`: Reconstruction.forward's."""
    if modulation is None:
        return rec(feat, layout, values, guide)
    m = per_channel(modulation, values)
    return m * rec(feat, layout, values / m, guide)


def per_channel(modulation: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """The [N, 3] modulation repeated over the k RGB triplets of values [N, 3k] (the layer, or AOVs batched)."""
    return modulation.repeat(1, values.shape[1] // 3)
