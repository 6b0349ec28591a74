"""The matching temporal step (matching.py): pairs are exactly the bins sharing a pixel, the weights are a
softmax per query, the output is linear in the values, and a cross-frame model using it starts as its single-frame
model and tiles like the whole frame."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from model_factory import matching_config
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.model import RaNAD, feature_dim, get_config, prepare
from ranad_core.model.config import ModelConfig
from ranad_core.model.crossframe import CrossFrameRaNAD
from ranad_core.model.inputs import GUIDE_COLUMNS, GUIDE_LAYOUT, GUIDE_WIDTH, guides
from ranad_core.model.layers import Layout
from ranad_core.model.crossframe import temporal_layout
from ranad_core.model.matching import (GUARD, MatchKernel, consistent, pair_features, pair_sum, pixel_pairs,
                                      segment_softmax)
from ranad_core.rana.extension import cpu_extension_or_none
from ranad_core.rana.reference import neighbour_pairs
from ranad_core.motion import compensate

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"


def random_layout(seed: int, h: int = 5, w: int = 7, max_bins: int = 4) -> Layout:
    counts = torch.randint(0, max_bins + 1, (h * w,), generator=torch.Generator().manual_seed(seed))
    return Layout.of(torch.cat([torch.zeros(1, dtype=torch.int64), torch.cumsum(counts, 0)]), h, w)


def test_pairs_are_the_bins_of_the_query_pixel():
    keys = random_layout(0)
    queries = random_layout(1)
    qi, kj = pixel_pairs(queries.pixels, keys)
    got = sorted(zip(qi.tolist(), kj.tolist()))
    kp = keys.pixels.tolist()
    want = sorted((q, k) for q, qp in enumerate(queries.pixels.tolist()) for k in range(keys.bins) if kp[k] == qp)
    assert got == want and len(want) > 0
    # the same pairs, in the same order, as the reference RaNA's for a disc of radius 0, queries off the grid too
    off = torch.cat([queries.pixels, torch.tensor([[-1, 2], [5, 0], [0, 7], [4, -3]])])
    ref = neighbour_pairs(off, keys.offsets, keys.size, 0.0)[:2]
    assert all(torch.equal(a, b) for a, b in zip(pixel_pairs(off, keys), ref))


def test_segment_softmax_sums_to_one_per_segment():
    seg = torch.tensor([0, 0, 0, 2, 2, 3])
    logits = torch.tensor([1.0, 2.0, 3.0, 1000.0, -1000.0, 5.0])
    w = segment_softmax(logits, seg, 4)
    sums = torch.zeros(4).index_add(0, seg, w)
    torch.testing.assert_close(sums[[0, 2, 3]], torch.ones(3))
    torch.testing.assert_close(w[:3], torch.softmax(logits[:3], 0))
    assert torch.isfinite(w).all()


def test_pair_features_are_the_gathered_difference_and_product_bit_for_bit(monkeypatch):
    """The C++ pass against torch's gathers, |a - b| and a * b (an oracle of exact IEEE operations), signed zeros,
    infinities and NaN included; without the kernels pair_features is that torch expression itself."""
    g = torch.Generator().manual_seed(0)
    a, b = torch.randn(50, 16, generator=g), torch.randn(70, 16, generator=g)
    a[3, :4] = torch.tensor([-0.0, float("inf"), float("nan"), 1e-40])
    b[5, :4] = torch.tensor([0.0, float("inf"), -2.0, -1e-40])
    qi = torch.randint(0, 50, (3000,), generator=g).sort().values
    kj = torch.randint(0, 70, (3000,), generator=g)
    qi[:2], kj[:2] = 3, 5
    x, y = a[qi], b[kj]
    want = torch.cat([(x - y).abs(), x * y], 1)
    if cpu_extension_or_none() is None:
        pytest.skip("the C++ kernels are not built here")
    got = pair_features(a, b, qi, kj)
    assert got.shape == (3000, 32) and got.view(torch.int32).equal(want.view(torch.int32))
    with pytest.raises(RuntimeError, match="out of range"):
        pair_features(a, b, qi, kj + 70)
    import ranad_core.rana.extension as extension
    monkeypatch.setattr(extension, "cpu_extension_or_none", lambda: None)
    assert pair_features(a, b, qi, kj).view(torch.int32).equal(want.view(torch.int32))


def test_pair_sum_is_torchs_index_add_of_the_weighted_values_bit_for_bit(monkeypatch):
    """The C++ weighted sum against torch's zeros.index_add(0, qi, w[:, None] * v[kj]) (what the matching step did
    before it): long runs of pairs, where a fused multiply-add or another order of the additions would show, queries
    without pairs (zeros) and one of -0.0 products; bad pairs are refused."""
    g = torch.Generator().manual_seed(1)
    v = torch.randn(90, 6, generator=g) * torch.logspace(-3, 3, 6)
    qi = torch.randint(0, 40, (4000,), generator=g).sort().values
    qi = qi[qi != 7]                                      # query 7 has no pairs
    kj = torch.randint(0, 90, (qi.numel(),), generator=g)
    w = torch.rand(qi.numel(), generator=g)
    w[qi == 9] = -0.0
    want = v.new_zeros(40, 6).index_add(0, qi, w.unsqueeze(1) * v[kj])
    if cpu_extension_or_none() is None:
        pytest.skip("the C++ kernels are not built here")
    got = pair_sum(w, v, qi, kj, 40)
    assert got.view(torch.int32).equal(want.view(torch.int32)) and (got[7] == 0).all()
    with pytest.raises(RuntimeError, match="out of range or queries out of order"):
        pair_sum(w, v, qi.flip(0), kj, 40)
    with pytest.raises(RuntimeError, match="out of range"):
        pair_sum(w, v, qi, kj, 30)
    import ranad_core.rana.extension as extension
    monkeypatch.setattr(extension, "cpu_extension_or_none", lambda: None)
    assert pair_sum(w, v, qi, kj, 40).view(torch.int32).equal(want.view(torch.int32))


def test_match_kernel_is_linear_in_values_and_local_to_the_pixel():
    torch.manual_seed(0)
    keys = random_layout(2)
    kern = MatchKernel(8)
    for p in kern.parameters():
        torch.nn.init.normal_(p, std=0.5)
    qf, kf = torch.randn(keys.bins, 8), torch.randn(keys.bins, 8)
    x, y = torch.randn(keys.bins, 3), torch.randn(keys.bins, 3)
    out = kern(qf, kf, keys.pixels, keys, 2 * x - 3 * y)
    torch.testing.assert_close(out, 2 * kern(qf, kf, keys.pixels, keys, x) - 3 * kern(qf, kf, keys.pixels, keys, y))
    # a constant layer comes back unchanged (a convex combination), and a key value in another pixel has no say
    torch.testing.assert_close(kern(qf, kf, keys.pixels, keys, torch.ones(keys.bins, 2)), torch.ones(keys.bins, 2))
    b = 0
    changed = x.clone()
    changed[b] += 100
    same_pixel = (keys.pixels == keys.pixels[b]).all(1)
    diff = (kern(qf, kf, keys.pixels, keys, changed) - kern(qf, kf, keys.pixels, keys, x)).abs().amax(1)
    assert (diff[~same_pixel] == 0).all() and (diff[same_pixel] > 0).all()


def test_a_matching_model_is_its_single_frame_model_when_shut_and_tiles_exactly():
    torch.manual_seed(0)
    single = RaNAD(get_config("cpu-small"), feature_dim()).eval()
    model = CrossFrameRaNAD.from_single(single, matching_config(), feature_dim()).eval()
    frames = [read_deep(SHOT / f"noisy_spp16.{i:04d}.exr") for i in range(3)]
    one = denoise_window(single, frames[1:2], 0).image.values
    for g in model.temporal_gate.values():
        torch.nn.init.constant_(g.bias, -1e4)
    np.testing.assert_allclose(denoise_window(model, frames, 1).image.values, one, rtol=1e-6, atol=1e-7)
    for g in model.temporal_gate.values():
        torch.nn.init.constant_(g.bias, 0.0)
    for t in model.temporal.values():         # all the weight on each bin's own row: the identity step
        torch.nn.init.constant_(t.self_bonus, 1e4)
    np.testing.assert_allclose(denoise_window(model, frames, 1).image.values, one, rtol=1e-5, atol=1e-6)
    for t in model.temporal.values():
        torch.nn.init.constant_(t.self_bonus, 0.0)
    whole = denoise_window(model, frames, 1).image.values
    assert np.abs(whole - one).max() > 1e-3
    np.testing.assert_allclose(denoise_window(model, frames, 1, tile=16).image.values, whole, rtol=1e-4, atol=1e-5)
    with pytest.raises(ValueError):                          # matching has radius 0 only
        CrossFrameRaNAD(ModelConfig(**{**matching_config().__dict__, "temporal_radius": 1.0}), feature_dim())
    with pytest.raises(ValueError):                          # and only matching has a guard
        CrossFrameRaNAD(ModelConfig(**{**get_config("cpu-small-xf").__dict__, "temporal_guard": True}),
                        feature_dim())


def test_consistent_checks_every_guide_against_its_tolerance():
    a = torch.rand(1, GUIDE_WIDTH)
    a[0, GUIDE_LAYOUT["black"]] = 0
    assert consistent(a, a.clone()).item()
    prior = GUIDE_LAYOUT["prior"]
    for name, tol in GUARD.items():
        cols = GUIDE_LAYOUT[name]
        for step, agree in ((0.9 * tol, True), (1.1 * tol, False)):
            b = a.clone()
            b[0, cols.start] += step
            assert consistent(a, b).item() is agree, (cols, step)
    # the prior as a ratio: 15% apart agree, 30% do not, whatever the level; far below the floor all agree
    for level in (0.5, 5.0, 50.0):
        for ratio, agree in ((1.15, True), (1.3, False)):
            b, c = a.clone(), a.clone()
            b[0, prior] = math.log1p(level)
            c[0, prior] = math.log1p(level * ratio)
            assert consistent(b, c).item() is agree, (level, ratio)
    b, c = a.clone(), a.clone()
    b[0, prior], c[0, prior] = 0.0, math.log1p(1e-4)
    assert consistent(b, c).item()


def guarded_window():
    """A guarded matching model (gates open) and the bundled shot's window as model inputs."""
    torch.manual_seed(0)
    single = RaNAD(get_config("cpu-small"), feature_dim()).eval()
    model = CrossFrameRaNAD.from_single(single, matching_config(guard=True), feature_dim()).eval()
    for t in model.temporal.values():
        torch.nn.init.constant_(t.self_bonus, 0.0)
    frames = [read_deep(SHOT / f"noisy_spp16.{i:04d}.exr").crop((0, 0, 23, 23)) for i in range(3)]
    window = [prepare(f.sorted()[0]) for f in compensate(frames, 1)[0]]
    return single, model, window


