"""The fused inference path of the per-bin layers (model/fused.py, cuda/rows_cpu.cpp): each row kernel equals the
torch ops it replaces, and a model's output with the path equals its output without it (the plain torch modules are
the oracle), to float rounding."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
import torch.nn.functional as F

from ranad_core.channels import canonical, detect
from ranad_core.exr import read_deep
from ranad_core.model import RaNAD, feature_dim, fused, get_config, prepare
from ranad_core.rana.extension import cpu_extension_or_none

FRAME = Path(__file__).resolve().parents[1] / "examples" / "synth_shot" / "noisy_spp16.0001.exr"
ext = cpu_extension_or_none()
pytestmark = pytest.mark.skipif(ext is None, reason="the C++ extension could not be built here (no compiler)")


def close(a, b, tol=1e-5):
    scale = float(b.abs().max()) + 1e-6
    assert float((a - b).abs().max()) <= tol * scale, float((a - b).abs().max()) / scale


@pytest.mark.parametrize("rows,c,outs", [(1000, 32, [32, 32, 32]), (53, 43, [20]), (7, 32, [16, 5])])
@pytest.mark.parametrize("with_norm", [True, False])
def test_ln_linear_is_layer_norm_then_linear(rows, c, outs, with_norm):
    """Rows not a multiple of the micro-kernel's, outputs not a multiple of a vector (the remainder paths)."""
    g = torch.Generator().manual_seed(rows + c)
    x = torch.randn(rows, c, generator=g) * 3 + 1
    lw, lb = torch.rand(c, generator=g) + 0.5, torch.randn(c, generator=g)
    w, b = torch.randn(sum(outs), c, generator=g), torch.randn(sum(outs), generator=g)
    got = ext.rows_ln_linear(x, lw if with_norm else None, lb if with_norm else None, 1e-5, w.t().contiguous(), b,
                             outs)
    xn = F.layer_norm(x, (c,), lw, lb, 1e-5) if with_norm else x
    want = torch.split(F.linear(xn, w, b), outs, 1)
    assert [tuple(t.shape) for t in got] == [(rows, o) for o in outs]
    for a, e in zip(got, want):
        assert a.is_contiguous()
        close(a, e)


@pytest.mark.parametrize("c", [32, 48, 43])
def test_layer_norm_does_not_depend_on_where_a_row_falls(c):
    """The fused LayerNorm's result for a row is the same bit for bit whatever rows come before it and however many
    follow (tiles of a frame against the whole frame; a faster LayerNorm over groups of rows must keep this), on
    one thread and two."""
    g = torch.Generator().manual_seed(c)
    x = torch.randn(301, c, generator=g) * 5 + 2
    lw, lb = torch.rand(c, generator=g) + 0.5, torch.randn(c, generator=g)
    wt, b = torch.eye(c), torch.zeros(c)
    (whole,) = ext.rows_ln_linear(x, lw, lb, 1e-5, wt, b, [c])
    close(whole, F.layer_norm(x, (c,), lw, lb, 1e-5))
    for start in (1, 5, 17, 64, 300):
        (part,) = ext.rows_ln_linear(x[start:].contiguous(), lw, lb, 1e-5, wt, b, [c])
        assert torch.equal(part, whole[start:]), start
    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        (one,) = ext.rows_ln_linear(x, lw, lb, 1e-5, wt, b, [c])
    finally:
        torch.set_num_threads(threads)
    assert torch.equal(one, whole)


@pytest.mark.parametrize("two", [False, True])
def test_linear_residual(two):
    g = torch.Generator().manual_seed(1)
    res, y1, y2 = (torch.randn(101, 32, generator=g) for _ in range(3))
    w1, w2, b = torch.randn(32, 32, generator=g), torch.randn(32, 32, generator=g), torch.randn(32, generator=g)
    got = ext.rows_linear_residual(res, y1, w1.t().contiguous(), y2 if two else None,
                                   w2.t().contiguous() if two else None, b)
    want = res + F.linear(y1, w1, b) + (F.linear(y2, w2) if two else 0)
    close(got, want)


