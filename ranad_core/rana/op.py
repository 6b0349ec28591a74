"""The public RaNA op: ``rana(q, k, v, q_pixels, k_offsets, k_size, radius, bias=None)``.

Registered as torch custom ops (``ranad::rana_fwd`` / ``ranad::rana_bwd`` with autograd and fake-tensor
shapes) so it composes with autograd and torch.compile. Backends, picked by ``backend``:

* ``"cpu"``: the C++/OpenMP kernels (``cuda/rana_cpu.cpp``), built on first use;
* ``"cpu-scalar"``: the same kernels with one lane per block, i.e. the bodies exactly as a GPU thread runs
  them (head dimensions up to 16; slow; for tests);
* ``"cuda"``: the CUDA kernels (``cuda/rana_cuda*.cpp/.cu``: blocks of neighbouring queries sharing their keys
  through shared memory, or the same block bodies with one lane per thread where those do not fit), built on
  first use with nvcc;
* ``"reference"``: the plain-torch oracle (:mod:`.reference`), any device, slow and memory-hungry;
* ``"auto"`` (default): the kernels of the tensors' device when they build, the reference otherwise.
"""

from __future__ import annotations

import math
from typing import Literal, Optional

import torch

from .extension import cpu_extension_or_none, cuda_extension_or_none, load_cpu_extension, load_cuda_extension
from .neighborhood import disc
from .reference import rana_reference

Backend = Literal["auto", "cpu", "cpu-scalar", "cuda", "reference"]


def _disc_args(radius: float):
    d = disc(radius)
    dy, dx0, dx1 = d.tensors()
    return dy, dx0, dx1, d.R


def _forward_kernels(q, k, v, q_pixels, k_offsets, hk, wk, radius, bias, scalar_lanes=False):
    """The forward kernels themselves (what the custom op runs); called directly when no gradient is wanted."""
    dy, dx0, dx1, R = _disc_args(radius)
    scale = 1.0 / math.sqrt(q.shape[2])
    if q.is_cuda:
        return tuple(load_cuda_extension().forward(q, k, v, q_pixels, k_offsets, hk, wk, dy, dx0, dx1, R, bias,
                                                   scale, torch.cuda.current_stream(q.device).cuda_stream))
    ext = load_cpu_extension()
    out, lse = ext.forward(q, k, v, q_pixels, k_offsets, hk, wk, dy, dx0, dx1, R, bias, scale, scalar_lanes)
    return out, lse


@torch.library.custom_op("ranad::rana_fwd", mutates_args=())
def rana_fwd(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, q_pixels: torch.Tensor, k_offsets: torch.Tensor,
             hk: int, wk: int, radius: float, bias: Optional[torch.Tensor], scalar_lanes: bool = False
             ) -> tuple[torch.Tensor, torch.Tensor]:
    """Forward kernels: (out [Nq, H, dv], lse [Nq, H]); lse is -inf for queries with an empty disc."""
    return _forward_kernels(q, k, v, q_pixels, k_offsets, hk, wk, radius, bias, scalar_lanes)


@rana_fwd.register_fake
def _(q, k, v, q_pixels, k_offsets, hk, wk, radius, bias, scalar_lanes=False):
    return q.new_empty((q.shape[0], q.shape[1], v.shape[2])), q.new_empty((q.shape[0], q.shape[1]))


