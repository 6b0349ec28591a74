"""Pixel reconstruction filters: each path sample splatted into every pixel its filter reaches, with a weight.

Production renderers rarely box-filter: Arnold's and RenderMan's default pixel filter is a Gaussian 2 px wide,
Mitsuba's a Gaussian of radius 2. Where a renderer's deep output is filtered like its beauty, a sample lands, with a
weight, in the bins of its neighbours too, so noise is correlated between neighbouring pixels and edge pixels get
bins of their neighbours' surfaces. ranad's tracer box-filters (a sample belongs to one pixel);
`ranad synth --pixel-filter gaussian` renders the same scenes and samples the other way, for held-out sets and
training data that look like those renderers' files.

The Gaussian is PBRT's separable, truncated form: w(x) = max(0, exp(-2 (x/r)^2) - exp(-2)) per axis, r = width / 2,
x the distance from the sample to the pixel's centre. Binning (binning.accumulate/bin_values) then divides each
bin's weighted sums by its pixel's total weight, as a film does, instead of by the sample count.
"""

from __future__ import annotations

import math

import numpy as np

FILTERS = ("box", "gaussian")
ALPHA = 2.0


def taps(width: float) -> int:
    """Pixels a sample can reach along one axis (box: 1)."""
    r = width / 2
    return 2 * math.ceil(r - 0.5) + 1 if r > 0.5 else 1


def copies_per_sample(filt: str, width: float) -> int:
    """At most how many pixels one sample is splatted into (what a caller sizes its sample chunks by)."""
    return 1 if filt == "box" else taps(width) ** 2


def _weights_1d(dist: np.ndarray, r: float) -> np.ndarray:
    w = np.exp(-ALPHA * (dist / r) ** 2) - math.exp(-ALPHA)
    return np.where(np.abs(dist) < r, np.maximum(w, 0.0), 0.0).astype(np.float32)


def splat(s: dict, width_px: int, height_px: int, filt: str, filter_width: float) -> dict:
    """Samples replicated into every pixel their filter reaches, each copy with its weight in `weight`.

    `s` needs `pixel` (row-major index), `sx`, `sy` (position in the pixel, [0, 1)). The copies carry what binning
    reads per sample (`pixel`, `weight`, `hit`, `z`, `obj`, and with media `volume`, `zin`, `zout`) and `_src`,
    each copy's sample in `_parent` (= s), whose channel matrix binning gathers once (copying every channel of
    every copy took most of a scene's time). `sample(copies, name)` gives any other channel per copy. Box
    filtering returns `s` itself (weights implicit 1, the existing path).
    """
    if filt == "box":
        return s
    if filt != "gaussian":
        raise ValueError(f"unknown pixel filter {filt!r}")
    r = filter_width / 2
    reach = (taps(filter_width) - 1) // 2
    px, py = s["pixel"] % width_px, s["pixel"] // width_px
    src, pix, wts = [], [], []
    for oy in range(-reach, reach + 1):
        ty = py + oy
        wy = _weights_1d(s["sy"] - 0.5 - oy, r)
        for ox in range(-reach, reach + 1):
            tx = px + ox
            w = wy * _weights_1d(s["sx"] - 0.5 - ox, r)
            keep = np.flatnonzero((w > 0) & (tx >= 0) & (tx < width_px) & (ty >= 0) & (ty < height_px))
            src.append(keep)
            pix.append(ty[keep] * width_px + tx[keep])
            wts.append(w[keep])
    order = np.concatenate(src)
    out = {k: s[k][order] for k in ("hit", "z", "obj", "volume", "zin", "zout") if k in s}
    out.update(pixel=np.concatenate(pix).astype(np.int64), weight=np.concatenate(wts), _src=order, _parent=s)
    return out


def sample(copies: dict, name: str) -> np.ndarray:
    """Channel `name` of every sample, or of every copy of a splat's samples."""
    return copies[name] if name in copies else copies["_parent"][name][copies["_src"]]
