"""The CUDA RaNA kernels against the reference, on the CPU tests' cases (they need a GPU and CUDA torch).

Without a GPU these tests skip; the maths they run is still covered on every machine: the CUDA kernels are the
block bodies of cuda/rana_math.h with one lane per thread, which `backend="cpu-scalar"` runs in test_rana.py,
and CI compiles the CUDA sources for sm_80/86/89/90 (cuda/check_build.sh).
"""

from __future__ import annotations

import pytest
import torch

from ranad_core.rana import rana
from test_rana import CASES, _inputs, qkv, ragged_offsets

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(),
                                reason="no CUDA GPU here (CUDA kernels are compile-checked by cuda/check_build.sh)")


@pytest.mark.parametrize("name,radius,with_bias", CASES)
def test_cuda_equals_reference(name, radius, with_bias):
    q, k, v, qp, ko, ks, bias = _inputs(name, radius, with_bias, torch.float32, d=16, dv=16, heads=4)
    dev = torch.device("cuda")
    grads = []
    for backend, device in (("cuda", dev), ("reference", torch.device("cpu"))):
        ts = [t.clone().to(device).requires_grad_(True) for t in (q, k, v) + ((bias,) if bias is not None else ())]
        out = rana(*ts[:3], qp.to(device), ko.to(device), ks, radius, ts[3] if bias is not None else None,
                   backend=backend)
        g = torch.autograd.grad(out, ts, torch.linspace(-1, 1, out.numel(), device=device).reshape(out.shape))
        grads.append((out.cpu(), [x.cpu() for x in g]))
    (a, ga), (b, gb) = grads
    torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)
    for x, y in zip(ga, gb):
        torch.testing.assert_close(x, y, atol=1e-5 * max(1.0, float(y.abs().max())), rtol=1e-5)


@pytest.mark.parametrize("name,radius,with_bias", CASES[:4])
def test_cuda_gradcheck_float64(name, radius, with_bias):
    q, k, v, qp, ko, ks, bias = _inputs(name, radius, with_bias, torch.float64)
    dev = torch.device("cuda")
    ts = [t.to(dev).requires_grad_(True) for t in (q, k, v) + ((bias,) if bias is not None else ())]
    fn = lambda *a: rana(*a[:3], qp.to(dev), ko.to(dev), ks, radius, a[3] if len(a) > 3 else None,  # noqa: E731
                         backend="cuda")
    assert torch.autograd.gradcheck(fn, ts, atol=1e-6, rtol=1e-4)


def test_cuda_is_deterministic():
    from ranad_core.rana import self_attention_layout

    offs = ragged_offsets(24, 20, max_bins=6, seed=3)
    qp, ko, ks = self_attention_layout(offs, 24, 20)
    q, k, v = qkv(qp.shape[0], int(ko[-1]), 4, 16, 16, torch.float32)
    bias = torch.randn(4, 7, 7)
    results = []
    for _ in range(2):
        ts = [t.cuda().requires_grad_(True) for t in (q, k, v, bias)]
        out = rana(*ts[:3], qp.cuda(), ko.cuda(), ks, 3.5, ts[3], backend="cuda")
        results.append((out, *torch.autograd.grad(out, ts, torch.ones_like(out))))
    for x, y in zip(*results):
        assert torch.equal(x, y)