@pytest.mark.parametrize("with_norm,residual,c", [(True, True, 32), (False, False, 43)])
def test_mlp(with_norm, residual, c):
    g = torch.Generator().manual_seed(2)
    x = torch.randn(333, c, generator=g)
    lw, lb = torch.rand(c, generator=g), torch.randn(c, generator=g)
    w1, b1 = torch.randn(64, c, generator=g), torch.randn(64, generator=g)
    out = c if residual else 32
    w2, b2 = torch.randn(out, 64, generator=g), torch.randn(out, generator=g)
    got = ext.rows_mlp(x, lw if with_norm else None, lb if with_norm else None, 1e-5, w1.t().contiguous(), b1,
                       w2.t().contiguous(), b2, residual)
    xn = F.layer_norm(x, (c,), lw, lb, 1e-5) if with_norm else x
    want = F.linear(torch.relu(F.linear(xn, w1, b1)), w2, b2) + (x if residual else 0)
    close(got, want)


def test_bad_shapes_are_refused():
    x = torch.randn(10, 32)
    with pytest.raises(RuntimeError, match="splits add up"):
        ext.rows_ln_linear(x, None, None, 1e-5, torch.randn(32, 8), torch.randn(8), [4, 5])
    with pytest.raises(RuntimeError, match="input channels"):
        ext.rows_linear_residual(x, x, torch.randn(16, 32), None, None, torch.randn(32))
    with pytest.raises(RuntimeError, match="contiguous"):
        ext.rows_mlp(x.t(), None, None, 1e-5, torch.randn(10, 4), torch.randn(4), torch.randn(4, 10),
                     torch.randn(10), True)


@pytest.mark.parametrize("heads,d", [(2, 8), (4, 16), (1, 3)])
def test_wide_operand_equals_the_python_assembly(heads, d, monkeypatch):
    """The gated kernels' wide q and k operands from the one-pass op (what _with_range uses at inference) equal, bit
    for bit, the ones _with_range writes block by block without it (projection scaled, gate terms on every head,
    zeros), in the same channel-major layout."""
    from ranad_core.model.reconstruction import KernelAttention, gate_terms, wide_dim

    torch.manual_seed(heads)
    mod = KernelAttention(16, heads, d, 2.5, gated=True)
    nq, nk = 101, 77
    q, k = torch.randn(nq, d * heads), torch.randn(nk, d * heads)
    a, b = torch.randn(nq, 3), torch.randn(nk, 3)
    a[:, -1], b[:, -1] = a[:, -1].abs() * 50, b[:, -1].abs() * 50     # lambdas, non-negative
    views = q.view(nq, d, heads).transpose(1, 2), k.view(nk, d, heads).transpose(1, 2)
    with torch.inference_mode():
        fq2, fk2 = mod._with_range(*views, (a, b))             # the fused path
        monkeypatch.setenv("RANAD_NO_FUSED", "1")
        qa, kb = mod._with_range(*views, (a, b))               # block by block
        monkeypatch.delenv("RANAD_NO_FUSED")
        tq, tk = gate_terms(a, b)
        wide = wide_dim(d, tq.shape[1])
        s = wide ** 0.5
        fq = fused.wide_operand(q, heads, s / d ** 0.5, tq, s, wide)
        fk = fused.wide_operand(k, heads, 1.0, tk, 1.0, wide)
    assert fq.shape == qa.shape == (nq, heads, wide) and fk.shape == kb.shape == (nk, heads, wide)
    assert torch.equal(fq, qa) and torch.equal(fk, kb) and torch.equal(fq2, qa) and torch.equal(fk2, kb)
    assert fq.transpose(1, 2).is_contiguous()    # channel-major, as the kernels stream it
    with pytest.raises(RuntimeError, match="do not fit"):
        fused.wide_operand(q, heads, 1.0, torch.randn(nq, wide), 1.0, wide)
    with pytest.raises(RuntimeError, match="term rows"):
        fused.wide_operand(q, heads, 1.0, tq[:5], 1.0, wide)


