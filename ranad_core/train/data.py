"""Training pairs from a `ranad synth` dataset: the centre frame's noisy image and its reference (identical bin
layouts), random crops and the eight flips/transposes applied identically to both; for the temporal loss,
consecutive frames that both have references (datasets made with `--ref-frames all`)."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..channels import ALBEDO, DIFFUSE, NORMAL, PRIOR, PRIOR_NOAUX, SPECULAR
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


def pair_at(scene: Path, kind: str, spp: int, frame: int) -> Pair:
    """The (noisy, reference) files of one frame of a scene (they may not exist)."""
    return Pair(scene / kind / f"noisy_spp{spp}.{frame:04d}.exr", scene / kind / f"reference_spp{spp}.{frame:04d}.exr",
                scene.name, kind, spp)


def complete(*pairs: Pair) -> bool:
    return all(p.noisy.is_file() and p.reference.is_file() for p in pairs)


def dataset_roots(roots) -> list:
    """One dataset folder or several (a path, or a list/tuple of them), as Paths in the order given."""
    return [Path(r) for r in ([roots] if isinstance(roots, (str, Path)) else roots)]


def manifests(roots) -> list:
    """The scene manifests of one or several datasets (scenes of each dataset in order, datasets in turn)."""
    return [m for root in dataset_roots(roots) for m in sorted(root.glob("scene_*/manifest.json"))]


def read_manifest(path: Path) -> dict:
    """A scene's manifest.json; RanadError naming it when it is no JSON object with the keys the pairs need."""
    try:
        m = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise RanadError(f"not a scene manifest ({type(e).__name__})", path) from None
    if not isinstance(m, dict) or not isinstance(m.get("spp"), list) or not isinstance(m.get("centre_frame"), int):
        raise RanadError("not a scene manifest (needs a list 'spp' and an integer 'centre_frame')", path)
    return m


def find_pairs(roots, missing: list | None = None) -> list:
    """Every (noisy, reference) pair of the centre frames of the complete scenes of one or several datasets.
    `missing`: where given, the pairs whose noisy file is there without its reference are appended to it (a scene
    still rendering, a reference lost), so a caller can say what it leaves out."""
    for root in dataset_roots(roots):
        if not root.is_dir():
            raise RanadError("dataset folder not found", root)
    pairs = []
    for root in dataset_roots(roots):
        found, lacking = [], []
        for manifest in manifests(root):
            m = read_manifest(manifest)
            for kind in ("deepz", "deepoid"):
                for spp in m["spp"]:
                    pair = pair_at(manifest.parent, kind, spp, m["centre_frame"])
                    if complete(pair):
                        found.append(pair)
                    elif pair.noisy.is_file():
                        lacking.append(pair)
        if not found:
            raise RanadError("no complete scenes (scene_*/manifest.json with noisy and reference files)"
                             + (f"; {len(lacking)} noisy file(s) have no reference, e.g. {lacking[0].reference}"
                                if lacking else ""), root)
        if missing is not None:
            missing += lacking
        pairs += found
    return pairs


def find_frame_pairs(roots) -> list:
    """(pair of frame t, pair of frame t + 1) for every two consecutive frames with references: the inputs of
    the temporal loss. Empty for datasets with the centre frame's reference only."""
    out = []
    for manifest in manifests(roots):
        m = read_manifest(manifest)
        refs = set(m.get("reference_frames", [m["centre_frame"]]))
        for kind in ("deepz", "deepoid"):
            for spp in m["spp"]:
                for t in sorted(refs):
                    two = (pair_at(manifest.parent, kind, spp, t), pair_at(manifest.parent, kind, spp, t + 1))
                    if t + 1 in refs and complete(*two):
                        out.append(two)
    return out


@lru_cache(maxsize=64)
def load(path: Path) -> DeepImage:
    return read_deep(path)


@lru_cache(maxsize=1024)
def load_noisy(path: Path, features: str = "log1p") -> DeepImage:
    """A noisy frame as training reads it: with the flat prior's channels (guided and unguided) for the "prior"
    feature set, computed once per file on the whole frame, as `ranad denoise` does."""
    img = load(path)
    if features == "prior":
        from ..model.prior import with_prior

        img = with_prior(img, both=True)
    return img


@dataclass(frozen=True)
class FrameContext:
    """Whole-frame statistics a crop's features use (so that crops see what `ranad denoise` gives a tile)."""
    z_stats: tuple
    scale: float


@lru_cache(maxsize=1024)
def frame_context(path: Path, features: str = "log1p") -> FrameContext:
    from ..model.inputs import depth_stats

    img = load_noisy(path, features)  # depth_stats and frame_scale do not depend on the bin order
    scale = 1.0
    if features == "prior":
        from ..model.prior import frame_scale

        scale = frame_scale(img)
    return FrameContext(depth_stats(img), scale)


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


