"""RaNA: the C++ kernels against the torch reference (the oracle), gradients, layouts, determinism."""

from __future__ import annotations

import math

import pytest
import torch

from ranad_core.rana import (bin_pixels, concat_frames, disc, downsample_layout, rana, rana_reference,
                             self_attention_layout)
from ranad_core.rana import extension
from ranad_core.rana.op import rana_fwd


def ragged_offsets(h, w, max_bins=4, seed=0, heavy=True):
    g = torch.Generator().manual_seed(seed)
    counts = torch.randint(0, max_bins + 1, (h * w,), generator=g)
    counts[0] = 0  # an empty corner pixel
    if heavy:
        counts[min(h * w - 1, w + 1)] = 11  # a pixel with 10+ bins
    return torch.cat([torch.zeros(1, dtype=torch.int64), torch.cumsum(counts, 0)])


def qkv(nq, nk, heads, d, dv, dtype, seed=1):
    g = torch.Generator().manual_seed(seed)
    mk = lambda n, c: torch.randn(n, heads, c, generator=g, dtype=dtype)  # noqa: E731
    return mk(nq, d), mk(nk, d), mk(nk, dv)


def layouts(h=7, w=6, seed=0):
    """(name, q_pixels, k_offsets, k_size, nq): every way the model uses RaNA, on one small ragged grid."""
    offs = ragged_offsets(h, w, seed=seed)
    out = []
    qp, ko, ks = self_attention_layout(offs, h, w)
    out.append(("self", qp, ko, ks))
    keep = torch.arange(int(offs[-1])) % 3 != 1  # deterministic bin dropout
    _, q_sparse, sparse_offs = downsample_layout(offs, w, keep)
    out.append(("down", q_sparse, offs, (h, w)))  # sparse queries over all bins
    out.append(("up", bin_pixels(offs, w), sparse_offs, (h, w)))  # all bins over the sparse layout
    frames = [ragged_offsets(h, w, seed=seed + t, heavy=False) for t in range(3)]
    t_offs, _, _ = concat_frames(frames)
    out.append(("temporal", bin_pixels(frames[1], w), t_offs, (h, w)))  # centre frame over 3 frames
    return out


CASES = [(name, radius, with_bias) for name in ("self", "down", "up", "temporal")
         for radius, with_bias in ((0.0, False), (1.0, True), (2.5, True), (2.5, False))]
# "cpu": one query (and head) per SIMD lane, 16 floats or 8 doubles per block with AVX-512, half that with AVX2;
# "cpu-scalar": the same bodies with one lane per block, exactly as a GPU thread runs them.
KERNELS = ("cpu", "cpu-scalar")


def _inputs(name, radius, with_bias, dtype, d=4, dv=3, heads=2):
    lay = {n: (qp, ko, ks) for n, qp, ko, ks in layouts()}[name]
    qp, ko, ks = lay
    q, k, v = qkv(qp.shape[0], int(ko[-1]), heads, d, dv, dtype)
    side = disc(radius).side
    bias = torch.randn(heads, side, side, dtype=dtype) if with_bias else None
    return q, k, v, qp, ko, ks, bias


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("name,radius,with_bias", CASES)
def test_cpu_kernels_gradcheck_float64(name, radius, with_bias, kernel):
    q, k, v, qp, ko, ks, bias = _inputs(name, radius, with_bias, torch.float64)
    tensors = [t.requires_grad_(True) for t in (q, k, v) + ((bias,) if bias is not None else ())]

    def f(q, k, v, *b):
        return rana(q, k, v, qp, ko, ks, radius, b[0] if b else None, backend=kernel)

    assert torch.autograd.gradcheck(f, tensors, eps=1e-6, atol=1e-7, rtol=1e-5)


