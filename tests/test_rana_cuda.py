"""The CUDA RaNA kernels against the reference, on the CPU tests' cases (they need a GPU and CUDA torch).

Both CUDA designs are checked: the staged kernels (the default: a block of neighbouring entries shares the key or
query rows through shared memory, cuda/rana_cuda_staged.cu) and the one-thread kernels they fall back to (the block
bodies of cuda/rana_math.h with one lane per thread, which `backend="cpu-scalar"` runs in test_rana.py on every
machine). Without a GPU these tests skip; CI compiles the CUDA sources for sm_80/86/89/90 (cuda/check_build.sh).
"""

from __future__ import annotations

import pytest
import torch

from ranad_core.rana import rana
from test_rana import CASES, _inputs, qkv, ragged_offsets

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(),
                                reason="no CUDA GPU here (CUDA kernels are compile-checked by cuda/check_build.sh)")

DESIGNS = ("staged", "one-thread")


@pytest.fixture
def design(request):
    """Switches the process to one CUDA kernel design (request.param, or (design, rows per chunk)) for a test."""
    from ranad_core.rana.extension import load_cuda_extension

    ext = load_cuda_extension()
    name, chunk = request.param if isinstance(request.param, tuple) else (request.param, 0)
    before = ext.configure(True, 0)
    ext.configure(name == "staged", chunk)
    yield name
    ext.configure(*before)


def _against_reference(q, k, v, qp, ko, ks, radius, bias, atol=1e-5):
    """Output and every gradient of the CUDA backend against the torch reference on the CPU."""
    dev = torch.device("cuda")
    grads = []
    for backend, device in (("cuda", dev), ("reference", torch.device("cpu"))):
        ts = [t.clone().to(device).requires_grad_(True) for t in (q, k, v) + ((bias,) if bias is not None else ())]
        out = rana(*ts[:3], qp.to(device), ko.to(device), ks, radius, ts[3] if bias is not None else None,
                   backend=backend)
        g = torch.autograd.grad(out, ts, torch.linspace(-1, 1, out.numel(), device=device).reshape(out.shape))
        grads.append((out.cpu(), [x.cpu() for x in g]))
    (a, ga), (b, gb) = grads
    torch.testing.assert_close(a, b, atol=atol, rtol=1e-5)
    for x, y in zip(ga, gb):
        torch.testing.assert_close(x, y, atol=atol * max(1.0, float(y.abs().max())), rtol=1e-5)


@pytest.mark.parametrize("design", DESIGNS, indirect=True)
@pytest.mark.parametrize("name,radius,with_bias", CASES)
def test_cuda_equals_reference(name, radius, with_bias, design):
    q, k, v, qp, ko, ks, bias = _inputs(name, radius, with_bias, torch.float32, d=16, dv=16, heads=4)
    _against_reference(q, k, v, qp, ko, ks, radius, bias)


@pytest.mark.parametrize("design", [("staged", 4)], indirect=True)
@pytest.mark.parametrize("heads,d,dv", [(1, 8, 3), (3, 16, 8), (8, 32, 16)])
def test_staged_kernels_across_chunks_heads_and_query_orders(heads, d, dv, design):
    """Chunks of 4 rows (a pixel's bins and a block's discs straddle chunks), head counts that do not divide a
    block's 128 threads, a radius-5 disc with a bias, and queries in a random order (a block's entries then lie on
    many grid rows: the kernels group them into runs of one row each)."""
    from ranad_core.rana import self_attention_layout

    offs = ragged_offsets(13, 17, max_bins=6, seed=5)
    qp, ko, ks = self_attention_layout(offs, 13, 17)
    perm = torch.randperm(qp.shape[0], generator=torch.Generator().manual_seed(2))
    q, k, v = qkv(qp.shape[0], int(ko[-1]), heads, d, dv, torch.float32, seed=4)
    bias = torch.randn(heads, 11, 11)
    for pixels in (qp, qp[perm]):
        _against_reference(q, k, v, pixels, ko, ks, 5.5, bias, atol=2e-5)


@pytest.mark.parametrize("design", [("staged", 5)], indirect=True)
def test_staged_equals_one_thread(design):
    """The two CUDA designs on a 48 x 40 layout (0..6 bins per pixel): equal outputs and gradients."""
    from ranad_core.rana import self_attention_layout
    from ranad_core.rana.extension import load_cuda_extension

    offs = ragged_offsets(48, 40, max_bins=6, seed=8)
    qp, ko, ks = self_attention_layout(offs, 48, 40)
    q, k, v = qkv(qp.shape[0], int(ko[-1]), 4, 16, 16, torch.float32, seed=9)
    bias = torch.randn(4, 7, 7)
    gout = torch.randn(qp.shape[0], 4, 16).cuda()
    results = []
    for staged in (True, False):
        load_cuda_extension().configure(staged, 0)
        ts = [t.cuda().requires_grad_(True) for t in (q, k, v, bias)]
        out = rana(*ts[:3], qp.cuda(), ko.cuda(), ks, 3.5, ts[3], backend="cuda")
        results.append((out, *torch.autograd.grad(out, ts, gout)))
    for x, y in zip(*results):
        torch.testing.assert_close(x, y, atol=2e-5 * max(1.0, float(y.detach().abs().max())), rtol=1e-5)


@pytest.mark.parametrize("design", DESIGNS, indirect=True)
@pytest.mark.parametrize("name,radius,with_bias", CASES[:4])
def test_cuda_gradcheck_float64(name, radius, with_bias, design):
    q, k, v, qp, ko, ks, bias = _inputs(name, radius, with_bias, torch.float64)
    dev = torch.device("cuda")
    ts = [t.to(dev).requires_grad_(True) for t in (q, k, v) + ((bias,) if bias is not None else ())]
    fn = lambda *a: rana(*a[:3], qp.to(dev), ko.to(dev), ks, radius, a[3] if len(a) > 3 else None,  # noqa: E731
                         backend="cuda")
    assert torch.autograd.gradcheck(fn, ts, atol=1e-6, rtol=1e-4)


@pytest.mark.parametrize("design", DESIGNS, indirect=True)
def test_cuda_is_deterministic(design):
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
