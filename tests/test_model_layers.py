"""Model building blocks: bin dropout, the RaNA block, and the reconstruction's linearity in the noisy values."""

from __future__ import annotations

import torch

import pytest

from ranad_core.model import CONFIGS, Layout, ModelConfig, MultiUNet, RaNABlock, Reconstruction, bin_dropout, get_config


def layout(h=9, w=8, max_bins=5, seed=0):
    g = torch.Generator().manual_seed(seed)
    counts = torch.randint(0, max_bins + 1, (h * w,), generator=g)
    return Layout.of(torch.cat([torch.zeros(1, dtype=torch.int64), torch.cumsum(counts, 0)]), h, w)


def test_bin_dropout_halves_each_pixel_and_patterns_alternate():
    lay = layout()
    k0, c0 = bin_dropout(lay, 0)
    k1, c1 = bin_dropout(lay, 1)
    assert set(k0.tolist()).isdisjoint(k1.tolist()) and len(k0) + len(k1) == lay.bins
    counts = lay.offsets[1:] - lay.offsets[:-1]
    for c in (c0, c1):
        kept = c.offsets[1:] - c.offsets[:-1]
        assert torch.all((kept == counts // 2) | (kept == (counts + 1) // 2))
        assert torch.equal(c.pixels, torch.stack([torch.repeat_interleave(torch.arange(72), kept) // 8,
                                                  torch.repeat_interleave(torch.arange(72), kept) % 8], 1))
    assert torch.equal(lay.pixels[k0], c0.pixels)


def test_bin_dropout_is_computed_once_per_layout_pattern_and_level():
    """The reconstructions reuse the backbone's dropouts (Layout.dropouts): the same call gives the same tensors,
    and every (pattern, level, lattice) its own, equal to a fresh computation on a fresh layout."""
    from ranad_core.model.layers import _bin_dropout

    lay = layout()
    for lattice in (False, True):
        for level in (1, 2, 3):
            for pattern in (0, 1):
                kept, coarse = bin_dropout(lay, pattern, level, lattice)
                again = bin_dropout(lay, pattern, level, lattice)
                assert again[0] is kept and again[1] is coarse
                fresh_kept, fresh = _bin_dropout(layout(), pattern, level, lattice)
                assert torch.equal(kept, fresh_kept) and torch.equal(coarse.offsets, fresh.offsets)
                assert torch.equal(coarse.pixels, fresh.pixels)


def test_kept_rows_are_gathered_once_per_features_at_inference():
    """kept_rows is feat[kept]; at inference a second call on the same features returns the same tensor (the output
    layers' reconstructions share it), other features or another dropout their own rows, and with gradients on
    nothing is kept (each call its own graph node)."""
    from ranad_core.model.layers import kept_rows

    lay = layout()
    feat, other = torch.randn(lay.bins, 5), torch.randn(lay.bins, 5)
    with torch.inference_mode():
        for pattern, level, lattice in ((0, 1, True), (1, 2, True), (1, 1, False)):
            kept = bin_dropout(lay, pattern, level, lattice)[0]
            rows = kept_rows(lay, pattern, level, lattice, feat)
            assert torch.equal(rows, feat[kept])
            assert kept_rows(lay, pattern, level, lattice, feat) is rows
            theirs = kept_rows(lay, pattern, level, lattice, other)
            assert theirs is not rows and torch.equal(theirs, other[kept])
    lay = layout()
    w = torch.randn(lay.bins, 5, requires_grad=True)
    first, second = kept_rows(lay, 0, 1, True, w), kept_rows(lay, 0, 1, True, w)
    assert first is not second and not lay.gathers
    (first.sum() + second.sum()).backward()
    kept = bin_dropout(lay, 0, 1, True)[0]
    assert torch.equal(w.grad[kept], torch.full((len(kept), 5), 2.0))


def test_lattice_dropout_keeps_single_bin_pixels_on_ever_sparser_lattices():
    """A frame of single-bin pixels, four down-sampling levels, both patterns at each level: with the lattice,
    level L keeps exactly 1/2^L of the pixels, each level's bins are a subset of the level above's, and from level
    2 on the kept pixels are a regular lattice (constant y and x modulo the spacing). The first models' dropout
    keeps none at level 2 (what dropout_lattice mends). A multi-bin frame still halves every pixel's bins."""
    h = w = 32
    single = Layout.of(torch.arange(h * w + 1), h, w)
    for patterns in ((0, 1, 0, 1), (1, 0, 1, 0), (0, 0, 1, 1)):
        lay, ids = single, torch.arange(h * w)
        for level, pattern in enumerate(patterns, 1):
            kept, lay = bin_dropout(lay, pattern, level, lattice=True)
            ids = ids[kept]
            assert lay.bins == h * w // 2 ** level
            y, x = ids // w, ids % w
            if level >= 2:
                step = 2 ** (level // 2)
                assert len(set((y % step).tolist())) == 1 and len(set((x % step).tolist())) == 1
    kept, first = bin_dropout(single, 0)
    assert first.bins == h * w // 2 and bin_dropout(first, 1)[1].bins == 0
    lay = layout()
    counts = lay.offsets[1:] - lay.offsets[:-1]
    for level in (1, 2, 3):
        kept = bin_dropout(lay, 0, level, lattice=True)[1]
        n = kept.offsets[1:] - kept.offsets[:-1]
        assert torch.all((n == counts // 2) | (n == (counts + 1) // 2))


def test_rana_block_shapes_and_gradients():
    lay = layout()
    torch.manual_seed(0)
    block = RaNABlock(dim=32, heads=4, head_dim=8, radius=2.5)
    feat = torch.randn(lay.bins, 32, requires_grad=True)
    out = block(feat, lay)
    assert out.shape == feat.shape
    out.square().mean().backward()
    assert feat.grad is not None and torch.isfinite(feat.grad).all()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in block.parameters())
    assert block.attn.bias.grad.abs().sum() > 0


def test_reconstruction_is_linear_in_the_noisy_values_and_batches_aovs():
    lay = layout(seed=3)
    torch.manual_seed(1)
    rec = Reconstruction(dim=16, scales=3, heads=2, head_dim=8, radius=1.5)
    feat = torch.randn(lay.bins, 16)
    x, y = torch.rand(lay.bins, 3), torch.rand(lay.bins, 3)
    with torch.no_grad():
        fx, fy = rec(feat, lay, x), rec(feat, lay, y)
        torch.testing.assert_close(rec(feat, lay, 2.0 * x - 0.5 * y), 2.0 * fx - 0.5 * fy, atol=1e-5, rtol=1e-5)
        both = rec(feat, lay, torch.cat([x, y], 1))  # AOVs batched in the value channels: same kernels
        torch.testing.assert_close(both, torch.cat([fx, fy], 1), atol=1e-6, rtol=1e-6)
        # light groups that sum to the beauty give denoised groups that sum to the denoised beauty
        torch.testing.assert_close(fx + fy, rec(feat, lay, x + y), atol=1e-5, rtol=1e-5)


def test_multi_unet_keeps_the_layout_and_trains():
    lay = layout(h=10, w=9, seed=4)
    torch.manual_seed(2)
    net = MultiUNet(dim=16, unets=2, levels=2, blocks_per_level=1, heads=4, head_dim=4, radius=1.5,
                    radius_growth=1.0)
    feat = torch.randn(lay.bins, 16)
    target = torch.randn(lay.bins, 16)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    losses = []
    for _ in range(30):
        loss = (net(feat, lay) - target).square().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert net(feat, lay).shape == feat.shape
    assert losses[-1] < 0.8 * losses[0]


def test_config_registry_round_trips():
    for name, cfg in CONFIGS.items():
        assert get_config(name) is cfg
        assert ModelConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError, match="unknown model config"):
        get_config("nope")


def test_ranad_on_the_example_shot_learns_toward_the_reference():
    """The assembled model on ranad synth's example: outputs for every layer, and a few steps of training on
    the reference reduce the error of the denoised diffuse layer (the whole pipeline is differentiable)."""
    from pathlib import Path

    from ranad_core.exr import read_deep
    from ranad_core.model import RaNAD, feature_dim, prepare

    shot = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"
    noisy = prepare(read_deep(shot / "noisy_spp16.0001.exr"))
    ref = prepare(read_deep(shot / "reference_spp16.0001.exr"))
    assert noisy.feature_dim == feature_dim()
    torch.manual_seed(0)
    model = RaNAD(get_config("cpu-small"), feature_dim())
    out = model(noisy)
    assert set(out) == {"diffuse", "specular", "alpha", "depth"}
    for name, val in out.items():
        assert val.shape == noisy.layers[name].shape and torch.isfinite(val).all()

    def loss():
        d = model(noisy)["diffuse"]
        t = ref.layers["diffuse"]
        return ((d - t).abs() / (d.abs() + t.abs() + 1e-2)).mean()  # SMAPE

    opt = torch.optim.Adam(model.parameters(), lr=2e-3)
    first = loss().item()
    for _ in range(8):
        value = loss()
        opt.zero_grad()
        value.backward()
        opt.step()
    assert loss().item() < first


def test_layers_with_no_bins_at_a_coarse_scale():
    """A crop whose bins all drop out at some scale (one bin in one pixel): every module still runs."""
    lay = Layout.of(torch.tensor([0, 0, 1, 1, 1]), 2, 2)  # only pixel (0, 1) holds a bin
    torch.manual_seed(0)
    net = MultiUNet(dim=8, unets=2, levels=2, blocks_per_level=1, heads=4, head_dim=2, radius=1.0, radius_growth=1.0)
    rec = Reconstruction(dim=8, scales=3, heads=2, head_dim=4, radius=1.0)
    feat = torch.randn(1, 8)
    assert net(feat, lay).shape == (1, 8)
    assert rec(feat, lay, torch.ones(1, 3)).shape == (1, 3)
