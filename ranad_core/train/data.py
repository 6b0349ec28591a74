"""Training pairs from a `ranad synth` dataset: the centre frame's noisy image and its reference (identical bin
layouts), random crops and the eight flips/transposes applied identically to both."""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..deep import DeepImage
from ..errors import RanadError
from ..exr import read_deep


@dataclass(frozen=True)
class Pair:
    noisy: Path
    reference: Path
    scene: str
    kind: str
    spp: int


def find_pairs(root: str | Path) -> list:
    """Every (noisy, reference) pair of the centre frames of a dataset's complete scenes."""
    root = Path(root)
    if not root.is_dir():
        raise RanadError("dataset folder not found", root)
    pairs = []
    for manifest in sorted(root.glob("scene_*/manifest.json")):
        m = json.loads(manifest.read_text())
        c = m["centre_frame"]
        for kind in ("deepz", "deepoid"):
            for spp in m["spp"]:
                noisy = manifest.parent / kind / f"noisy_spp{spp}.{c:04d}.exr"
                ref = manifest.parent / kind / f"reference_spp{spp}.{c:04d}.exr"
                if noisy.is_file() and ref.is_file():
                    pairs.append(Pair(noisy, ref, manifest.parent.name, kind, spp))
    if not pairs:
        raise RanadError("no complete scenes (scene_*/manifest.json with noisy and reference files)", root)
    return pairs


@lru_cache(maxsize=64)
def load(path: Path) -> DeepImage:
    return read_deep(path)


def transform(img: DeepImage, flip_x: bool, flip_y: bool, transpose: bool) -> DeepImage:
    """The image flipped and/or transposed (pixels moved with their bins; screen-space motion vectors follow)."""
    h, w = img.height, img.width
    ys, xs = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    src_y, src_x = (ys, xs)
    if flip_y:
        src_y = h - 1 - src_y
    if flip_x:
        src_x = w - 1 - src_x
    if transpose:  # new (y, x) takes the flipped image's (x, y): the output is w x h
        src_y, src_x = src_y.T, src_x.T
    src = (src_y * w + src_x).ravel()
    counts = np.diff(img.offsets)
    new_counts = counts[src]
    offsets = np.concatenate([[0], np.cumsum(new_counts)]).astype(np.int64)
    starts = np.repeat(img.offsets[:-1][src], new_counts)
    rows = starts + (np.arange(offsets[-1]) - np.repeat(offsets[:-1], new_counts))
    values = img.values[rows].copy()
    for name, axis_flip in (("X", flip_x), ("Y", flip_y)):
        for mv in ("motion_prev", "motion_next"):
            if axis_flip and f"{mv}.{name}" in img.channels:
                values[:, img.channels.index(f"{mv}.{name}")] *= -1
    if transpose:
        for mv in ("motion_prev", "motion_next"):
            if f"{mv}.X" in img.channels:
                ix, iy = img.channels.index(f"{mv}.X"), img.channels.index(f"{mv}.Y")
                values[:, [ix, iy]] = values[:, [iy, ix]]
    nh, nw = (w, h) if transpose else (h, w)
    return DeepImage(values=values, offsets=offsets, channels=list(img.channels),
                     ids={k: v[rows] for k, v in img.ids.items()}, data_window=(0, 0, nw - 1, nh - 1),
                     display_window=(0, 0, nw - 1, nh - 1), channel_types=dict(img.channel_types))


def sample(pair: Pair, rng: np.random.Generator, crop: int) -> tuple:
    """A random crop (the same window for noisy and reference) with a random flip/transpose."""
    noisy, ref = load(pair.noisy), load(pair.reference)
    x0d, y0d = noisy.data_window[:2]
    cw, ch = min(crop, noisy.width), min(crop, noisy.height)
    x0 = x0d + int(rng.integers(0, noisy.width - cw + 1))
    y0 = y0d + int(rng.integers(0, noisy.height - ch + 1))
    win = (x0, y0, x0 + cw - 1, y0 + ch - 1)
    fx, fy, tr = (bool(b) for b in rng.integers(0, 2, 3))
    return transform(noisy.crop(win), fx, fy, tr), transform(ref.crop(win), fx, fy, tr)


AUX_LAYERS = ("albedo", "N")
SPLIT_LAYERS = ("diffuse", "specular")


def without_aux(img: DeepImage) -> DeepImage:
    """The image without albedo and normal channels (what many renderers' deep outputs lack)."""
    return img.select([c for c in img.channels if c.split(".")[0] not in AUX_LAYERS])


def merged_split(img: DeepImage) -> DeepImage:
    """diffuse := diffuse + specular, specular channels removed: a file without the split, as the model sees it
    (the whole radiance goes through the diffuse reconstruction)."""
    if not all(f"{layer}.{c}" in img.channels for layer in SPLIT_LAYERS for c in "RGB"):
        return img
    vals = img.values.copy()
    for c in "RGB":
        vals[:, img.channels.index(f"diffuse.{c}")] += img.channel(f"specular.{c}")
    keep = [c for c in img.channels if c.split(".")[0] != "specular"]
    return img.with_values(vals).select(keep)


def reduce_inputs(noisy: DeepImage, ref: DeepImage, rng: np.random.Generator, p_no_aux: float,
                  p_no_split: float) -> tuple:
    """Randomly present a pair in the reduced modes `ranad denoise` supports (no albedo/normal; no
    diffuse/specular split), so one model serves full and reduced inputs."""
    if rng.random() < p_no_aux:
        noisy = without_aux(noisy)
    if rng.random() < p_no_split:
        noisy, ref = merged_split(noisy), merged_split(ref)
    return noisy, ref