@pytest.mark.parametrize("scales,c", [(1, 3), (2, 6), (3, 1), (4, 9)])
def test_scale_mix_is_the_softmax_mix_and_thread_free(scales, c):
    """The fused scale mixer: softmax(mixer(feat)) over each row's scales, the scales' results mixed by it, as the
    torch ops compute it (to rounding); equal bit for bit on one thread and two, and a convex mix (a constant
    result comes back unchanged)."""
    torch.manual_seed(scales)
    feat = torch.randn(1003, 32)
    mixer = torch.nn.Linear(32, scales)
    outs = [torch.randn(1003, c) for _ in range(scales)]
    with torch.inference_mode():
        w = torch.softmax(mixer(feat), dim=1)
        expect = sum(w[:, s, None] * outs[s] for s in range(scales))
        got = fused.scale_mix(feat, mixer, outs)
        close(got, expect, 1e-5)
        threads = torch.get_num_threads()
        try:
            torch.set_num_threads(1)
            one = fused.scale_mix(feat, mixer, outs)
        finally:
            torch.set_num_threads(threads)
        assert torch.equal(one, got)
        flat = fused.scale_mix(feat, mixer, [torch.full((1003, c), 0.25)] * scales)
        close(flat, torch.full((1003, c), 0.25), 2e-7 * scales)
    with pytest.raises(RuntimeError, match="results for"):
        fused.scale_mix(feat, mixer, outs[:-1] + [outs[0]] * 2)


@pytest.mark.parametrize("config", ["cpu-small-pd", "cpu-small", "cpu-small-pdl-gall", "cpu-small-pdl-gza",
                                    "cpu-small-pdr"])
def test_model_output_equals_the_plain_modules(config, monkeypatch):
    """A whole single-frame model (input embedding, both U-Nets, every reconstruction) with and without the fused
    path, on the bundled frame: the same output to float rounding, and the path was taken."""
    from ranad_core.model.prior import frame_scale, with_prior

    img = read_deep(FRAME)
    srt = canonical(img, detect(img))[0].sorted()[0]
    cfg = get_config(config)
    if cfg.features == "prior":
        srt = with_prior(srt, None, presorted=True)
        inputs = prepare(srt, features="prior", scale=frame_scale(srt))
    else:
        inputs = prepare(srt)
    torch.manual_seed(0)
    model = RaNAD(cfg, feature_dim(cfg.features)).eval()
    calls, wide = [], []
    real, real_wide = fused.ln_linear, fused.wide_operand
    monkeypatch.setattr(fused, "ln_linear", lambda *a: calls.append(1) or real(*a))
    monkeypatch.setattr(fused, "wide_operand", lambda *a: wide.append(1) or real_wide(*a))
    with torch.inference_mode():
        fast = model(inputs)
        assert calls, "the fused path was not taken"
        assert bool(wide) == bool(cfg.layer_gate and not cfg.prior_range), "gated operands: the one-pass path"
        monkeypatch.setenv("RANAD_NO_FUSED", "1")
        n = len(calls)
        plain = model(inputs)
        assert len(calls) == n
    for k in plain:
        close(fast[k], plain[k], 1e-4)


def test_cross_frame_model_equals_the_plain_modules(monkeypatch):
    """The sequence default's kind of model (guarded matching: the neighbours' key MLP and the pair scores take the
    fused path too) on a 3-frame window, with and without the path."""
    from model_factory import demodulating, matching_config
    from ranad_core.denoise import denoise_window
    from ranad_core.model.crossframe import CrossFrameRaNAD

    torch.manual_seed(0)
    single = RaNAD(demodulating(get_config("cpu-small")), feature_dim()).eval()
    model = CrossFrameRaNAD.from_single(single, demodulating(matching_config(guard=True)), feature_dim()).eval()
    for g in model.temporal_gate.values():      # open the temporal step, so its result counts
        torch.nn.init.constant_(g.bias, 0.0)
    frames = [read_deep(FRAME.parent / f"noisy_spp16.{i:04d}.exr") for i in range(3)]
    fast = denoise_window(model, frames, 1).image.values
    monkeypatch.setenv("RANAD_NO_FUSED", "1")
    plain = denoise_window(model, frames, 1).image.values
    close(torch.from_numpy(fast), torch.from_numpy(plain), 1e-4)