@pytest.mark.parametrize("name", ["self", "temporal"])
def test_reference_gradcheck_float64(name):
    """fast_mode: the Jacobian checked along random directions (the full one cost ~100 s for the temporal layout on
    a 2-core machine); the C++ kernels' own gradchecks and their match with the reference cover the rest."""
    q, k, v, qp, ko, ks, bias = _inputs(name, 1.5, True, torch.float64)
    tensors = [t.requires_grad_(True) for t in (q, k, v, bias)]
    assert torch.autograd.gradcheck(lambda q, k, v, b: rana_reference(q, k, v, qp, ko, ks, 1.5, b), tensors,
                                    fast_mode=True)


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("name,radius,with_bias", CASES)
def test_cpu_equals_reference_float32(name, radius, with_bias, kernel):
    q, k, v, qp, ko, ks, bias = _inputs(name, radius, with_bias, torch.float32, d=16, dv=16, heads=4)
    grads = []
    for backend in (kernel, "reference"):
        ts = [t.clone().requires_grad_(True) for t in (q, k, v) + ((bias,) if bias is not None else ())]
        out = rana(*ts[:3], qp, ko, ks, radius, ts[3] if bias is not None else None, backend=backend)
        g = torch.autograd.grad(out, ts, torch.linspace(-1, 1, out.numel()).reshape(out.shape))
        grads.append((out, g))
    (a, ga), (b, gb) = grads
    torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)
    for x, y in zip(ga, gb):
        torch.testing.assert_close(x, y, atol=1e-5 * max(1.0, float(y.abs().max())), rtol=1e-5)


@pytest.mark.parametrize("d,dv", [(5, 7), (24, 20), (40, 3), (8, 1), (64, 64)])
def test_head_sizes_padded_to_compiled_sizes(d, dv):
    """Head sizes the kernels are not compiled for run padded with zero channels: same results as the oracle."""
    q, k, v = qkv(*_counts("self"), 2, d, dv, torch.float32)
    qp, ko, ks = {n: (a, b, c) for n, a, b, c in layouts()}["self"]
    bias = torch.randn(2, 5, 5)
    res = []
    for backend in ("cpu", "reference"):
        ts = [t.clone().requires_grad_(True) for t in (q, k, v, bias)]
        out = rana(*ts[:3], qp, ko, ks, 2.5, ts[3], backend=backend)
        res.append((out, *torch.autograd.grad(out, ts, torch.linspace(-1, 1, out.numel()).reshape(out.shape))))
    assert res[0][0].shape == (q.shape[0], 2, dv)
    for x, y in zip(*res):
        x, y = x.detach(), y.detach()
        torch.testing.assert_close(x, y, atol=1e-5 * max(1.0, float(y.abs().max())), rtol=1e-5)


@pytest.mark.parametrize("heads,radius", [(1, 2.0), (3, 2.0), (8, 2.0), (8, 4.5), (4, 4.5)])
def test_head_counts_and_wide_discs(heads, radius):
    """1 head (16 queries per block), padded heads (3 -> 4), two groups of 4 heads, and discs wider than the
    permute tables (R > 3: the gather path) all agree with the oracle, forward and backward."""
    qp, ko, ks = {n: (a, b, c) for n, a, b, c in layouts()}["self"]
    q, k, v = qkv(*_counts("self"), heads, 16, 8, torch.float32)
    side = disc(radius).side
    bias = torch.randn(heads, side, side)
    res = []
    for backend in ("cpu", "reference"):
        ts = [t.clone().requires_grad_(True) for t in (q, k, v, bias)]
        out = rana(*ts[:3], qp, ko, ks, radius, ts[3], backend=backend)
        res.append((out, *torch.autograd.grad(out, ts, torch.linspace(-1, 1, out.numel()).reshape(out.shape))))
    for x, y in zip(*res):
        x, y = x.detach(), y.detach()
        torch.testing.assert_close(x, y, atol=1e-5 * max(1.0, float(y.abs().max())), rtol=1e-5)