@torch.library.custom_op("ranad::rana_bwd", mutates_args=())
def rana_bwd(dout: torch.Tensor, q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, out: torch.Tensor,
             lse: torch.Tensor, q_pixels: torch.Tensor, k_offsets: torch.Tensor, hk: int, wk: int, radius: float,
             bias: Optional[torch.Tensor], need_dbias: bool, scalar_lanes: bool = False
             ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Backward kernels: (dq, dk, dv, dbias); dbias is an empty tensor when not needed."""
    dy, dx0, dx1, R = _disc_args(radius)
    dout = dout.contiguous()
    scale = 1.0 / math.sqrt(q.shape[2])
    if q.is_cuda:
        delta = torch.einsum("nhc,nhc->nh", dout, out).contiguous()  # no [N, H, dv] product (~5x faster)
        dq, dk, dv, dbias = load_cuda_extension().backward(dout, q, k, v, lse, delta, q_pixels, k_offsets, hk, wk, dy,
                                                           dx0, dx1, R, bias, scale, need_dbias,
                                                           torch.cuda.current_stream(q.device).cuda_stream)
    else:  # the CPU kernels compute delta = dout . out themselves, in the dQ pass
        ext = load_cpu_extension()
        dq, dk, dv, dbias = ext.backward(dout, q, k, v, out.contiguous(), lse, q_pixels, k_offsets, hk, wk, dy, dx0,
                                         dx1, R, bias, scale, need_dbias, scalar_lanes)
    if not need_dbias:
        dbias = q.new_empty((0,))
    return dq, dk, dv, dbias


@rana_bwd.register_fake
def _(dout, q, k, v, out, lse, q_pixels, k_offsets, hk, wk, radius, bias, need_dbias, scalar_lanes=False):
    side = disc(radius).side
    db = q.new_empty((q.shape[1], side, side)) if need_dbias else q.new_empty((0,))
    return torch.empty_like(q), torch.empty_like(k), torch.empty_like(v), db


def _setup_context(ctx, inputs, output):
    q, k, v, q_pixels, k_offsets, hk, wk, radius, bias, scalar_lanes = inputs
    out, lse = output
    ctx.save_for_backward(q, k, v, out, lse, q_pixels, k_offsets, bias)
    ctx.geometry = (hk, wk, radius, scalar_lanes)
    ctx.has_bias = bias is not None
    # lse is an output for the backward only: without this autograd would hand the backward a zero-filled
    # [Nq, H] gradient for it on every call (~20 ms at 512x512)
    ctx.set_materialize_grads(False)


def _backward(ctx, dout, dlse):
    if dout is None:  # only lse was used downstream: nothing flows back
        return (None,) * 10
    q, k, v, out, lse, q_pixels, k_offsets, bias = ctx.saved_tensors
    hk, wk, radius, scalar_lanes = ctx.geometry
    need_dbias = ctx.has_bias and ctx.needs_input_grad[8]
    dq, dk, dv, dbias = rana_bwd(dout, q, k, v, out, lse, q_pixels, k_offsets, hk, wk, radius, bias, need_dbias,
                                 scalar_lanes)
    return dq, dk, dv, None, None, None, None, None, (dbias if need_dbias else None), None


rana_fwd.register_autograd(_backward, setup_context=_setup_context)


def _validate(q, k, v, q_pixels, k_offsets, k_size, radius, bias):
    if q.dim() != 3 or k.dim() != 3 or v.dim() != 3:
        raise ValueError("q, k, v must be [N, heads, d]")
    if q.shape[1:] != k.shape[1:] or k.shape[:2] != v.shape[:2]:
        raise ValueError(f"shape mismatch: q {tuple(q.shape)}, k {tuple(k.shape)}, v {tuple(v.shape)}")
    if q_pixels.shape != (q.shape[0], 2):
        raise ValueError(f"q_pixels must be [Nq, 2], got {tuple(q_pixels.shape)}")
    hk, wk = int(k_size[0]), int(k_size[1])
    if k_offsets.shape != (hk * wk + 1,) or int(k_offsets[-1]) != k.shape[0]:
        raise ValueError("k_offsets must be [Hk*Wk+1] cumulative counts ending at the number of key bins")
    if q_pixels.numel():  # one pass over the centres (per-column min and max were 4 passes, ~10 ms at 512x512)
        lo, hi = (t.tolist() for t in q_pixels.aminmax(dim=0))
        if min(lo) < 0 or hi[0] >= hk or hi[1] >= wk:
            raise ValueError("query centres must lie on the key grid")
    if bias is not None:
        side = disc(radius).side
        if bias.shape != (q.shape[1], side, side):
            raise ValueError(f"bias must be [heads, {side}, {side}], got {tuple(bias.shape)}")
    return hk, wk


def _kernel_layout(x: torch.Tensor) -> torch.Tensor:
    """x as the C++ kernels take it: contiguous [N, H, d], or kept channel-major when it is the transposed view of
    a contiguous [N, d, H] tensor (a projection can write k and v that way, and the kernels then skip a copy)."""
    return x if x.is_contiguous() or x.transpose(1, 2).is_contiguous() else x.contiguous()


def rana(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, q_pixels: torch.Tensor, k_offsets: torch.Tensor,
         k_size: tuple[int, int], radius: float, bias: torch.Tensor | None = None,
         backend: Backend = "auto") -> torch.Tensor:
    """Ragged neighbourhood attention (paper Eq. 2-4), multi-head.

    q [Nq, heads, d], k [Nk, heads, d], v [Nk, heads, dv] (float32, or float64 for gradcheck);
    q_pixels int64 [Nq, 2]: (y, x) of each query's centre on the key grid (inside it);
    k_offsets int64 [Hk*Wk+1]: cumulative key-bin counts per key pixel, row-major; k_size (Hk, Wk);
    radius: the L2 disc ||(dy, dx)|| <= radius; bias: optional [heads, 2R+1, 2R+1] (R = floor(radius))
    relative-position bias added to the logits. Returns out [Nq, heads, dv] with scale 1/sqrt(d); a query
    whose disc holds no key bins gets zeros.
    """
    if backend not in ("auto", "cpu", "cpu-scalar", "cuda", "reference"):
        raise ValueError(f"unknown RaNA backend {backend!r}")
    hk, wk = _validate(q, k, v, q_pixels, k_offsets, k_size, radius, bias)
    if backend in ("cpu", "cpu-scalar") and q.is_cuda or backend == "cuda" and not q.is_cuda:
        raise ValueError(f"backend {backend!r} does not run on {q.device.type} tensors")
    if backend == "auto":
        available = cuda_extension_or_none() if q.is_cuda else cpu_extension_or_none()
        backend = ("cuda" if q.is_cuda else "cpu") if available else "reference"
    if backend == "reference":
        return rana_reference(q, k, v, q_pixels, k_offsets, (hk, wk), radius, bias)
    q, k, v = (_kernel_layout(x) for x in (q, k, v))
    q_pixels = q_pixels.to(torch.int64).contiguous()
    k_offsets = k_offsets.to(torch.int64).contiguous()
    if bias is not None:
        bias = bias.to(q.dtype).contiguous()
    args = (q, k, v, q_pixels, k_offsets, hk, wk, float(radius), bias, backend == "cpu-scalar")
    if not _wants_graph(q, k, v, bias):  # inference: the kernels directly, without the dispatcher (whose first
        return _forward_kernels(*args)[0]  # call of a custom op imports torch._dynamo, ~2.4 s per process)
    return rana_fwd(*args)[0]


def _wants_graph(*tensors) -> bool:
    """Whether the op must go through the custom op: a gradient may be needed, or torch.compile is tracing."""
    if torch.compiler.is_compiling():
        return True
    return torch.is_grad_enabled() and any(t is not None and t.requires_grad for t in tensors)
