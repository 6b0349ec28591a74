"""Procedural albedo textures for `ranad synth`: patterns other than checkerboards.

A checkerboard is all straight edges at one frequency; real albedo maps hold clouds, veins, grain and stripes at
many. Each texture here is tileable (so uv wrapping shows no seams), made from value noise summed over octaves
(fBm) and mapped through two colours, as a Mitsuba bitmap. A scene stores only the parameters; the texels are
made when the Mitsuba scene is built.
"""

from __future__ import annotations

import numpy as np

NOISE_STYLES = ("clouds", "marble", "stripes", "cells")
TEXELS = 256


def value_noise(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Tileable smooth noise in [0, 1]: a random `cells` x `cells` lattice, interpolated with a smoothstep."""
    lattice = rng.random((cells, cells))
    t = np.arange(size) / size * cells
    i0 = np.floor(t).astype(int)
    f = t - i0
    f = f * f * (3 - 2 * f)
    i1 = (i0 + 1) % cells
    rows = lattice[i0] * (1 - f)[:, None] + lattice[i1] * f[:, None]
    return rows[:, i0] * (1 - f)[None, :] + rows[:, i1] * f[None, :]


def fbm(rng: np.random.Generator, size: int, cells: int, octaves: int) -> np.ndarray:
    """Octaves of value noise, each twice the frequency and half the amplitude of the one before, in [0, 1]."""
    out = np.zeros((size, size))
    total = 0.0
    for k in range(octaves):
        c = min(cells * 2 ** k, size)
        out += value_noise(rng, size, c) * 0.5 ** k
        total += 0.5 ** k
    return out / total


def noise_texels(params: dict, size: int = TEXELS) -> np.ndarray:
    """The texels [size, size, 3] (linear albedo) of a texture's parameters: {"style", "seed", "cells", "colour0",
    "colour1"}; cells: a power of two up to `size`. Styles: clouds (fBm), marble (a sine bent by fBm: veins),
    stripes (a sine thresholded: hard edges at a random angle), cells (a coarse lattice of flat tiles with fBm
    grain)."""
    rng = np.random.default_rng(int(params["seed"]))
    cells = int(params["cells"])
    if cells < 1 or size % cells:
        raise ValueError(f"texture cells must divide {size}, not {cells}")
    style = params["style"]
    if style == "clouds":
        t = fbm(rng, size, cells, 4)
    elif style == "marble":
        y = np.arange(size)[:, None] / size
        t = 0.5 + 0.5 * np.sin(2 * np.pi * (cells * y + 2.0 * fbm(rng, size, max(2, cells // 2), 4)))
    elif style == "stripes":
        k = int(rng.integers(1, 4))   # integer wave vector components keep the stripes tileable
        yy, xx = np.mgrid[0:size, 0:size] / size
        wave = np.sin(2 * np.pi * (cells * xx + k * yy) + 0.8 * fbm(rng, size, 4, 3))
        t = (wave > rng.uniform(-0.5, 0.5)).astype(float)
    elif style == "cells":   # (cells divides size: the lattice's tiles are whole texels)
        tiles = rng.random((cells, cells)).repeat(size // cells, 0).repeat(size // cells, 1)
        t = 0.8 * tiles + 0.2 * fbm(rng, size, 16, 3)
    else:
        raise ValueError(f"unknown texture style {style!r} (one of {', '.join(NOISE_STYLES)})")
    t = np.clip(t, 0.0, 1.0)[..., None]
    c0, c1 = np.asarray(params["colour0"], float), np.asarray(params["colour1"], float)
    return (c0 * (1 - t) + c1 * t).astype(np.float32)