def test_channel_major_inputs_need_no_copy_and_agree():
    """q, k, v given as transposed views of contiguous [N, d, H] tensors (as a projection can write them)."""
    qp, ko, ks = {n: (a, b, c) for n, a, b, c in layouts()}["self"]
    nq, nk = _counts("self")
    g = torch.Generator().manual_seed(5)
    cm = [torch.randn(n, 16, 4, generator=g) for n in (nq, nk, nk)]  # [N, d, H] storage
    bias = torch.randn(4, 5, 5)
    res = []
    for inputs in ([x.transpose(1, 2) for x in cm], [x.transpose(1, 2).contiguous() for x in cm]):
        ts = [t.detach().clone() if t.is_contiguous() else t.detach() for t in inputs]
        ts = [t.requires_grad_(True) for t in ts] + [bias.clone().requires_grad_(True)]
        out = rana(*ts[:3], qp, ko, ks, 2.5, ts[3], backend="cpu")
        res.append((out, *torch.autograd.grad(out, ts, torch.linspace(-1, 1, out.numel()).reshape(out.shape))))
    for x, y in zip(*res):
        torch.testing.assert_close(x.detach(), y.detach(), atol=1e-6, rtol=1e-6)
    ref = rana(*[x.transpose(1, 2) for x in cm], qp, ko, ks, 2.5, bias, backend="reference")
    torch.testing.assert_close(res[0][0].detach(), ref, atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("name", ["self", "down", "up", "temporal"])
@pytest.mark.parametrize("heads,d", [(4, 8), (8, 8), (4, 16), (2, 6), (2, 13)])
def test_channel_major_operands_of_the_models_sizes_agree_with_the_oracle(name, heads, d):
    """The model's own cases: q, k, v as channel-major views; 4 heads per block (one or two head groups, so the
    second group's rows start at head 4), value rows of 8 or 16 channels (stored by whole rows on AVX2); 2 heads of
    sizes the kernels pad (a reconstruction's 6 value channels, a gated one's 13 q/k channels: padded and grouped in
    one pass). Every layout, so blocks of one entry (a row's last) and of several occur. Against the reference."""
    qp, ko, ks = {n: (a, b, c) for n, a, b, c in layouts()}[name]
    nq, nk = qp.shape[0], int(ko[-1])
    g = torch.Generator().manual_seed(11)
    q, k, v = (torch.randn(n, d, heads, generator=g).transpose(1, 2) for n in (nq, nk, nk))
    bias = torch.randn(heads, 5, 5, generator=g)
    out = rana(q, k, v, qp, ko, ks, 2.5, bias, backend="cpu")
    ref = rana(q, k, v, qp, ko, ks, 2.5, bias, backend="reference")
    torch.testing.assert_close(out, ref, atol=1e-5, rtol=1e-5)


def _counts(name):
    """(queries, key bins) of one of the test layouts."""
    qp, ko, _ = {n: (a, b, c) for n, a, b, c in layouts()}[name]
    return qp.shape[0], int(ko[-1])


def test_definition_on_a_hand_example():
    """One query, two key pixels inside the disc and one outside: softmax over exactly the disc's bins."""
    offs = torch.tensor([0, 1, 3, 4])  # 1x3 grid: pixel 0 one bin, pixel 1 two bins, pixel 2 one bin
    q = torch.tensor([[[1.0, 0.0]]])
    k = torch.tensor([[[0.0, 0.0]], [[2.0, 0.0]], [[1.0, 1.0]], [[5.0, 5.0]]])
    v = torch.tensor([[[1.0]], [[2.0]], [[3.0]], [[100.0]]])
    qp = torch.tensor([[0, 0]])
    for backend in ("cpu", "reference"):
        out = rana(q, k, v, qp, offs, (1, 3), 1.0, backend=backend)
        logits = torch.tensor([0.0, 2.0, 1.0]) / math.sqrt(2)
        expected = (torch.softmax(logits, 0) * torch.tensor([1.0, 2.0, 3.0])).sum()
        torch.testing.assert_close(out.flatten(), expected.reshape(1))


def test_empty_disc_gives_zeros_and_zero_grads():
    offs = torch.tensor([0, 0, 0, 2])  # only the last of 3 pixels has bins
    q, k, v = qkv(2, 2, 2, 4, 3, torch.float64)
    qp = torch.tensor([[0, 0], [0, 2]])
    for backend in ("cpu", "reference"):
        qq = q.clone().requires_grad_(True)
        out = rana(qq, k, v, qp, offs, (1, 3), 1.0, backend=backend)
        assert torch.all(out[0] == 0) and torch.any(out[1] != 0)
        (g,) = torch.autograd.grad(out.sum(), [qq])
        assert torch.all(g[0] == 0)


def test_deterministic_across_runs_and_threads():
    offs = ragged_offsets(24, 20, max_bins=6, seed=3)
    qp, ko, ks = self_attention_layout(offs, 24, 20)
    q, k, v = qkv(qp.shape[0], int(ko[-1]), 4, 16, 16, torch.float32)
    bias = torch.randn(4, 7, 7)
    results = []
    before = torch.get_num_threads()
    try:
        for threads in (1, 2, 2):
            torch.set_num_threads(threads)
            ts = [t.clone().requires_grad_(True) for t in (q, k, v, bias)]
            out = rana(*ts[:3], qp, ko, ks, 3.5, ts[3], backend="cpu")
            grads = torch.autograd.grad(out, ts, torch.ones_like(out))
            results.append((out, *grads))
    finally:
        torch.set_num_threads(before)
    for other in results[1:]:
        for x, y in zip(results[0], other):
            assert torch.equal(x, y)


def test_large_outputs_reuse_freed_buffers_only():
    """Outputs of 4 MiB and more come from the kernels' buffer cache (cuda/rana_cpu_buffers.h): a freed output's
    buffer is taken by the next call, a live output's never is, and a reused buffer holds exactly the new result."""
    side = 210
    offs = torch.cat([torch.zeros(1, dtype=torch.int64), torch.full((side * side,), 3).cumsum(0)])
    qp, ko, ks = self_attention_layout(offs, side, side)
    g = torch.Generator().manual_seed(9)
    q, k, v = (torch.randn(int(offs[-1]), 16, 4, generator=g).transpose(1, 2) for _ in range(3))
    first = rana(q, k, v, qp, ko, ks, 1.5, backend="cpu")
    assert first.numel() * first.element_size() >= 32 << 20  # large enough for the cache
    keep = first.clone()
    second = rana(q, k, v, qp, ko, ks, 1.5, backend="cpu")
    assert second.data_ptr() != first.data_ptr()
    assert torch.equal(first, keep) and torch.equal(second, keep)
    freed = {first.data_ptr(), second.data_ptr()}
    del first, second
    doubled = rana(q, k, v * 2, qp, ko, ks, 1.5, backend="cpu")  # softmax weights unchanged, values doubled
    assert doubled.data_ptr() in freed
    assert torch.equal(doubled, 2 * keep)
    torch.testing.assert_close(keep, rana(q, k, v, qp, ko, ks, 1.5, backend="reference"), atol=1e-5, rtol=1e-5)


def test_custom_op_registration():
    q, k, v, qp, ko, ks, bias = _inputs("self", 1.5, True, torch.float32)
    args = (q.requires_grad_(True), k.requires_grad_(True), v, qp, ko, ks[0], ks[1], 1.5, bias.requires_grad_(True))
    torch.library.opcheck(rana_fwd, args)


def test_validation_errors():
    q, k, v, qp, ko, ks, bias = _inputs("self", 1.5, True, torch.float32)
    with pytest.raises(ValueError, match="bias must be"):
        rana(q, k, v, qp, ko, ks, 2.5, bias)
    with pytest.raises(ValueError, match="query centres"):
        rana(q, k, v, qp + 100, ko, ks, 1.5)
    with pytest.raises(ValueError, match="k_offsets"):
        rana(q, k, v, qp, ko[:-1], ks, 1.5)


def test_fallback_to_reference_with_a_warning(monkeypatch):
    q, k, v, qp, ko, ks, bias = _inputs("self", 1.5, True, torch.float32)
    expected = rana_reference(q, k, v, qp, ko, ks, 1.5, bias)
    monkeypatch.setenv("RANAD_NO_EXTENSION", "1")
    extension.load_cpu_extension.cache_clear()
    extension.cpu_extension_or_none.cache_clear()
    try:
        with pytest.warns(RuntimeWarning, match="using the slow torch reference"):
            out = rana(q, k, v, qp, ko, ks, 1.5, bias)
        torch.testing.assert_close(out, expected)
    finally:
        monkeypatch.delenv("RANAD_NO_EXTENSION")
        extension.load_cpu_extension.cache_clear()
        extension.cpu_extension_or_none.cache_clear()
    assert extension.cpu_extension_or_none() is not None


def test_disc_is_the_l2_disc():
    for r in (0.0, 1.0, 1.5, 2.5, 3.5):
        d = disc(r)
        expected = {(y, x) for y in range(-4, 5) for x in range(-4, 5) if y * y + x * x <= r * r}
        assert set(d.offsets()) == expected and d.size == len(expected)
    assert disc(3.5).size == 37


def test_concat_frames_matches_a_loop():
    frames = [ragged_offsets(3, 4, seed=s, heavy=False) for s in range(3)]
    offs, gather, frame = concat_frames(frames)
    base = [0, int(frames[0][-1]), int(frames[0][-1]) + int(frames[1][-1])]
    rows = []
    for p in range(12):
        for t, o in enumerate(frames):
            rows += [(base[t] + i, t) for i in range(int(o[p]), int(o[p + 1]))]
    assert gather.tolist() == [r for r, _ in rows] and frame.tolist() == [t for _, t in rows]
    assert offs[-1] == len(rows)


def test_downsample_layout_keeps_pixels():
    offs = ragged_offsets(5, 4, seed=2)
    keep = torch.arange(int(offs[-1])) % 2 == 0
    idx, qp, sparse = downsample_layout(offs, 4, keep)
    assert torch.equal(qp, bin_pixels(offs, 4)[idx]) and int(sparse[-1]) == int(keep.sum())
    assert torch.equal(bin_pixels(sparse, 4), qp)


def test_inference_calls_the_kernels_directly_and_equally():
    """Without a gradient the op calls the kernels directly (the custom op's first call imports torch._dynamo,
    ~2.4 s per process): the same numbers as through the custom op, and a fresh process denoising a tile never
    imports torch._dynamo."""
    import subprocess
    import sys

    from ranad_core.rana import op

    q, k, v, qp, ko, ks, bias = _inputs("self", 2.5, True, torch.float32)
    args = (q, k, v, qp, ko, ks[0], ks[1], 2.5, bias, False)
    with torch.inference_mode():
        direct = rana(q, k, v, qp, ko, ks, 2.5, bias, backend="cpu")
        via_op = op.rana_fwd(*args)[0]
    torch.testing.assert_close(direct, via_op, rtol=0, atol=0)
    code = ("import sys, torch\n"
            "from ranad_core.rana import rana, self_attention_layout\n"
            "offs = torch.arange(0, 2 * 64 + 1, 2)\n"
            "qp, ko, ks = self_attention_layout(offs, 8, 8)\n"
            "x = torch.randn(128, 2, 8)\n"
            "with torch.inference_mode():\n"
            "    rana(x, x, x, qp, ko, ks, 2.5, backend='cpu')\n"
            "assert 'torch._dynamo' not in sys.modules\n"
            "y = x.clone().requires_grad_()\n"
            "rana(y, x, x, qp, ko, ks, 2.5, backend='cpu').sum().backward()\n"
            "assert y.grad is not None\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