def sample(pair: Pair, rng: np.random.Generator, crop: int, features: str = "log1p") -> tuple:
    """A random crop (the same window for noisy and reference) with a random flip/transpose."""
    noisy, ref = load_noisy(pair.noisy, features), load(pair.reference)
    win = random_window(noisy, rng, crop)
    fx, fy, tr = (bool(b) for b in rng.integers(0, 2, 3))
    noisy, ref = sorted_pair(noisy.crop(win), ref.crop(win))
    return transform(noisy, fx, fy, tr), transform(ref, fx, fy, tr)


def sorted_pair(noisy: DeepImage, ref: DeepImage) -> tuple:
    """Both images' bins front to back by the noisy image's depths (the model's convention; deep-OID files are
    ordered by object, not depth), the reference's bins permuted exactly like the noisy ones."""
    srt, perm = noisy.sorted()
    return srt, gather_bins(ref, perm, ref.offsets)


def without_aux(img: DeepImage) -> DeepImage:
    """The image without albedo and normal channels (what many renderers' deep outputs lack); a flat prior it
    carries becomes the one computed without them."""
    if all(c in img.channels for c in PRIOR_NOAUX + PRIOR):
        vals = img.values.copy()
        for a, b in zip(PRIOR, PRIOR_NOAUX):
            vals[:, img.channels.index(a)] = img.channel(b)
        img = img.with_values(vals)
    return img.select([c for c in img.channels if c not in (*ALBEDO, *NORMAL, *PRIOR_NOAUX)])


