"""Training pairs from a `ranad synth` dataset: the centre frame's noisy image and its reference (identical bin
layouts), random crops and the eight flips/transposes applied identically to both; for the temporal loss,
consecutive frames that both have references (datasets made with `--ref-frames all`)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..deep import DeepImage, gather_bins
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


def frame_pair(pair: Pair, offset: int) -> Pair:
    """The pair of the frame `offset` frames after `pair`'s (same scene, kind and spp; the files may not exist)."""
    def moved(path: Path) -> Path:
        stem, frame, ext = path.name.rsplit(".", 2)
        return path.parent / f"{stem}.{int(frame) + offset:0{len(frame)}d}.{ext}"
    return Pair(moved(pair.noisy), moved(pair.reference), pair.scene, pair.kind, pair.spp)


def find_frame_pairs(root: str | Path) -> list:
    """(pair of frame t, pair of frame t + 1) for every two consecutive frames with references: the inputs of
    the temporal loss. Empty for datasets with the centre frame's reference only."""
    out = []
    for manifest in sorted(Path(root).glob("scene_*/manifest.json")):
        m = json.loads(manifest.read_text())
        refs = set(m.get("reference_frames", [m["centre_frame"]]))
        for kind in ("deepz", "deepoid"):
            for spp in m["spp"]:
                for t in sorted(refs):
                    if t + 1 not in refs:
                        continue
                    a = Pair(manifest.parent / kind / f"noisy_spp{spp}.{t:04d}.exr",
                             manifest.parent / kind / f"reference_spp{spp}.{t:04d}.exr", manifest.parent.name, kind, spp)
                    b = frame_pair(a, 1)
                    if all(p.is_file() for p in (a.noisy, a.reference, b.noisy, b.reference)):
                        out.append((a, b))
    return out


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


def random_window(img: DeepImage, rng: np.random.Generator, crop: int) -> tuple:
    """A crop x crop window (smaller for smaller images) at a random place inside the data window."""
    x0d, y0d = img.data_window[:2]
    cw, ch = min(crop, img.width), min(crop, img.height)
    x0 = x0d + int(rng.integers(0, img.width - cw + 1))
    y0 = y0d + int(rng.integers(0, img.height - ch + 1))
    return (x0, y0, x0 + cw - 1, y0 + ch - 1)


def sample(pair: Pair, rng: np.random.Generator, crop: int) -> tuple:
    """A random crop (the same window for noisy and reference) with a random flip/transpose."""
    noisy, ref = load(pair.noisy), load(pair.reference)
    win = random_window(noisy, rng, crop)
    fx, fy, tr = (bool(b) for b in rng.integers(0, 2, 3))
    noisy, ref = sorted_pair(noisy.crop(win), ref.crop(win))
    return transform(noisy, fx, fy, tr), transform(ref, fx, fy, tr)


def sorted_pair(noisy: DeepImage, ref: DeepImage) -> tuple:
    """Both images' bins front to back by the noisy image's depths (the model's convention; deep-OID files are
    ordered by object, not depth), the reference's bins permuted exactly like the noisy ones."""
    srt, perm = noisy.sorted()
    return srt, gather_bins(ref, perm, ref.offsets)


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


def window_frames(pair: Pair, offsets) -> list:
    """Paths of the noisy frames at `offsets` from the pair's centre frame (those that exist)."""
    name = pair.noisy.name               # noisy_spp16.0001.exr
    stem, frame, ext = name.rsplit(".", 2)
    c = int(frame)
    paths = [pair.noisy.parent / f"{stem}.{c + o:0{len(frame)}d}.{ext}" for o in offsets]
    return [p for p in paths if p.is_file()]


@lru_cache(maxsize=32)
def compensated(pair: Pair, lo: int, hi: int) -> tuple:
    """(the noisy frames centre+lo .. centre+hi moved onto the centre frame with bins sorted front to back, the
    centre's index, the centre frame's sort permutation)."""
    from ..motion import compensate

    frames = [load(p) for p in window_frames(pair, range(lo, hi + 1))]
    centre = -lo
    moved, _ = compensate(frames, centre)
    done = [f.sorted() for f in moved]
    return tuple(f for f, _ in done), centre, done[centre][1]


def sample_window(pair: Pair, rng: np.random.Generator, crop: int, window: int) -> tuple:
    """(noisy crops of a window of frames, the reference crop, the centre's index): windows up to `window`
    frames around the centre, shortened at random as at a sequence's ends, the same crop and flip for all."""
    half = (window - 1) // 2
    have = [o for o in range(-half, half + 1) if window_frames(pair, [o])]
    lo_all, hi_all = min(have), max(have)
    r = rng.random()
    lo, hi = (lo_all, hi_all) if r < 0.6 else ((lo_all, 0) if r < 0.75 else ((0, hi_all) if r < 0.9 else (0, 0)))
    frames, centre, perm = compensated(pair, lo, hi)
    ref = load(pair.reference)
    ref = gather_bins(ref, perm, ref.offsets)            # in the centre frame's sorted order
    win = random_window(ref, rng, crop)
    fx, fy, tr = (bool(b) for b in rng.integers(0, 2, 3))
    return ([transform(f.crop(win), fx, fy, tr) for f in frames], transform(ref.crop(win), fx, fy, tr), centre)


def sample_consecutive(pairs: tuple, rng: np.random.Generator, crop: int, window: int) -> list:
    """For two consecutive frames (find_frame_pairs): each frame's window (every frame up to `window` around it that
    exists, as `ranad denoise` uses them), its reference and its centre index, with one crop and one
    flip/transpose for both, so their flattened results can be compared pixel for pixel."""
    half = (window - 1) // 2
    out = []
    for pair in pairs:
        have = [o for o in range(-half, half + 1) if window_frames(pair, [o])]
        frames, centre, perm = compensated(pair, min(have), max(have))
        ref = load(pair.reference)
        out.append((frames, gather_bins(ref, perm, ref.offsets), centre))
    win = random_window(out[0][1], rng, crop)
    fx, fy, tr = (bool(b) for b in rng.integers(0, 2, 3))
    return [([transform(f.crop(win), fx, fy, tr) for f in frames], transform(ref.crop(win), fx, fy, tr), centre)
            for frames, ref, centre in out]


def reduce_window(frames: list, ref: DeepImage, rng: np.random.Generator, p_no_aux: float,
                  p_no_split: float) -> tuple:
    """reduce_inputs for a window: the same reduction for every frame."""
    if rng.random() < p_no_aux:
        frames = [without_aux(f) for f in frames]
    if rng.random() < p_no_split:
        frames, ref = [merged_split(f) for f in frames], merged_split(ref)
    return frames, ref
