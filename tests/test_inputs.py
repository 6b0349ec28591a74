"""The model's input features (model/inputs.py `prepare`) against an oracle: the column-by-column version they were
computed with before `prepare` gathered its channels in one pass and joined its blocks in one concatenation. The two
must agree bit for bit on every kind of image a model meets (guides or none, the diffuse/specular split or none, a
coverage channel or the computed one, "prior" features, an empty image), since the shipped weights were trained on
those features and the AOV cache must rebuild the same kernels."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from ranad_core.channels import (ALBEDO, ALPHA, COVERAGE, DEPTH, DIFFUSE, FLAT_NOISY, NORMAL, PRIOR, SPECULAR,
                                 canonical, detect)
from ranad_core.deep import DeepImage
from ranad_core.exr import read_deep
from ranad_core.model.inputs import (AUX, BIN_FREQS, DEMOD_FLOOR, FEATURE_SETS, PERIODS, RADIANCE_LAYERS, Layout,
                                     contribution, depth_stats, feature_dim, prepare)
from ranad_core.model.prior import with_prior

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"


def prepare_by_columns(img, z_stats=None, features="log1p", scale=1.0):
    """The oracle: `prepare` as sessions 5-36 wrote it, one take per channel group and two concatenations."""
    def cols(names):
        return img.columns(names).astype(np.float32, copy=False)

    def has(names):
        return all(c in img.channels for c in names)

    inv = 1.0 / scale if features == "prior" else 1.0
    n = img.values.shape[0]
    layers = {name: cols(names) if has(names) else np.zeros((n, 3), np.float32)
              for name, names in RADIANCE_LAYERS.items()}
    layers["alpha"] = cols([ALPHA])
    layers["depth"] = cols([DEPTH])
    cov = cols([COVERAGE]) if COVERAGE in img.channels else contribution(layers["alpha"], img.offsets)
    mean, std = depth_stats(img) if z_stats is None else z_stats
    zn = ((np.log(np.maximum(layers["depth"], 1e-4)) - mean) / (std + 1e-6)).astype(np.float32)
    aux = [cols(names) if has(names) else np.zeros((n, 3), np.float32) for names in AUX.values()]
    rad = lambda x: np.log1p(np.maximum(np.asarray(x, np.float32) * np.float32(inv), 0))  # noqa: E731
    extra = []
    if features == "prior":
        extra = [rad(cols(names)) if has(names) else np.zeros((n, 3), np.float32) for names in (PRIOR, FLAT_NOISY)]
    base = np.concatenate([rad(layers["diffuse"]), rad(layers["specular"]), layers["alpha"], cov, zn, *aux,
                           *extra], axis=1)
    layout = Layout.of(torch.from_numpy(img.offsets), img.height, img.width)
    y, x = layout.pixels[:, 0].float(), layout.pixels[:, 1].float()
    pos = [f(2 * math.pi * t / p) for p in PERIODS for t in (x, y) for f in (torch.sin, torch.cos)]
    offs = layout.offsets
    counts = offs[1:] - offs[:-1]
    b = (torch.arange(layout.bins) - torch.repeat_interleave(offs[:-1], counts, output_size=layout.bins)).float()
    nb = torch.repeat_interleave(counts, counts, output_size=layout.bins).float()
    bins = [f(b * math.pi / 2 ** k) for k in range(BIN_FREQS) for f in (torch.sin, torch.cos)]
    feats = torch.cat([torch.from_numpy(base), torch.stack(pos, 1), torch.stack(bins, 1),
                       (b / nb.clamp(min=1)).unsqueeze(1)], dim=1)
    mod = None
    if has(ALBEDO) and has(SPECULAR):
        mod = (np.clip(np.nan_to_num(cols(ALBEDO)), 0, 1) + np.float32(DEMOD_FLOOR)).astype(np.float32)
    return feats, layers, mod


def assert_same(img, **kw):
    got = prepare(img, **kw)
    feats, layers, mod = prepare_by_columns(img, **kw)
    assert got.features.shape == (img.num_bins, feature_dim(kw.get("features", "log1p")))
    assert torch.equal(got.features, feats)
    assert set(got.layers) == set(layers)
    for k, v in layers.items():
        assert got.layers[k].is_contiguous() and torch.equal(got.layers[k], torch.from_numpy(v)), k
    assert torch.equal(got.depth, torch.from_numpy(layers["depth"]))
    assert (got.modulation is None) == (mod is None)
    if mod is not None:
        assert torch.equal(got.modulation, torch.from_numpy(mod))


def canonical_sorted(img):
    return canonical(img, detect(img))[0].sorted()[0]


@pytest.fixture(scope="module")
def frame():
    return canonical_sorted(read_deep(SHOT / "noisy_spp16.0001.exr"))


@pytest.mark.parametrize("kernels", [True, False], ids=["C++ concat", "torch.cat"])
@pytest.mark.parametrize("features", FEATURE_SETS)
def test_features_equal_the_column_by_column_oracle(frame, features, kernels, monkeypatch):
    """With the C++ kernels (their one-pass concatenation) and without them (torch.cat)."""
    from ranad_core.rana import extension

    if kernels and extension.cpu_extension_or_none() is None:
        pytest.skip("the C++ kernels are not built here (no compiler); the torch.cat case still runs")
    if not kernels:
        monkeypatch.setattr(extension, "cpu_extension_or_none", lambda: None)
    img = with_prior(frame) if features == "prior" else frame
    assert_same(img, features=features, scale=0.37)
    assert_same(img, z_stats=(0.5, 2.0), features=features, scale=3.0)


def test_the_one_pass_concatenation_is_torch_cat():
    from ranad_core.rana.extension import cpu_extension_or_none

    ext = cpu_extension_or_none()
    if ext is None:
        pytest.skip("the C++ kernels are not built here (no compiler)")
    g = torch.Generator().manual_seed(0)
    for n in (0, 1, 63, 64, 65, 1000):
        parts = [torch.randn(n, w, generator=g) for w in (3, 1, 16, 7, 1)]
        assert torch.equal(ext.rows_concat(parts), torch.cat(parts, 1))
    with pytest.raises(RuntimeError, match="rows"):
        ext.rows_concat([torch.zeros(3, 2), torch.zeros(4, 2)])
    with pytest.raises(RuntimeError, match="contiguous float32"):
        ext.rows_concat([torch.zeros(3, 2).t()])


def test_without_guides_split_or_coverage(frame):
    """Images that lack optional groups: zeros (guides, specular) or the computed coverage, as before."""
    keep = [c for c in frame.channels if c not in (*ALBEDO, *NORMAL, *SPECULAR, COVERAGE)]
    bare = frame.with_values(frame.columns(keep), keep)
    assert COVERAGE not in bare.channels and DIFFUSE[0] in bare.channels
    assert_same(bare)
    assert_same(with_prior(bare), features="prior")
    assert prepare(bare).modulation is None


def test_an_empty_image(frame):
    empty = DeepImage(values=np.zeros((0, len(frame.channels)), np.float32),
                      offsets=np.zeros(frame.height * frame.width + 1, np.int64), channels=frame.channels,
                      data_window=frame.data_window)
    assert_same(empty)


def test_alpha_and_depth_stay_required(frame):
    keep = [c for c in frame.channels if c != ALPHA]
    with pytest.raises(KeyError, match="no channel 'A'"):
        prepare(frame.with_values(frame.columns(keep), keep))


def test_concat_columns_keeps_gradients_and_matches_torch_cat():
    """concat_columns (the features' and the cross-frame one-hot's joins) takes the C++ pass only for float32 CPU
    tensors without gradients; a tensor that needs them goes through torch.cat and its gradient flows."""
    from ranad_core.model.inputs import concat_columns

    g = torch.Generator().manual_seed(1)
    parts = [torch.randn(9, 4, generator=g), torch.randn(9, generator=g), torch.randn(9, 2, generator=g)]
    assert torch.equal(concat_columns(parts), torch.cat([parts[0], parts[1][:, None], parts[2]], 1))
    leaf = torch.randn(9, 4, generator=g, requires_grad=True)
    out = concat_columns([leaf, parts[1]])
    out[:, :4].sum().backward()
    assert out.requires_grad and torch.equal(leaf.grad, torch.ones(9, 4))
