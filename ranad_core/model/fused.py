"""Inference fast path of the per-bin layers: LayerNorm, linear layers, the MLP and residual adds fused tile by tile
in the C++ extension (cuda/rows_cpu.cpp), one pass over the bins instead of one per torch op.

The layers themselves stay ordinary torch modules (training, gradients, the reference backend use them as they
are); `active` says when a forward may take this path instead: no gradient wanted, float32 on the CPU, the C++
kernels built, and the RaNA backend not forced to the reference. Results equal the modules' to float rounding
(tests/test_fused.py). RANAD_NO_FUSED=1 turns the path off (for comparisons).
"""

from __future__ import annotations

import os

import torch
from torch import nn

from ..rana.extension import cpu_extension_or_none


def active(x: torch.Tensor, backend: str = "auto") -> bool:
    """Whether a forward on `x` may use the fused kernels."""
    if torch.is_grad_enabled() or x.device.type != "cpu" or x.dtype != torch.float32:
        return False
    if backend not in ("auto", "cpu") or os.environ.get("RANAD_NO_FUSED"):
        return False
    return cpu_extension_or_none() is not None


def _ext():
    return cpu_extension_or_none()


def _rows(x: torch.Tensor) -> torch.Tensor:
    return x if x.is_contiguous() else x.contiguous()


def _norm_args(norm: nn.LayerNorm | None):
    if norm is None:
        return None, None, 1e-5
    return norm.weight, norm.bias, float(norm.eps)


def ln_linear(x: torch.Tensor, norm: nn.LayerNorm | None, linears: list) -> list:
    """[linear(norm(x)) for linear in linears], one pass (norm None: no LayerNorm)."""
    w, b, eps = _norm_args(norm)
    wt = torch.cat([lin.weight for lin in linears]).t().contiguous()
    bias = torch.cat([lin.bias for lin in linears])
    return _ext().rows_ln_linear(_rows(x), w, b, eps, wt, bias, [lin.out_features for lin in linears])


def linear_residual(res: torch.Tensor, y: torch.Tensor, linear: nn.Linear) -> torch.Tensor:
    """res + linear(y)."""
    return _ext().rows_linear_residual(_rows(res), _rows(y), linear.weight.t().contiguous(), None, None,
                                       linear.bias)


def merge_residual(skip: torch.Tensor, y: torch.Tensor, out: nn.Linear, merge: nn.Linear) -> torch.Tensor:
    """skip + merge(cat([skip, out(y)])): a U-Net's up-sampling projection and merge, with `out` folded into the
    merge's second half (merge(cat([s, out(y)])) = s A^T + y (B W)^T + B b + m for merge weights [A | B] and bias
    m, out weight W and bias b)."""
    dim = skip.shape[1]
    a, bmat = merge.weight[:, :dim], merge.weight[:, dim:]
    folded = bmat @ out.weight
    bias = merge.bias + bmat @ out.bias
    return _ext().rows_linear_residual(_rows(skip), _rows(skip), a.t().contiguous(), _rows(y),
                                       folded.t().contiguous(), bias)


def relu_mlp(seq: nn.Sequential, x: torch.Tensor) -> torch.Tensor:
    """seq(x) for an nn.Sequential(Linear, ReLU, Linear) (input embeddings, pair scores): fused where `active`."""
    return mlp(x, None, seq[0], seq[2], False) if active(x) else seq(x)


def mlp(x: torch.Tensor, norm: nn.LayerNorm | None, first: nn.Linear, second: nn.Linear,
        residual: bool) -> torch.Tensor:
    """[x +] second(relu(first(norm(x))))."""
    w, b, eps = _norm_args(norm)
    return _ext().rows_mlp(_rows(x), w, b, eps, first.weight.t().contiguous(), first.bias,
                           second.weight.t().contiguous(), second.bias, residual)


def wide_operand(proj: torch.Tensor, heads: int, scale: float, terms: torch.Tensor, term_scale: float,
                 wide: int) -> torch.Tensor:
    """[N, heads, wide] (a channel-major view): proj [N, d * heads] (channel-major) times scale, then the terms
    [N, e] times term_scale on every head, then zeros: a gated reconstruction kernel's q or k operand in one pass
    (reconstruction.KernelAttention._with_range builds the same with a pass per block of columns)."""
    out = _ext().rows_wide_operand(_rows(proj), heads, float(scale), _rows(terms), float(term_scale), wide)
    return out.transpose(1, 2)


def scale_mix(feat: torch.Tensor, mixer: nn.Linear, outs: list) -> torch.Tensor:
    """sum_s softmax(mixer(feat))[:, s] * outs[s]: a reconstruction's per-bin convex mix of its scales, one pass
    (the torch ops: a GEMM, a softmax over rows of 2-4, a multiply and add per scale; 0.5 s of a 2.9 M-bin frame)."""
    return _ext().rows_scale_mix(_rows(feat), mixer.weight.t().contiguous(), mixer.bias, [_rows(o) for o in outs])