def test_the_guard_keeps_the_pairs_of_the_plain_rule():
    """_match_args compares guides on the neighbours' pairs only: the pairs it keeps are those of the rule written
    plainly over every pair of a pixel (the bin itself, or a neighbour's bin whose guides agree), on a window whose
    neighbours differ from the centre in albedo in some pixels and not in others."""
    _, model, window = guarded_window()
    centre = window[1]
    other = copy.copy(centre)
    other.features = centre.features.clone()
    other.features[::3, GUIDE_COLUMNS["albedo"]] += 0.5
    w = [other, centre, window[2]]
    with torch.no_grad():
        feats = model.embeddings(w, 1)
        keys, gather, frame = temporal_layout([f.layout for f in w])
        got = model._match_args(feats, w, 1, keys, gather, frame)
        rows = torch.empty_like(gather)
        rows[gather] = torch.arange(gather.numel())
        own = rows[other.layout.bins:other.layout.bins + centre.layout.bins]
        qi, kj = pixel_pairs(centre.layout.pixels, keys)
        allg = torch.cat([f[:, -GUIDE_WIDTH:] for f in feats])[gather]
        ok = (kj == own[qi]) | ((frame[kj] != 1) & consistent(allg[own][qi], allg[kj]))
    assert torch.equal(got["own"], own)
    assert torch.equal(got["pairs"][0], qi[ok]) and torch.equal(got["pairs"][1], kj[ok])
    neighbours = frame[kj[ok]] != 1
    assert 0 < int(neighbours.sum()) < int((frame[kj] != 1).sum())   # some neighbours' bins kept, some left out


def test_the_guard_keeps_out_neighbours_that_show_something_else():
    """Neighbours whose bins are the centre's with other noisy values are used; the same neighbours with another
    albedo are not (the result is the single-frame model's, exactly), nor are the centre's other bins."""
    single, model, window = guarded_window()
    centre = window[1]
    with torch.no_grad():
        alone = single.reconstruct(single.embeddings(centre), centre)

        def run(neighbour):
            w = [neighbour, centre, neighbour]
            return model.reconstruct(model.embeddings(w, 1), w, 1)
        noisier = copy.copy(centre)
        noisier.layers = {k: v * 2 for k, v in centre.layers.items()}
        used = run(noisier)
        assert (used["diffuse"] - alone["diffuse"]).abs().max() > 1e-3
        other = copy.copy(noisier)
        other.features = centre.features.clone()
        other.features[:, GUIDE_COLUMNS["albedo"]] += 0.5
        albedo = GUIDE_LAYOUT["albedo"]
        assert torch.equal(guides(other.features, "log1p")[:, albedo],
                           guides(centre.features, "log1p")[:, albedo] + 0.5)
        kept_out = run(other)
        for name in alone:
            torch.testing.assert_close(kept_out[name], alone[name], rtol=1e-5, atol=1e-6)
