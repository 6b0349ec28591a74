"""The "prior" feature set (issue 24): exposure invariance, the whole-frame flat prior, tiles agree with the whole
frame, starting from a model of the other feature set, and the reduced-mode prior of training crops."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from ranad_core.channels import FLAT_NOISY, PRIOR, PRIOR_NOAUX
from ranad_core.denoise import denoise_frame
from ranad_core.exr import read_deep
from ranad_core.model import RaNAD, ReconConfig, feature_dim
from ranad_core.model.config import ModelConfig
from ranad_core.model.inputs import old_columns, prepare
from ranad_core.model.prior import exposure_scale, frame_scale, with_prior

pytest.importorskip("pyoidn", reason="the flat prior runs OIDN (pyoidn, a core dependency)")

FRAME = Path(__file__).resolve().parents[1] / "examples" / "synth_shot" / "noisy_spp16.0001.exr"
RADIANCE = ("R", "G", "B", "diffuse.R", "diffuse.G", "diffuse.B", "specular.R", "specular.G", "specular.B",
            "emission.R", "emission.G", "emission.B")


def tiny(features: str, seed: int = 0) -> RaNAD:
    torch.manual_seed(seed)
    rc = ReconConfig(scales=2, heads=2, head_dim=8, radius=1.5, radius_growth=0.5)
    cfg = ModelConfig("tiny-p", dim=16, unets=1, levels=1, blocks_per_level=1, heads=4, head_dim=8, radius=1.5,
                      radius_growth=0.5, recon={"diffuse": rc, "specular": rc, "alpha": rc, "depth": rc},
                      features=features)
    model = RaNAD(cfg, feature_dim(features)).eval()
    with torch.no_grad():  # untrained weights are near-uniform kernels; make the features matter
        model.embed[0].weight.mul_(8)
    return model


@pytest.fixture(scope="module")
def frame():
    return read_deep(FRAME).crop((40, 40, 87, 87))


def scaled(img, k: float):
    vals = img.values.copy()
    for c in RADIANCE:
        if c in img.channels:
            vals[:, img.channels.index(c)] *= k
    return img.with_values(vals)


def radiance(img) -> np.ndarray:
    return np.stack([img.channel(c) for c in RADIANCE if c in img.channels], 1).astype(np.float64)


def test_exposure_scale_is_a_robust_median():
    flat = np.zeros((10, 3))
    flat[:9] = 1.0
    flat[9] = 1e6  # a firefly does not move it
    assert exposure_scale(flat) == pytest.approx(1.0)
    assert exposure_scale(flat * 2.0 ** -5) == pytest.approx(2.0 ** -5)
    assert exposure_scale(np.zeros((4, 3))) == 1.0


@pytest.mark.parametrize("stops", range(-6, 7))
def test_denoised_output_scales_with_the_input(frame, stops):
    """A frame scaled by k = 2^stops denoises to k times the unscaled result (issue 24: mean relative difference
    at most 0.5%), and the log1p feature set does not (so the test can fail)."""
    k = 2.0 ** stops
    model = tiny("prior")
    base = radiance(denoise_frame(model, frame).image)
    out = radiance(denoise_frame(model, scaled(frame, k)).image) / k
    mask = np.abs(base) > 1e-4
    rel = np.abs(out - base)[mask] / np.abs(base)[mask]
    assert rel.mean() <= 0.005, rel.mean()
    if stops >= 3:  # (at low exposure log1p is nearly linear, so only bright frames show it)
        old = tiny("log1p")
        b0 = radiance(denoise_frame(old, frame).image)
        o0 = radiance(denoise_frame(old, scaled(frame, k)).image) / k
        m0 = np.abs(b0) > 1e-4
        assert (np.abs(o0 - b0)[m0] / np.abs(b0)[m0]).mean() > 0.005


def test_prior_is_oidn_of_the_flattened_frame(frame):
    """Every bin of a pixel carries its pixel's flattened noisy beauty (an independent flatten) and OIDN's denoised
    version of it; the prior is smoother than the noisy image and keeps its brightness."""
    from ranad_core.deep import flatten

    img = with_prior(frame, both=True)
    for names in (PRIOR, FLAT_NOISY, PRIOR_NOAUX):
        assert all(c in img.channels for c in names)
    flat = flatten(frame)  # [H, W, C] in the image's channel order
    ref = np.stack([flat[..., frame.channels.index(c)] for c in "RGB"], -1).reshape(-1, 3)
    pix = img.pixel_index()
    got = np.stack([img.channel(c) for c in FLAT_NOISY], 1)
    np.testing.assert_allclose(got, ref[pix], rtol=2e-3, atol=2e-3)
    prior = np.zeros_like(ref)
    prior[pix] = np.stack([img.channel(c) for c in PRIOR], 1)
    h, w = frame.height, frame.width
    tv = lambda x: np.abs(np.diff(x.reshape(h, w, 3), axis=1)).mean()  # noqa: E731
    assert tv(prior) < 0.7 * tv(ref)
    assert prior.mean() == pytest.approx(ref.mean(), rel=0.15)
    assert frame_scale(img) == pytest.approx(exposure_scale(ref), rel=1e-6)


def test_prior_releases_oidn_and_equals_the_cached_call(frame):
    """The flat prior's OIDN runs on a device and filter released after the call (prior.released_oidn): nothing of
    it is left in pyoidn's process-wide cache, whose filter scratch (1.2 GB at 1080p) would sit beside the tiles;
    the result is bitwise what pyoidn.denoise (the cached call) gives."""
    import sys

    import pyoidn

    from ranad_core.model.prior import released_oidn

    cache = sys.modules["pyoidn.denoise"]._denoiser
    cache.close()
    with_prior(frame)
    assert cache._resources == {}
    rng = np.random.default_rng(3)
    colour, albedo = rng.random((40, 56, 3), np.float32) * 4, rng.random((40, 56, 3), np.float32)
    normal = rng.random((40, 56, 3), np.float32) * 2 - 1
    own = released_oidn(pyoidn, colour, {"albedo": albedo, "normal": normal})
    np.testing.assert_array_equal(own, pyoidn.denoise(colour, albedo, normal, hdr=True))
    assert float(np.abs(own - colour).mean()) > 0.05   # it denoised


def test_tiles_equal_the_whole_frame_with_the_prior(frame):
    model = tiny("prior")
    whole = denoise_frame(model, frame).image
    tiled = denoise_frame(model, frame, tile=16)
    assert tiled.tiles == 9
    np.testing.assert_allclose(tiled.image.values, whole.values, rtol=1e-4, atol=1e-5)


def test_start_from_the_other_feature_set(frame, tmp_path):
    """A "prior" model started from a "log1p" model has the old embedding weights on the shared columns and zero
    weights on the prior's, so the prior's features cannot change its first layer until it trains."""
    from ranad_core.train.trainer import init_single
    import json
    from safetensors.torch import save_file

    old = tiny("log1p", seed=1)
    path = tmp_path / "old.safetensors"
    save_file({k: v.contiguous() for k, v in old.state_dict().items()}, str(path),
              metadata={"model_config": json.dumps(old.config.to_dict())})
    new = tiny("prior", seed=2)
    init_single(new, str(path))
    cols = old_columns("log1p", "prior")
    assert len(cols) == feature_dim("log1p") and max(cols) == feature_dim("prior") - 1
    w = new.embed[0].weight.detach()
    torch.testing.assert_close(w[:, cols], old.embed[0].weight.detach())
    extra = sorted(set(range(feature_dim("prior"))) - set(cols))
    assert len(extra) == 6 and w[:, extra].abs().max() == 0
    inputs = prepare(with_prior(frame.sorted()[0]), features="prior")
    f2 = inputs.features.clone()
    f2[:, extra] = torch.randn(f2.shape[0], 6)
    torch.testing.assert_close(new.embed(inputs.features), new.embed(f2))


def test_reduced_mode_crops_read_the_unguided_prior(frame):
    from ranad_core.train.data import without_aux

    img = with_prior(frame, both=True)
    red = without_aux(img)
    assert "albedo.R" not in red.channels and PRIOR_NOAUX[0] not in red.channels
    np.testing.assert_array_equal(red.channel(PRIOR[1]), img.channel(PRIOR_NOAUX[1]))
    assert not np.array_equal(img.channel(PRIOR[1]), img.channel(PRIOR_NOAUX[1]))


def test_prior_of_a_presorted_image_skips_the_sort_and_equals_it():
    """denoise passes its already sorted canonical image with presorted=True: the same channels and values as
    sorting it again (the identity permutation), without the sort."""
    from ranad_core.exr import read_deep
    from ranad_core.model.prior import with_prior

    img = read_deep(Path(__file__).resolve().parents[1] / "examples" / "synth_shot" / "noisy_spp16.0001.exr")
    srt, _ = img.sorted()
    a, b = with_prior(srt), with_prior(srt, presorted=True)
    assert a.channels == b.channels
    np.testing.assert_array_equal(a.values, b.values)
    shuffled = with_prior(img)                       # any bin order: the prior follows each bin
    _, perm = img.sorted()
    np.testing.assert_array_equal(shuffled.values[perm], a.values)


def test_a_carried_prior_is_the_prior_made_on_the_frame():
    """A frame's FramePrior attached to it and read back by the model's frame preparation gives the sorted
    channels and exposure scale that making the prior there gives, bit for bit (the centre of a cross-frame window
    is denoised as the single-frame path does)."""
    from ranad_core.channels import detect
    from ranad_core.denoise import FramePrior, _model_frame

    img = read_deep(FRAME)
    mapping = detect(img)
    made = _model_frame(img, mapping, "prior")
    prior = FramePrior.of(img, mapping)
    carried = _model_frame(prior.attached(img), mapping, "prior", prior)
    assert carried.srt.channels == made.srt.channels and carried.scale == made.scale
    np.testing.assert_array_equal(carried.srt.values, made.srt.values)
    np.testing.assert_array_equal(carried.perm, made.perm)


def test_cross_frame_windows_make_each_frame_prior_once(tmp_path, monkeypatch):
    """A shot through a cross-frame model on the prior: OIDN's prior is made once per frame, not once per window
    and frame; each moved neighbour bin carries the prior of its own frame's pixel (training reads windows the
    same way, train.data.compensated)."""
    from ranad_core import denoise
    from ranad_core.exr.sequence import Frame
    from ranad_core.model.crossframe import CrossFrameRaNAD
    from ranad_core.model.store import LoadedModel
    from ranad_core.shot import ShotOptions, denoise_shot
    from ranad_core.train.data import Pair, compensated

    single = tiny("prior")
    config = ModelConfig(**{**single.config.__dict__, "name": "tiny-pxk", "window": 3, "temporal_keys": "inputs"})
    cross = CrossFrameRaNAD.from_single(single, config, feature_dim("prior")).eval()
    made = []
    of = denoise.FramePrior.of
    monkeypatch.setattr(denoise.FramePrior, "of", classmethod(lambda cls, img, m: made.append(1) or of(img, m)))
    shot = Path(FRAME).parent
    frames = [Frame(str(shot / f"noisy_spp16.{i:04d}.exr"), i) for i in range(3)]
    jobs = [(f, str(tmp_path / f"out.{f.frame:04d}.exr")) for f in frames]
    denoise_shot(jobs, LoadedModel(cross, "tiny", "tiny"), ShotOptions(window=3))
    assert len(made) == 3
    pair = Pair(shot / "noisy_spp16.0001.exr", shot / "reference_spp16.0001.exr", "shot", "deepz", 16)
    moved, centre, _, _ = compensated(pair, -1, 1, "prior")
    assert centre == 1
    for k in (0, 2):
        own = with_prior(read_deep(shot / f"noisy_spp16.{k:04d}.exr"))
        have = {tuple(r) for r in np.stack([own.channel(c) for c in PRIOR], 1).tolist()}
        assert all(tuple(r) in have for r in np.stack([moved[k].channel(c) for c in PRIOR], 1).tolist())
