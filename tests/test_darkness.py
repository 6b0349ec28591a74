"""Exactly black neighbourhoods stay black (ranad_core.darkness): which pixels qualify (against a brute-force
window check), that the default model's leak into them is stopped and nothing else changes, and that light groups
through the cache keep summing to the beauty with the radius the primary pass used."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core import darkness
from ranad_core.channels import ChannelMap, detect
from ranad_core.deep import DeepImage
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep, write_deep
from ranad_core.model.store import load_model

from test_aov import exact_groups, sums

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"
BOX = (8, 28)   # rows and columns 8..27 of the 48 x 48 frame are made black
RADIANCE = ("R", "G", "B", "diffuse.", "specular.", "emission.", "lg_")


def radiance_columns(img: DeepImage) -> list:
    return [i for i, c in enumerate(img.channels) if c in RADIANCE[:3] or c.startswith(RADIANCE[3:])]


def without_light(img: DeepImage, bins: np.ndarray) -> DeepImage:
    """img with every radiance channel of `bins` (bool [N]) set to exactly 0; alpha, depth and guides kept."""
    vals = img.values.copy()
    vals[np.ix_(bins, radiance_columns(img))] = 0
    return img.with_values(vals)


def blackened(img: DeepImage) -> DeepImage:
    """img with the pixels in BOX x BOX without light: an object over an empty background, as a renderer writes
    it."""
    return without_light(img, inner(img, 0))


def held_out(img: DeepImage, obj: int) -> DeepImage:
    """img with object `obj`'s bins without light, alpha kept: a deep holdout matte."""
    return without_light(img, img.ids["id"] == obj)


def inner(img: DeepImage, margin: int = 1) -> np.ndarray:
    y, x = np.divmod(img.pixel_index(), img.width)
    lo, hi = BOX[0] + margin, BOX[1] - margin
    return (y >= lo) & (y < hi) & (x >= lo) & (x < hi)


def brute_force(lit: np.ndarray, radius: int) -> np.ndarray:
    """[H, W] dark pixels, pixel by pixel: those in a clipped (2 radius + 1)^2 window with no lit pixel, neither
    they nor the window's centre within SPECK_REACH of a speck (a lit pixel with at least SPECK_BLACK unlit pixels
    among its in-image 8 neighbours)."""
    h, w = lit.shape

    def window(a, y, x, r):
        return a[max(0, y - r):y + r + 1, max(0, x - r):x + r + 1]

    speck = np.array([[lit[y, x] and int((~window(lit, y, x, 1)).sum()) >= darkness.SPECK_BLACK
                       for x in range(w)] for y in range(h)])
    calm = np.array([[not window(speck, y, x, darkness.SPECK_REACH).any() for x in range(w)] for y in range(h)])
    centre = np.array([[calm[y, x] and not window(lit, y, x, radius).any() for x in range(w)] for y in range(h)])
    return np.array([[calm[y, x] and window(centre, y, x, radius).any() for x in range(w)] for y in range(h)])


