"""Light matching (ranad_core/lightmatch.py): the gain's properties, its composite against DeepImage.flatten, and
what it does to a denoised frame (only the denoised colour moves, by its pixel's gain; alpha, depth and emission
stay; off means off)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from deep_factory import random_deep
from test_aov import exact_groups, sums
from ranad_core import lightmatch
from ranad_core.channels import EMISSION, RGB, detect
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep, write_deep
from ranad_core.model import RaNAD, feature_dim, get_config
from ranad_core.model.prior import LUMA

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"


def test_gain_is_one_for_equal_light_and_clamped_otherwise():
    rng = np.random.default_rng(0)
    cur = rng.uniform(0.1, 2.0, size=(20, 30))
    np.testing.assert_allclose(lightmatch.pixel_gain(cur, cur, 3, 1.05), 1.0, rtol=1e-6)
    np.testing.assert_allclose(lightmatch.pixel_gain(1.01 * cur, cur, 3, 1.05), 1.01, rtol=1e-6)
    np.testing.assert_allclose(lightmatch.pixel_gain(1.5 * cur, cur, 3, 1.05), 1.05, rtol=1e-6)
    np.testing.assert_allclose(lightmatch.pixel_gain(0.5 * cur, cur, 3, 1.05), 1 / 1.05, rtol=1e-6)
    dark = np.zeros_like(cur)
    assert (lightmatch.pixel_gain(dark, dark, 3, 1.05) == 1).all()     # no light in the box: no gain
    assert (lightmatch.pixel_gain(cur, dark, 3, 1.05) == 1).all()


def test_gain_is_a_local_ratio_and_exposure_free():
    """Two halves with different ratios: far from the seam each half keeps its own ratio; scaling both images by
    k = 2^-6 .. 2^6 leaves every gain as it is."""
    rng = np.random.default_rng(1)
    cur = rng.uniform(0.5, 1.5, size=(16, 40))
    tgt = cur * np.where(np.arange(40) < 20, 1.01, 0.99)[None, :]
    g = lightmatch.pixel_gain(tgt, cur, 2, 1.05)
    np.testing.assert_allclose(g[:, :17], 1.01, rtol=1e-6)
    np.testing.assert_allclose(g[:, 23:], 0.99, rtol=1e-6)
    for k in (2.0 ** -6, 2.0 ** 6):
        np.testing.assert_allclose(lightmatch.pixel_gain(k * tgt, k * cur, 2, 1.05), g, rtol=1e-6)


def test_box_mean_against_a_direct_window_sum():
    x = np.random.default_rng(2).normal(size=(9, 11))
    r = 2
    m = lightmatch.box_mean(x, r)
    for y in (0, 4, 8):
        for xx in (0, 5, 10):
            win = x[max(0, y - r):y + r + 1, max(0, xx - r):xx + r + 1]
            assert m[y, xx] == pytest.approx(win.mean(), abs=1e-12)


def test_flat_luminance_matches_the_deep_composite():
    img = random_deep(width=9, height=6, channels=("R", "G", "B", "A", "Z"), ids=()).sorted()[0]
    vals = img.values.copy()
    vals[:, 3] = np.clip(vals[:, 3] / 4, 0, 1)            # alpha in [0, 1]
    img = img.with_values(vals)
    want = img.flatten()[..., :3].astype(np.float64) @ LUMA
    lum = img.columns(list(RGB)).astype(np.float64) @ LUMA
    got = lightmatch.flat_luminance(lum, img.channel("A"), img.offsets, img.height, img.width)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)


@pytest.fixture(scope="module")
def prior_model():
    torch.manual_seed(0)
    return RaNAD(get_config("cpu-small-pdl-gza"), feature_dim("prior")).eval()


def test_only_the_denoised_colour_moves_and_by_its_pixels_gain(prior_model):
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    on = denoise_window(prior_model, [img], 0)
    off = denoise_window(prior_model, [img], 0, light_match=False)
    assert off.gain is None and on.gain is not None and on.gain.shape == (img.width * img.height,)
    assert (on.gain >= 1 / lightmatch.CLAMP - 1e-6).all() and (on.gain <= lightmatch.CLAMP + 1e-6).all()
    assert np.abs(on.gain - 1).max() > 1e-3               # an untrained model's light differs from the input's
    m = detect(img)
    ch = on.image.channels
    colour = [ch.index(c) for c in m.beauty]
    emission = np.zeros((img.num_bins, 3))
    if all(c in img.channels for c in EMISSION):
        emission = img.columns(list(EMISSION)).astype(np.float64)
    f = lightmatch.bin_factors(on.gain, img.offsets)      # the file's own order: one pixel's bins share a gain
    np.testing.assert_allclose(on.image.values[:, colour] - emission,
                               (off.image.values[:, colour] - emission) * f, rtol=2e-5, atol=1e-6)
    rest = [i for i, c in enumerate(ch) if c not in m.beauty and not c.startswith(("diffuse", "specular"))]
    np.testing.assert_array_equal(on.image.values[:, rest], off.image.values[:, rest])


def test_the_command_line_switch(prior_model, tmp_path):
    """`ranad denoise --no-light-match` gives the frame as the model made it; the default matches the light."""
    import json

    from click.testing import CliRunner
    from safetensors.torch import save_file

    from ranad_cli.main import cli

    model = tmp_path / "m.safetensors"
    save_file({k: v.contiguous() for k, v in prior_model.state_dict().items()}, str(model),
              metadata={"model_config": json.dumps(prior_model.config.to_dict())})
    src = SHOT / "noisy_spp16.0001.exr"
    outs = {}
    for flag in ("--light-match", "--no-light-match"):
        out = tmp_path / f"{flag}.exr"
        r = CliRunner().invoke(cli, ["denoise", str(src), "-o", str(out), "--model", str(model), flag])
        assert r.exit_code == 0, r.output
        outs[flag] = read_deep(out)
    img = read_deep(src)
    want = denoise_window(prior_model, [img], 0, light_match=False).image
    np.testing.assert_allclose(outs["--no-light-match"].values, want.values, rtol=1e-3, atol=1e-5)   # half channels
    a = outs["--light-match"].columns(list(RGB))
    b = outs["--no-light-match"].columns(list(RGB))
    assert np.abs(a - b).max() > 1e-4 * np.abs(b).max()
    np.testing.assert_array_equal(outs["--light-match"].channel("A"), outs["--no-light-match"].channel("A"))


def test_the_cache_carries_the_gain_and_a_wrong_one_is_refused(prior_model, tmp_path):
    """`ranad denoise --cache` keeps the gains (none with --no-light-match) and `ranad aov` applies them, so the
    light groups sum to the denoised beauty either way; a cache whose gains do not fit the frame is refused with
    exit 2 and no output."""
    import json

    from click.testing import CliRunner
    from safetensors.numpy import save_file as save_np
    from safetensors.torch import save_file

    from ranad_cli.main import cli
    from ranad_core import cache as cache_io

    model = tmp_path / "m.safetensors"
    save_file({k: v.contiguous() for k, v in prior_model.state_dict().items()}, str(model),
              metadata={"model_config": json.dumps(prior_model.config.to_dict())})
    src = tmp_path / "b.exr"
    write_deep(src, exact_groups(read_deep(SHOT / "noisy_spp16.0001.exr")))   # groups that sum exactly to R, G, B
    run = lambda *a: CliRunner().invoke(cli, [str(x) for x in a])  # noqa: E731
    for flag, has_gain in (("--light-match", True), ("--no-light-match", False)):
        out, cdir = tmp_path / f"d{flag}.exr", tmp_path / f"c{flag}"
        r = run("denoise", src, "-o", out, "--model", model, "--cache", cdir, flag)
        assert r.exit_code == 0, r.output
        cpath = next(cdir.glob("*.ranadcache"))
        tensors, meta = cache_io.read_cache(str(cpath))
        assert ("gain" in tensors) == has_gain
        r = run("aov", cpath, "--layers", "lg_*", "-o", tmp_path / f"a{flag}.exr")
        assert r.exit_code == 0, r.output
        (lg, _), (_, rgb) = sums(read_deep(tmp_path / f"a{flag}.exr")), sums(read_deep(out))
        assert np.abs(lg - rgb).max() < 1e-5 * np.abs(rgb).max()
    tensors["gain"] = np.ones(7, np.float32)           # a gain map of another frame's size, checksum made to fit
    meta["tensors_crc32"] = cache_io.tensors_checksum(tensors)
    bad = tmp_path / "bad.ranadcache"
    save_np(tensors, str(bad), metadata=meta)
    r = run("aov", bad, "--layers", "lg_*", "-o", tmp_path / "bad.exr")
    assert r.exit_code == 2 and "light-matching gains do not match" in r.output and str(bad) in r.output
    assert not (tmp_path / "bad.exr").exists()