def merged_split(img: DeepImage) -> DeepImage:
    """diffuse := diffuse + specular, specular channels removed: a file without the split, as the model sees it
    (the whole radiance goes through the diffuse reconstruction)."""
    if not all(c in img.channels for c in (*DIFFUSE, *SPECULAR)):
        return img
    vals = img.values.copy()
    for d, s in zip(DIFFUSE, SPECULAR):
        vals[:, img.channels.index(d)] += img.channel(s)
    keep = [c for c in img.channels if c not in SPECULAR]
    return img.with_values(vals).select(keep)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A 3x3 rotation drawn uniformly (the Q of a Gaussian matrix's QR, its column signs fixed, det +1)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def rotated_normals(img: DeepImage, rot: np.ndarray) -> DeepImage:
    """The image with every normal turned by `rot` (the other channels as they are; an image without normals as
    it is). Renderers write normals in world space, for a camera facing any way, or in camera space, and a file
    does not say which: a model shown its normals in one space only learns that space's directions (ranad's scenes
    are all seen from one side, y up), so training turns them at random (`TrainConfig.p_rotate_normals`)."""
    if not all(c in img.channels for c in NORMAL):
        return img
    cols = [img.channels.index(c) for c in NORMAL]
    vals = img.values.copy()
    vals[:, cols] = (vals[:, cols].astype(np.float64) @ np.asarray(rot, np.float64).T).astype(vals.dtype)
    return img.with_values(vals)


def normal_rotation(rng: np.random.Generator, p_rotate: float) -> np.ndarray | None:
    """A random rotation for a crop's normals with probability p_rotate, else None; draws nothing at 0, so recipes
    from before the option keep their random stream."""
    if p_rotate <= 0 or rng.random() >= p_rotate:
        return None
    return random_rotation(rng)


def reduce_inputs(noisy: DeepImage, ref: DeepImage, rng: np.random.Generator, p_no_aux: float,
                  p_no_split: float, p_rotate: float = 0.0) -> tuple:
    """Randomly present a pair in the reduced modes `ranad denoise` supports (no albedo/normal; no
    diffuse/specular split), so one model serves full and reduced inputs; with p_rotate, its normals in another
    space (rotated_normals)."""
    if rng.random() < p_no_aux:
        noisy = without_aux(noisy)
    if rng.random() < p_no_split:
        noisy, ref = merged_split(noisy), merged_split(ref)
    rot = normal_rotation(rng, p_rotate)
    if rot is not None:
        noisy = rotated_normals(noisy, rot)
    return noisy, ref


def window_frames(pair: Pair, offsets) -> list:
    """Paths of the noisy frames at `offsets` from the pair's centre frame (those that exist)."""
    name = pair.noisy.name               # noisy_spp16.0001.exr
    stem, frame, ext = name.rsplit(".", 2)
    c = int(frame)
    paths = [pair.noisy.parent / f"{stem}.{c + o:0{len(frame)}d}.{ext}" for o in offsets]
    return [p for p in paths if p.is_file()]


@lru_cache(maxsize=32)
def compensated(pair: Pair, lo: int, hi: int, features: str = "log1p") -> tuple:
    """(the noisy frames centre+lo .. centre+hi moved onto the centre frame with bins sorted front to back, the
    centre's index, the centre frame's sort permutation, each frame's whole-frame FrameContext). For the "prior"
    feature set every frame carries its flat prior made on the frame itself before compensation (load_noisy),
    with its own exposure scale, as `ranad denoise` does (denoise.FramePrior)."""
    from ..model.inputs import depth_stats
    from ..model.prior import frame_scale
    from ..motion import compensate

    frames = [load_noisy(p, features) for p in window_frames(pair, range(lo, hi + 1))]
    scales = [frame_scale(f) if features == "prior" else 1.0 for f in frames]
    centre = -lo
    moved, _ = compensate(frames, centre)
    done = [f.sorted() for f in moved]
    out = tuple(f for f, _ in done)
    ctxs = tuple(FrameContext(depth_stats(f), s) for f, s in zip(out, scales))
    return out, centre, done[centre][1], ctxs


def available_window(pair: Pair, window: int) -> tuple:
    """(lo, hi): the offsets of the first and last frames up to `window` around the pair's frame that exist."""
    half = (window - 1) // 2
    have = [o for o in range(-half, half + 1) if window_frames(pair, [o])]
    return min(have), max(have)


def window_with_reference(pair: Pair, lo: int, hi: int, features: str = "log1p") -> tuple:
    """(the compensated frames centre+lo .. centre+hi, the reference in the centre frame's sorted order, the
    centre's index, the frames' whole-frame contexts)."""
    frames, centre, perm, ctxs = compensated(pair, lo, hi, features)
    ref = load(pair.reference)
    return frames, gather_bins(ref, perm, ref.offsets), centre, ctxs


def cropped(windows: list, rng: np.random.Generator, crop: int, p_misalign: float = 0.0) -> list:
    """The windows (frames, reference, centre, contexts) cut to one random crop with one random flip/transpose.

    p_misalign: share of windows whose neighbour frames are cut `misaligned` (as if their motion vectors were
    wrong); no random numbers are drawn for it at 0, so runs without it keep their crops."""
    win = random_window(windows[0][1], rng, crop)
    fx, fy, tr = (bool(b) for b in rng.integers(0, 2, 3))
    shifts = None
    if p_misalign > 0 and rng.random() < p_misalign:
        shifts = [misalignment(rng, crop) for _ in range(max(len(w[0]) for w in windows))]

    def cut(f, k, centre):
        if shifts is None or k == centre:
            return f.crop(win)
        dx, dy = shifts[k]
        moved = f.crop((win[0] + dx, win[1] + dy, win[2] + dx, win[3] + dy))
        return replace(moved, data_window=tuple(win))

    return [([transform(cut(f, k, centre), fx, fy, tr) for k, f in enumerate(frames)],
             transform(ref.crop(win), fx, fy, tr), centre, ctxs) for frames, ref, centre, ctxs in windows]


def misalignment(rng: np.random.Generator, crop: int) -> tuple[int, int]:
    """A pixel offset (dx, dy) of 2 .. crop/4 pixels in a random direction: what a neighbour frame is moved by in a
    misaligned training window. Teaches the cross-frame model to trust a neighbour only where it agrees with the
    centre frame (refraction, wrong or missing motion vectors, disocclusions all look like this), which shots
    without such cases never show it."""
    reach = max(2, crop // 4)
    while True:
        dx, dy = (int(v) for v in rng.integers(-reach, reach + 1, 2))
        if max(abs(dx), abs(dy)) >= 2:
            return dx, dy


def sample_window(pair: Pair, rng: np.random.Generator, crop: int, window: int, features: str = "log1p",
                  p_misalign: float = 0.0) -> tuple:
    """(noisy crops of a window of frames, the reference crop, the centre's index, the frames' whole-frame
    contexts): windows up to `window` frames around the centre, shortened at random as at a sequence's ends, the
    same crop and flip for all (neighbours misaligned in a share `p_misalign` of the windows, see `cropped`)."""
    lo_all, hi_all = available_window(pair, window)
    r = rng.random()
    lo, hi = (lo_all, hi_all) if r < 0.6 else ((lo_all, 0) if r < 0.75 else ((0, hi_all) if r < 0.9 else (0, 0)))
    return cropped([window_with_reference(pair, lo, hi, features)], rng, crop, p_misalign)[0]


def sample_consecutive(pairs: tuple, rng: np.random.Generator, crop: int, window: int,
                       features: str = "log1p") -> list:
    """For two consecutive frames (find_frame_pairs): each frame's window (every frame up to `window` around it that
    exists, as `ranad denoise` uses them), its reference, its centre index and the frames' contexts, with one crop
    and one flip/transpose for both, so their flattened results can be compared pixel for pixel."""
    return cropped([window_with_reference(p, *available_window(p, window), features) for p in pairs], rng, crop)


def reduce_window(frames: list, ref: DeepImage, rng: np.random.Generator, p_no_aux: float,
                  p_no_split: float, rot: np.ndarray | None = None) -> tuple:
    """reduce_inputs for a window: the same reduction for every frame, and the same normal rotation `rot` (None:
    none; normal_rotation draws one)."""
    if rng.random() < p_no_aux:
        frames = [without_aux(f) for f in frames]
    if rng.random() < p_no_split:
        frames, ref = [merged_split(f) for f in frames], merged_split(ref)
    if rot is not None:
        frames = [rotated_normals(f, rot) for f in frames]
    return frames, ref
