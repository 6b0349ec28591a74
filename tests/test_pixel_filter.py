"""`ranad synth --pixel-filter`: samples splatted into neighbouring pixels' bins with a film's weights.

The oracle is a film computed the plain way, pixel by pixel over every sample (no splatting, no bins): the bins of
a pixel composited front to back must give sum(w L) / sum(w) over the samples its filter reaches. No Mitsuba needed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ranad_core.synth.binning import BinLayout, accumulate, bin_values, layout_from_samples
from ranad_core.synth.pixel_filter import copies_per_sample, splat, taps


def _samples(rng, w, h, spp, centred=False):
    n = w * h * spp
    s = {"pixel": np.repeat(np.arange(w * h), spp).astype(np.int64),
         "sx": np.full(n, 0.5, np.float32) if centred else rng.random(n, dtype=np.float32),
         "sy": np.full(n, 0.5, np.float32) if centred else rng.random(n, dtype=np.float32),
         "hit": rng.random(n) < 0.8,
         "z": rng.choice([2.0, 5.0, 9.0], n) * (1 + 0.001 * rng.random(n)),
         "obj": rng.integers(1, 4, n).astype(np.uint32)}
    for k in ("diffuse", "specular", "emission"):
        s[k] = (rng.random((n, 3)) * s["hit"][:, None]).astype(np.float32)
    s["albedo"] = rng.random((n, 3)).astype(np.float32)
    s["groups"] = np.concatenate([s["diffuse"], s["specular"]], 1)
    return s


def _film(s, w, h, width):
    """sum(w L) / sum(w) per pixel, by brute force over pixels and samples (PBRT's separable Gaussian)."""
    r = width / 2
    x = s["pixel"] % w + s["sx"].astype(np.float64)
    y = s["pixel"] // w + s["sy"].astype(np.float64)
    radiance = (s["diffuse"] + s["specular"] + s["emission"]).astype(np.float64)

    def g(d):
        return np.where(np.abs(d) < r, np.maximum(np.exp(-2 * (d / r) ** 2) - math.exp(-2), 0), 0)

    out = np.zeros((h * w, 3))
    for p in range(w * h):
        wt = g(x - (p % w + 0.5)) * g(y - (p // w + 0.5))
        out[p] = (wt[:, None] * radiance).sum(0) / wt.sum()
    return out


def _composite(s, w, h, kind):
    lay, sb = layout_from_samples(s, w, h, kind)
    v = bin_values(accumulate(s, sb, len(lay.pixel), npixels=w * h), lay, spp=0)
    colour = v["diffuse"] + v["specular"] + v["emission"]
    flat = np.zeros((w * h, 3))
    through = np.ones(w * h)
    for b in range(len(lay.pixel)):  # bins are per pixel, front to back
        p = lay.pixel[b]
        flat[p] += through[p] * colour[b]
        through[p] *= 1 - v["A"][b]
    return flat, lay, v


@pytest.mark.parametrize("kind", ["z", "oid"])
@pytest.mark.parametrize("width", [2.0, 3.0, 4.5])
def test_filtered_bins_composite_to_the_film(kind, width):
    rng = np.random.default_rng(5)
    w, h = 7, 5
    s = _samples(rng, w, h, 6)
    flat, lay, v = _composite(splat(s, w, h, "gaussian", width), w, h, kind)
    np.testing.assert_allclose(flat, _film(s, w, h, width), rtol=2e-6)  # the sums are float32
    # coverage is each bin's share of its pixel's weight: a pixel's bins sum to its hit share, at most 1
    per_px = np.bincount(lay.pixel, weights=v["coverage"], minlength=w * h)
    assert per_px.max() <= 1 + 1e-9 and per_px.min() > 0
    # weighted means stay means: albedo within the range of the samples'
    assert v["albedo"].min() >= 0 and v["albedo"].max() <= 1


def test_filtered_images_have_their_neighbours_bins():
    rng = np.random.default_rng(2)
    s = _samples(rng, 9, 9, 8)
    box, _ = layout_from_samples(s, 9, 9, "oid")
    gauss, _ = layout_from_samples(splat(s, 9, 9, "gaussian", 2.0), 9, 9, "oid")
    assert len(gauss.pixel) > len(box.pixel)


def test_centred_samples_reach_only_their_pixel_at_width_2():
    """At width 2 the Gaussian is 0 one pixel from its centre: samples at pixel centres bin as the box does."""
    rng = np.random.default_rng(3)
    s = _samples(rng, 6, 4, 4, centred=True)
    f = splat(s, 6, 4, "gaussian", 2.0)
    assert len(f["pixel"]) == len(s["pixel"]) and np.array_equal(f["pixel"], s["pixel"])
    a, _, va = _composite(f, 6, 4, "z")
    b_lay, sb = layout_from_samples(s, 6, 4, "z")
    vb = bin_values(accumulate(s, sb, len(b_lay.pixel)), b_lay, 4)
    np.testing.assert_allclose(va["coverage"], vb["coverage"], rtol=1e-6)
    np.testing.assert_allclose(va["diffuse"], vb["diffuse"], rtol=1e-5, atol=1e-7)


def test_box_is_the_unfiltered_path_and_taps_cover_the_support():
    s = _samples(np.random.default_rng(0), 3, 3, 2)
    assert splat(s, 3, 3, "box", 1.0) is s
    assert [taps(x) for x in (1.0, 2.0, 3.0, 3.2, 4.0, 6.0)] == [1, 3, 3, 5, 5, 7]
    with pytest.raises(ValueError):
        splat(s, 3, 3, "sinc", 2.0)


@pytest.mark.parametrize("width", [1.5, 2.0, 3.0, 4.0])
def test_copies_per_sample_bounds_the_splat(width):
    """What render_reference sizes its chunks by: no sample is ever copied into more pixels."""
    s = _samples(np.random.default_rng(1), 16, 16, 8)
    out = splat(s, 16, 16, "gaussian", width)
    per_sample = np.bincount(out["_src"], minlength=len(s["pixel"]))
    assert per_sample.max() <= copies_per_sample("gaussian", width)
    assert per_sample.min() >= 1 and copies_per_sample("box", width) == 1


def test_a_sliver_behind_a_nearly_opaque_front_keeps_a_finite_colour():
    """Filtered counts are summed in float32 and the pixel's weight in float64, so the bins of a pixel can cover a
    hair more than its weight. A sliver bin (coverage 3.6e-7) behind a front that then leaves it less room than its
    own share gets alpha 1 and its samples' mean radiance, not that radiance times share / room, which overflowed
    the files' half floats (inf in about 1% of stratified, filtered training files)."""
    count = np.array([1.0 - 2e-7, 3.6e-7])          # sums to 1 + 1.6e-7 of a pixel weight of 1
    radiance = np.array([[1.0, 1.0, 1.0], [5e4, 5e4, 5e4]])   # the sliver: one bright sample's copy
    lay = BinLayout(width=1, height=1, pixel=np.zeros(2, np.int64), obj=np.array([1, 2], np.uint32),
                    zmin=np.array([1.0, 2.0]), zmax=np.array([1.0, 2.0]), kind="z")
    acc = {"count": count, "pixel_weight": np.array([1.0]), "z": count * [1.0, 2.0], "unbinned": 0.0,
           "total": 1.0, "groups": radiance[:, :1] * count[:, None]}
    for name in ("diffuse", "specular", "emission"):
        acc[name] = radiance * count[:, None] if name == "diffuse" else np.zeros((2, 3))
    vals = bin_values(acc, lay, 16)
    assert vals["A"][1] == 1.0
    np.testing.assert_allclose(vals["diffuse"][1], 5e4, rtol=1e-6)    # the mean, within half's range
    np.testing.assert_allclose(vals["diffuse"][0], 1.0, rtol=1e-6)     # the front bin as before
    assert np.all(np.abs(vals["diffuse"]) < 65504)