@pytest.mark.parametrize("radius", [1, 2, 3])
def test_dark_pixels_match_a_brute_force_window_check(radius):
    rng = np.random.default_rng(radius)
    h, w = 23, 29
    counts = rng.integers(0, 3, h * w)          # pixels without bins count as black
    offsets = np.concatenate([[0], np.cumsum(counts)])
    n = int(offsets[-1])
    y = np.divmod(np.repeat(np.arange(h * w), counts), w)[0]
    lit_bin = rng.random(n) < np.where(y < h // 2, 0.9, 0.04)   # a lit half, a sparsely lit half (specks)
    vals = np.zeros((n, 4), np.float32)
    vals[:, 3] = 0.5                            # alpha: never read
    vals[lit_bin, rng.integers(0, 3, n)[lit_bin]] = rng.choice([-1e-7, 1e-30, 2.0], int(lit_bin.sum()))
    img = DeepImage(values=vals, offsets=offsets, channels=["R", "G", "B", "A"], ids={},
                    data_window=(0, 0, w - 1, h - 1), display_window=(0, 0, w - 1, h - 1))
    lit = np.zeros(h * w, bool)
    lit[img.pixel_index()[lit_bin]] = True
    want = brute_force(lit.reshape(h, w), radius).reshape(-1)[img.pixel_index()]
    got = darkness.dark_bins(img, ChannelMap(), radius)
    assert want.any() and not want.all()
    assert (brute_force(lit.reshape(h, w), 0) != ~lit.reshape(h, w)).any()   # specks veto some black windows
    np.testing.assert_array_equal(got, want)
    assert darkness.dark_bins(img, ChannelMap(), 0) is None


def test_a_black_pixel_among_lit_ones_is_not_dark():
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    m = detect(img)
    cols = [img.channels.index(c) for c in darkness.colour_channels(m)]
    lit = np.zeros(img.num_pixels, bool)
    lit[img.pixel_index()[(img.values[:, cols] != 0).any(1)]] = True
    lit = lit.reshape(img.height, img.width)
    y, x = next((y, x) for y in range(1, img.height - 1) for x in range(1, img.width - 1)
                if lit[y - 1:y + 2, x - 1:x + 2].all())
    p = y * img.width + x
    vals = img.values.copy()
    vals[img.offsets[p]:img.offsets[p + 1], cols] = 0
    before, after = darkness.dark_bins(img, m, 1), darkness.dark_bins(img.with_values(vals), m, 1)
    np.testing.assert_array_equal(after, before)


def test_the_default_model_keeps_black_neighbourhoods_black_and_changes_nothing_else():
    model = load_model(None).model
    img = blackened(read_deep(SHOT / "noisy_spp16.0001.exr"))
    m = detect(img)
    on = denoise_window(model, [img], 0).image
    off = denoise_window(model, [img], 0, dark_radius=0).image
    dark = darkness.dark_bins(img, m)
    colour = [img.channels.index(c) for c in darkness.colour_channels(m)]
    assert (inner(img) & dark).sum() > 0.9 * inner(img).sum() > 500   # specks veto a few near the example's own
    np.testing.assert_array_equal(on.values[np.ix_(dark, colour)], 0)
    leak = np.abs(off.values[np.ix_(dark, colour)]).max()
    assert leak > 1e-4 * np.abs(off.values[:, colour]).max()     # what the rule stops: light from lit pixels
    np.testing.assert_array_equal(on.values[~dark], off.values[~dark])
    others = [i for i in range(len(img.channels)) if i not in colour]
    np.testing.assert_array_equal(on.values[:, others], off.values[:, others])   # alpha, depth: denoised as ever
    edge = inner(img, 0) & ~inner(img)   # the region's own edge, next to lit pixels: kept with its windows
    assert (edge & dark).sum() > 0.6 * edge.sum()


@pytest.mark.parametrize("radius", [1, 0])
def test_light_groups_through_the_cache_keep_the_primary_pass_radius(tmp_path, radius):
    """`ranad denoise --cache` then `ranad aov` on a frame with a black region and exact light groups: the groups
    sum to the denoised beauty with the rule on and off, so `ranad aov` applied the radius the cache recorded; with
    a holdout object too."""
    img = held_out(blackened(exact_groups(read_deep(SHOT / "noisy_spp16.0001.exr"))), 5)   # and a holdout
    write_deep(tmp_path / "b.exr", img)
    run = lambda *a: CliRunner().invoke(cli, [str(x) for x in a])  # noqa: E731
    r = run("denoise", tmp_path / "b.exr", "-o", tmp_path / "d.exr", "--cache", tmp_path / "cache",
            "--dark-radius", radius)
    assert r.exit_code == 0, r.output
    r = run("aov", tmp_path / "cache", "--layers", "lg_*", "-o", tmp_path / "a.exr")
    assert r.exit_code == 0, r.output
    lg, _ = sums(read_deep(tmp_path / "a.exr"))
    _, rgb = sums(read_deep(tmp_path / "d.exr"))
    assert np.abs(lg - rgb).max() < 1e-5 * np.abs(rgb).max()
    dark = darkness.dark_bins(img, detect(img))
    assert (np.abs(rgb[dark]).max() == 0) == (radius > 0)
    assert dark[img.ids["id"] == 5].all()


def test_a_cache_with_a_damaged_radius_is_refused(tmp_path):
    from safetensors.numpy import load_file, save_file
    from safetensors import safe_open

    write_deep(tmp_path / "b.exr", blackened(read_deep(SHOT / "noisy_spp16.0001.exr")))
    run = lambda *a: CliRunner().invoke(cli, [str(x) for x in a])  # noqa: E731
    assert run("denoise", tmp_path / "b.exr", "-o", tmp_path / "d.exr", "--cache", tmp_path / "c").exit_code == 0
    path = next((tmp_path / "c").iterdir())
    with safe_open(str(path), framework="np") as f:
        meta = dict(f.metadata())
    assert meta["dark_radius"] == str(darkness.DARK_RADIUS)
    save_file(load_file(str(path)), str(path), metadata={**meta, "dark_radius": "-3"})
    r = run("aov", tmp_path / "c", "--layers", "lg_*", "-o", tmp_path / "a.exr")
    assert r.exit_code == 2 and "dark_radius" in r.output and path.name in r.output, r.output
    assert not (tmp_path / "a.exr").exists()


def test_info_counts_the_pixels_kept_black(tmp_path):
    import json

    img = blackened(read_deep(SHOT / "noisy_spp16.0001.exr"))
    write_deep(tmp_path / "b.exr", img)
    want = int(np.unique(img.pixel_index()[darkness.dark_bins(img, detect(img))]).size)
    r = CliRunner().invoke(cli, ["info", str(tmp_path / "b.exr"), "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)[0]["parts"][0]["dark_pixels"] == want > 300
    r = CliRunner().invoke(cli, ["info", str(tmp_path / "b.exr")])
    assert f"kept black: {want} pixels" in r.output


def test_a_holdout_object_stays_black_and_a_dim_one_does_not():
    model = load_model(None).model
    src = read_deep(SHOT / "noisy_spp16.0001.exr")
    img = held_out(src, 5)
    m = detect(img)
    rgb = [img.channels.index(c) for c in "RGB"]
    sel = img.ids["id"] == 5
    assert sel.sum() >= darkness.HOLDOUT_MIN_BINS
    on = denoise_window(model, [img], 0).image
    off = denoise_window(model, [img], 0, dark_radius=0).image
    np.testing.assert_array_equal(on.values[np.ix_(sel, rgb)], 0)
    # without the rule the kernels light the holdout: on average above the median lit bin's colour
    assert np.abs(off.values[np.ix_(sel, rgb)]).mean() > np.median(np.abs(off.values[np.ix_(~sel, rgb)]))
    dark = darkness.dark_bins(img, m)
    np.testing.assert_array_equal(on.values[~dark], off.values[~dark])
    # one lit bin makes it an object like any other, and so do too few bins
    p = int(np.flatnonzero(sel)[0])
    vals = img.values.copy()
    vals[p, rgb] = src.values[p, rgb] + 1e-3
    again = darkness.dark_bins(img.with_values(vals), m)
    assert not again[np.flatnonzero(sel)[1:]].all()
    cols = [img.channels.index(c) for c in darkness.colour_channels(m)]
    small = held_out(src, 4)
    four = small.ids["id"] == 4
    assert four.sum() == darkness.HOLDOUT_MIN_BINS
    assert darkness.holdout_bins(small, darkness._lit_bins(small.values, cols))[four].all()
    fewer = small.keep(~four | (np.cumsum(four) > 1))     # one of its bins gone: too few to call it a holdout
    assert darkness.holdout_bins(fewer, darkness._lit_bins(fewer.values, cols)) is None


def test_light_groups_in_one_step_through_a_shot(tmp_path):
    """`ranad denoise SHOT --aovs` (the sequence default, every frame with its neighbours): bins kept black are
    black in the beauty and in every group, and the groups sum to the denoised beauty."""
    for f in range(3):
        frame = held_out(blackened(exact_groups(read_deep(SHOT / f"noisy_spp16.{f:04d}.exr"))), 5)
        write_deep(tmp_path / f"b.{f:04d}.exr", frame)
    r = CliRunner().invoke(cli, ["denoise", str(tmp_path / "b.####.exr"), "-o", str(tmp_path / "d" / "b.####.exr"),
                                 "--aovs", "lg_*"])
    assert r.exit_code == 0, r.output
    for f in range(3):
        src, out = read_deep(tmp_path / f"b.{f:04d}.exr"), read_deep(tmp_path / "d" / f"b.{f:04d}.exr")
        lg, rgb = sums(out)
        assert np.abs(lg - rgb).max() < 1e-5 * np.abs(rgb).max()
        dark = darkness.dark_bins(src, detect(src))
        assert dark[src.ids["id"] == 5].all() and np.abs(lg[dark]).max() == 0 == np.abs(rgb[dark]).max()


@pytest.mark.parametrize("stops", [-6, 6])
def test_the_kept_bins_do_not_move_with_exposure(stops):
    """The rule reads which colours are exactly 0, which an exposure change keeps: the same bins are kept (so the
    exposure invariance of tests/test_prior.py holds with it)."""
    img = held_out(blackened(read_deep(SHOT / "noisy_spp16.0001.exr")), 5)
    k = np.float32(2.0 ** stops)
    vals = img.values.copy()
    vals[:, radiance_columns(img)] *= k
    np.testing.assert_array_equal(darkness.dark_bins(img.with_values(vals), detect(img)),
                                  darkness.dark_bins(img, detect(img)))
