"""Denoising a deep frame with a RaNAD model, in tiles with a halo, and putting the result back into the file's
channels.

- The model reads the canonical layers of channels.py, with every pixel's bins front to back (its bin-index
  encoding assumes it); results go back in the file's bin order, so the output has exactly the input's pixels,
  bins, order, ids and header.
- Denoised: the diffuse and specular layers, alpha and depth (ZBack keeps each bin's thickness); the beauty is
  rebuilt as diffuse + specular + emission (+ the residual the split leaves out, through the diffuse kernels), so
  it stays consistent with its layers. Every denoised value is a softmax-weighted average of noisy values of the
  same layer: alpha stays in [0, 1], depth within its neighbourhood's range.
- Tiles: the frame is cut into aligned square tiles; each is processed with a halo as wide as the model's
  receptive field (`receptive_field`), and only its core is kept. Tile origins are multiples of 16 (the period
  of the position encoding and the parity of the bin-dropout pattern) and the depth standardisation uses the
  whole frame's statistics, so tiled output equals whole-frame output up to float rounding.
- Non-finite input samples are counted and replaced before the model sees them (colour and alpha: 0; depth:
  the frame's largest finite depth), so they never reach the output.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import torch

from . import binmerge, darkness, heap, lightmatch
from .binmerge import Groups
from .channels import (ALPHA, DEPTH, DEPTH_BACK, DEPTHS, FLAT_NOISY, PRIOR, ChannelMap, canonical, detect,
                       layer_values, split_layer)
from .deep import DeepImage, copy_values, replace_nonfinite, unsort
from .model.inputs import concat_columns, depth_stats, prepare
from .profile import record_tile, stage

ALIGN = 16                 # tile origins: multiples of the position encoding's longest period
BYTES_PER_BIN = 2048       # model working memory per bin at inference (measured ~1.6 KB for cpu-small)


@dataclass
class FrameResult:
    image: DeepImage
    bins: int                            # the centre file's bins (before any merging)
    nonfinite: int                       # bins that had a non-finite value in a channel the model reads
    tiles: int
    embeddings: list | None = None       # per window frame: [N_f, dim] float16, sorted bin order (AOV cache)
    perms: list | None = None            # per window frame: sort permutation of its (compensated) bins
    z_stats: list = field(default_factory=list)   # per window frame: (mean, std) of log depth
    offsets: list = field(default_factory=list)   # per window frame: offsets of its compensated bins
    mapping: ChannelMap | None = None
    dropped: int = 0                     # neighbour bins that motion carried out of the frame
    merges: list | None = None           # per window frame: binmerge group of each sorted bin, or None (no merge)
    split: np.ndarray | None = None      # the centre's binmerge.split_factors (None: nothing merged)
    merge_gap: float = 0.0               # the binmerge gap the frames were merged with
    dark_radius: int = 0                 # darkness: black windows of this radius and holdouts kept black (0: off)
    gain: np.ndarray | None = None       # lightmatch: float32 [H*W] gain of the denoised colour (None: not applied)

    @property
    def perm(self):
        return None if self.perms is None else self.perms[self.centre]

    centre: int = 0


def is_cross_frame(model) -> bool:
    return getattr(model.config, "window", 1) > 1


def receptive_field(model) -> int:
    """An upper bound, in pixels, of how far a bin's output can depend on other pixels: the sum of the radii of
    the backbone's attention ops (all on one path, T-Mix blocks included) plus the deepest reconstruction path
    (the temporal step, its down-sampling chain and the widest per-scale kernel)."""
    from .model.layers import MultiHeadRaNA

    core = model.single if is_cross_frame(model) else model
    rf = sum(m.radius for m in core.modules() if isinstance(m, MultiHeadRaNA) and not _in_recon(model, m))
    rec = max((sum(d.radius for d in r.down) + max(p.radius for p in r.per_scale) for r in core.recon.values()),
              default=0.0)
    return int(math.ceil(rf + rec + temporal_reach(model)))


def temporal_reach(model) -> float:
    """The part of a cross-frame model's reach that a window of one frame skips: the T-Mix blocks' radii, the
    temporal step before the spatial reconstruction and the output mix after it (0 for a single-frame model)."""
    if not is_cross_frame(model):
        return 0.0
    return sum(t.attn.radius for t in model.tmix) \
        + model.config.temporal_radius * (2 if getattr(model.config, "output_mix", False) else 1)


def _in_recon(model, module) -> bool:
    core = model.single if is_cross_frame(model) else model
    return any(module is m for m in core.recon.modules())


def halo_for_bound(model) -> int:
    """The receptive-field bound rounded up to ALIGN: a halo that makes tiles exactly equal to the whole frame."""
    return int(math.ceil(receptive_field(model) / ALIGN) * ALIGN)


def halo_for(model) -> int:
    """The default tile halo: the model's measured halo (metadata "halo", halo.py) when it has one, else the
    receptive-field bound."""
    measured = getattr(model, "measured_halo", None)
    return min(int(measured), halo_for_bound(model)) if measured else halo_for_bound(model)


def tile_windows(width: int, height: int, tile: int, halo: int):
    """Yield (core, haloed) windows (x0, y0, x1, y1 inclusive, data-window-relative) covering the frame."""
    for y0 in range(0, height, tile):
        for x0 in range(0, width, tile):
            core = (x0, y0, min(x0 + tile, width) - 1, min(y0 + tile, height) - 1)
            halo_win = (max(0, x0 - halo), max(0, y0 - halo), min(width, x0 + tile + halo) - 1,
                        min(height, y0 + tile + halo) - 1)
            yield core, halo_win


def window_bins(offsets: np.ndarray, width: int, win) -> tuple[np.ndarray, np.ndarray]:
    """(bin indices of the window's pixels in row-major order, the window's offsets)."""
    x0, y0, x1, y1 = win
    rows = np.arange(y0, y1 + 1)
    pix = (rows[:, None] * width + np.arange(x0, x1 + 1)[None, :]).ravel()
    starts, ends = offsets[pix], offsets[pix + 1]
    counts = ends - starts
    local = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    idx = np.repeat(starts - local[:-1], counts) + np.arange(local[-1])
    return idx.astype(np.int64), local


def _bins_integral(offsets: np.ndarray, width: int, height: int) -> np.ndarray:
    counts = np.diff(offsets).reshape(height, width)
    integral = np.zeros((height + 1, width + 1), np.int64)
    integral[1:, 1:] = counts.cumsum(0).cumsum(1)
    return integral


def _window_bins(integral: np.ndarray, width: int, height: int, tile: int, halo: int) -> np.ndarray:
    """Bins of every haloed window of tile_windows(width, height, tile, halo), [rows of tiles, columns]."""
    xs, ys = np.arange(0, width, tile), np.arange(0, height, tile)
    x0, x1 = np.maximum(0, xs - halo), np.minimum(width, xs + tile + halo)     # x1, y1: one past the window
    y0, y1 = np.maximum(0, ys - halo), np.minimum(height, ys + tile + halo)
    return (integral[np.ix_(y1, x1)] - integral[np.ix_(y0, x1)] - integral[np.ix_(y1, x0)]
            + integral[np.ix_(y0, x0)])


def _work(bins: np.ndarray) -> int:
    return int(bins.sum()) + TILE_OVERHEAD_BINS * bins.size


def tiling_work(offsets: np.ndarray, width: int, height: int, tile: int, halo: int) -> int:
    """choose_tile's measure of a tiling's work: the bins its haloed windows compute plus TILE_OVERHEAD_BINS per
    tile."""
    return _work(_window_bins(_bins_integral(offsets, width, height), width, height, tile, halo))


def _worst_window(integral: np.ndarray, width: int, height: int, tile: int, halo: int) -> int:
    return int(_window_bins(integral, width, height, tile, halo).max())


def tile_bytes(offsets: np.ndarray, width: int, height: int, tile: int, halo: int, frames: int = 1) -> float:
    """Model working memory of the fullest haloed window at tile size `tile` (`frames` frames per window)."""
    return float(_worst_window(_bins_integral(offsets, width, height), width, height, tile, halo)) * BYTES_PER_BIN \
        * frames


# a tile's fixed cost, in bins' worth of model work (its gather, launches, scatter): among tilings that compute
# nearly the same bins, the one with fewer tiles wins
TILE_OVERHEAD_BINS = 20000
# on the CPU, the most bins of one haloed window the tile choice aims for, whatever the memory budget: larger tiles
# are no faster per bin and hold more memory. Measured on the held-out 1080p frame of bench/denoise.py (`ranad
# denoise --profile`, 2 threads, single runs whose spread is about 5%): 8.2 us per haloed bin with windows of 0.1-0.4
# M bins, 8.5-9.5 at 0.6 M, 9.2-9.5 at 1.7 M. With this cap that frame runs in 6 tiles (0.61 M bins at most, 1.03x
# the bins) instead of 2, at a 3.5 GB peak instead of 5.5.
CPU_TILE_BINS = 800_000


def tile_candidates(width: int, height: int) -> list:
    """Aligned tile sizes that split the width or the height into 1, 2, 3, ... nearly equal tiles, largest first."""
    return sorted({ALIGN * math.ceil(math.ceil(n / k) / ALIGN) for n in (width, height)
                   for k in range(1, math.ceil(n / ALIGN) + 1)}, reverse=True)


def choose_tile(offsets: np.ndarray, width: int, height: int, halo: int, budget_bytes: float,
                frames: int = 1, max_bins: int | None = None) -> int:
    """The aligned tile with the least work whose haloed windows all fit the memory budget: the fewest bins
    computed (the halos overlap; a tiling whose last row or column is a sliver pays a whole halo for it) plus
    TILE_OVERHEAD_BINS per tile, over tile_candidates. ALIGN when none fits (the caller checks that size against
    the budget with tile_bytes); `frames` windows of frames share the budget; `max_bins`: a cap on a window's bins
    per frame besides the budget (CPU_TILE_BINS on the CPU)."""
    if width <= 0 or height <= 0:
        return ALIGN
    integral = _bins_integral(offsets, width, height)
    limit = max(1, int(budget_bytes // (BYTES_PER_BIN * frames)))
    if max_bins is not None:
        limit = min(limit, max_bins)
    best = None
    for tile in tile_candidates(width, height):
        if best is not None and tile * 4 < best[1]:
            break   # a quarter of the best size and below: only more halo
        bins = _window_bins(integral, width, height, tile, halo)
        if bins.max() > limit:
            continue
        cost = _work(bins)
        if best is None or cost < best[0]:
            best = (cost, tile)
    return ALIGN if best is None else best[1]


def _fix_nonfinite(img: DeepImage, depth=DEPTHS) -> tuple[DeepImage, int]:
    """The NaN/Inf policy (deep.replace_nonfinite) on the canonical image the model reads."""
    return replace_nonfinite(img, depth)


@dataclass
class _Frame:
    """One frame of a window as the model reads it: canonical, sorted, with its residual, depth stats, exposure
    scale and feature set (the flat prior's channels attached for "prior" models)."""
    srt: DeepImage
    perm: np.ndarray
    residual: np.ndarray | None
    stats: tuple
    nonfinite: int
    features: str = "log1p"
    scale: float = 1.0
    groups: Groups | None = None   # thin bins merged into one (binmerge); srt and residual hold the merged bins


def model_features(model) -> str:
    return getattr(model.config, "features", "log1p")


def _model_frame(img: DeepImage, mapping: ChannelMap, features: str = "log1p", prior: "FramePrior | None" = None,
                 merge_gap: float | None = None) -> _Frame:
    """`prior`: the frame's flat prior made before motion compensation, whose channels `img` carries (a moved
    neighbour, see denoise_window); None: made here, on `img` as it is. `merge_gap`: binmerge's gap (None: its
    default; 0: no merging)."""
    canon, residual = canonical(img, mapping)
    canon, nonfinite = _fix_nonfinite(canon)
    if residual is not None:
        residual = np.nan_to_num(residual, nan=0.0, posinf=0.0, neginf=0.0)
    with stage("inputs/sort and prior"):
        srt, perm = canon.sorted(copy=False)   # canon is this function's own
        res = np.take(residual, perm, axis=0) if residual is not None else None
        groups = binmerge.groups_of(srt, img, perm, merge_gap)
        if groups is not None:
            srt = binmerge.merge(srt, groups)
            if res is not None:
                res = binmerge.merge_values(res, groups, "composite").astype(np.float32)
        scale = 1.0
        if features == "prior" and prior is not None:
            scale = prior.scale
        elif features == "prior":  # whole-frame prior and exposure, before tiling, so tiles agree
            from .model.prior import frame_scale, with_prior

            srt = with_prior(srt, res, presorted=True)
            scale = frame_scale(srt)
    return _Frame(srt, perm, res, depth_stats(srt), nonfinite, features, scale, groups)


@dataclass
class FramePrior:
    """A frame's flat prior as its own bins carry it (channels.PRIOR + FLAT_NOISY, [N, 6] in the file's bin
    order) and its exposure scale: made once per frame of a shot and carried by motion compensation onto every
    centre frame whose window holds it, so OIDN runs once per frame rather than once per window and frame."""
    columns: np.ndarray
    scale: float

    @classmethod
    def of(cls, img: DeepImage, mapping: ChannelMap) -> "FramePrior":
        fr = _model_frame(img, mapping, "prior", merge_gap=0.0)   # per-pixel values: merging changes nothing
        cols = fr.srt.columns((*PRIOR, *FLAT_NOISY))
        return cls(unsort(cols, fr.perm), fr.scale)

    def attached(self, img: DeepImage) -> DeepImage:
        """`img` (the frame it was made from) with the prior's channels added (concat_columns: numpy's concatenation
        of the two took 0.39 s of bench/shot.py's 5-frame 480x270 shot)."""
        cols = torch.from_numpy(self.columns.astype(img.values.dtype))
        values = concat_columns([torch.from_numpy(img.values), cols]).numpy()
        return img.with_values(values, list(img.channels) + [*PRIOR, *FLAT_NOISY])


def _tile_inputs(fr: _Frame, win, width: int):
    idx, local = window_bins(fr.srt.offsets, width, win)
    # np.take: numpy's row gather, half the time of fancy indexing's
    sub = DeepImage(values=np.take(fr.srt.values, idx, axis=0), offsets=local, channels=fr.srt.channels,
                    data_window=(0, 0, win[2] - win[0], win[3] - win[1]))
    inputs = prepare(sub, fr.stats, fr.features, fr.scale)
    if fr.residual is not None:
        inputs.layers["diffuse"] = torch.cat([inputs.layers["diffuse"],
                                              torch.from_numpy(np.take(fr.residual, idx, axis=0))], 1)
    return inputs, idx, local


def _core_mask(local: np.ndarray, win, core) -> np.ndarray:
    pix = np.repeat(np.arange(local.size - 1), np.diff(local))
    wide = win[2] - win[0] + 1
    py, px = pix // wide + win[1], pix % wide + win[0]
    return (py >= core[1]) & (py <= core[3]) & (px >= core[0]) & (px <= core[2])


def denoise_frame(model, img: DeepImage, mapping: ChannelMap | None = None, tile: int | None = None,
                  halo: int | None = None, keep_noisy: str | None = None, want_embeddings: bool = False,
                  progress=None) -> FrameResult:
    """Denoise one frame on its own (a window of one frame)."""
    return denoise_window(model, [img], 0, mapping, tile, halo, keep_noisy, want_embeddings, progress)


def denoise_window(model, images: list, centre: int, mapping: ChannelMap | None = None, tile: int | None = None,
                   halo: int | None = None, keep_noisy: str | None = None, want_embeddings: bool = False,
                   progress=None, flows: list | None = None, priors: list | None = None,
                   keep_depth: bool = False, merge_gap: float | None = None,
                   dark_radius: int | None = None, light_match: bool = True) -> FrameResult:
    """Denoise frame `centre` of `images` (a window of consecutive frames; neighbours are motion-compensated onto
    it, in display coordinates where their data windows differ). `tile`: tile size in pixels (None: the whole
    frame); `halo`: None for the model's receptive field; `keep_noisy`: a prefix under which the noisy versions
    of the replaced channels are kept; `progress(n)` is called per tile; `flows`: per frame, None or its
    per-pixel flow [H, W, 4] (motion.compensate). A single-frame model uses the centre frame only.

    A cross-frame model on the flat prior gets every frame's prior made on that frame before compensation and
    carried with its bins (FramePrior); `priors`: per window frame, its FramePrior or None, a list the caller
    keeps across the windows of a shot (shot.py) and this fills in where None. `keep_depth`: the depth layer is
    not reconstructed and the file's depths are written as they are. `merge_gap`: thin bins of one surface within
    this relative depth gap are denoised as one and shared back (binmerge; None: its default, 0: off).
    `dark_radius`: the radius of darkness' black windows: bins of exactly black windows and of holdout objects keep
    their colour, 0 (None: its default, 0: off). `light_match`: models on the flat prior bring each region's light
    within 2% of the noisy render's own (lightmatch.py; False: off).

    Tiles run where the model is (`model.to("cuda")`: `ranad denoise --device cuda`), and so does the flat prior's
    OIDN; inputs are prepared and outputs assembled on the CPU."""
    from .model.prior import oidn_on

    device = next(model.parameters()).device
    with oidn_on(device.type):
        return _denoise_window(model, images, centre, mapping, tile, halo, keep_noisy, want_embeddings, progress,
                               flows, priors, keep_depth, device,
                               binmerge.MERGE_GAP if merge_gap is None else float(merge_gap),
                               darkness.DARK_RADIUS if dark_radius is None else int(dark_radius), light_match)


def _denoise_window(model, images, centre, mapping, tile, halo, keep_noisy, want_embeddings, progress, flows,
                    priors, keep_depth, device, merge_gap, dark_radius, light_match) -> FrameResult:
    from .motion import compensate

    cross = is_cross_frame(model)
    if not cross:
        images, centre, flows = [images[centre]], 0, None
    img = images[centre]
    mapping = mapping or detect(img)
    features = model_features(model)
    carried = [None] * len(images)
    if len(images) > 1 and features == "prior":
        priors = [None] * len(images) if priors is None else priors
        with stage("inputs"):
            for i, im in enumerate(images):
                if priors[i] is None:
                    priors[i] = FramePrior.of(im, mapping)
                    # the prior's freed scratch before the next frame's (prior_need counts one frame's at a time: a
                    # 2-frame 1080p window at --max-memory 4G peaked at 4.05 GiB here, runs/generalization-s39)
                    heap.relieve()
        carried = list(priors)
        sources = [p.attached(im) for p, im in zip(carried, images)]
    else:
        sources = images
    if len(images) > 1:
        with stage("motion"):
            moved, dropped = compensate(sources, centre, flows=flows, motion=mapping.motion)
    else:
        moved, dropped = images, 0
    with stage("inputs"):
        # thin bins are merged in every frame of the window (a thin neighbour left as it is costs the cross-frame
        # model: runs/bin-merge-s15)
        frames = [_model_frame(m, mapping, features, p, merge_gap) for m, p in zip(moved, carried)]
    # the window's copies with the prior's channels and the compensated neighbours (every channel of the files) are
    # not read again: held through the tiles they were 1.5 GB of a 2-frame 1080p window (runs/generalization-s39)
    del sources, moved
    heap.relieve()   # the prior's freed scratch, where the resident set nears the memory ceiling
    c = frames[centre]
    n = c.srt.num_bins
    h, w = c.srt.height, c.srt.width
    halo = halo_for(model) if halo is None else int(math.ceil(halo / ALIGN) * ALIGN)
    tile = max(w, h) if tile is None else max(ALIGN, int(tile) // ALIGN * ALIGN)
    outs: dict = {}
    embs = [None] * len(frames) if want_embeddings else None
    tiles = 0
    for core, win in tile_windows(w, h, tile, halo):
        tiles += 1
        t_tile = time.perf_counter()
        with stage("tiles"):
            with stage("tiles/gather"):
                parts = [_tile_inputs(fr, win, w) for fr in frames]
            if parts[centre][1].size:
                window = [p[0].to(device) for p in parts]
                if keep_depth:   # the depth layer is not reconstructed (nor written back); the gate keeps its depths
                    for inp in window:
                        inp.layers.pop("depth", None)
                with torch.inference_mode():
                    # embeddings are rounded to float16, the precision of the AOV cache, before the
                    # reconstruction, so `ranad aov` rebuilds exactly these kernels and light groups sum to this
                    # beauty
                    with stage("tiles/backbone"):
                        if cross:
                            feats = [f.half().float() for f in model.embeddings(window, centre)]
                        else:
                            feats = [model.embeddings(window[0]).half().float()]
                    with stage("tiles/reconstruction"):
                        if cross:
                            pred = model.reconstruct(feats, window, centre)
                        else:
                            pred = model.reconstruct(feats[0], window[0])
                with stage("tiles/scatter"):
                    keep = _core_mask(parts[centre][2], win, core)
                    dst = parts[centre][1][keep]
                    for k, v in pred.items():
                        if k not in outs:
                            outs[k] = np.zeros((n, v.shape[1]), np.float32)
                        outs[k][dst] = v.cpu().numpy()[keep]
                    if want_embeddings:
                        for f, (fr, (_, idx, local)) in enumerate(zip(frames, parts)):
                            if embs[f] is None:
                                embs[f] = np.zeros((fr.srt.num_bins, feats[f].shape[1]), np.float16)
                            kf = _core_mask(local, win, core)
                            embs[f][idx[kf]] = feats[f].cpu().numpy()[kf].astype(np.float16)
                record_tile(int(parts[centre][1].size), int(keep.sum()), time.perf_counter() - t_tile,
                            sum(int(p[1].size) for p in parts))
        heap.relieve()
        if progress:
            progress(1)
    gain = None
    if light_match and features == "prior" and n:
        with stage("light match"):
            gain = lightmatch.frame_gain(c.srt, outs)
            lightmatch.apply(outs, gain, c.srt.offsets)
    with stage("assemble"):
        factors = None
        if c.groups is not None and n:
            alpha = outs["alpha"] if "alpha" in outs else c.srt.channel(ALPHA)
            factors = binmerge.split_factors(c.groups, alpha)
        out = _assemble(img, mapping, c.srt, c.perm, outs, keep_noisy, c.groups, factors, dark_radius) if n else img
    if want_embeddings:
        def width(f):
            return model.embedding_width(f == centre, len(frames)) if cross else model.embedding_width()

        embs = [e if e is not None else np.zeros((fr.srt.num_bins, width(f)), np.float16)
                for f, (e, fr) in enumerate(zip(embs, frames))]
    merges = [None if fr.groups is None else fr.groups.index for fr in frames]
    return FrameResult(out, img.num_bins, c.nonfinite, tiles, embs, [fr.perm for fr in frames],
                       [fr.stats for fr in frames], [fr.srt.offsets for fr in frames], mapping, dropped,
                       merges if any(g is not None for g in merges) else None, factors, merge_gap, dark_radius,
                       gain, centre)


def write_columns(values: np.ndarray, channels: list, names, data) -> None:
    """values[:, channel of names[i]] = data[:, i] for every i, in place, as if written one by one in order (a
    channel named twice keeps its last column). In one threaded pass over the rows (torch's index_copy_): a numpy
    write per column was a strided pass over the whole frame each, 0.6 s of a 6.5 M-bin, 38-channel frame against
    0.07 s."""
    last = {channels.index(name): i for i, name in enumerate(names)}
    block = np.ascontiguousarray(data, dtype=np.float32).reshape(len(values), len(names))
    if len(last) < len(names):
        block = np.ascontiguousarray(block[:, list(last.values())])
    torch.from_numpy(values).index_copy_(1, torch.tensor(list(last), dtype=torch.int64), torch.from_numpy(block))


def _assemble(img: DeepImage, m: ChannelMap, srt: DeepImage, perm: np.ndarray, outs: dict,
              keep_noisy: str | None, groups: Groups | None = None, factors: np.ndarray | None = None,
              dark_radius: int = 0) -> DeepImage:
    """The output image: the file's channels with the denoised layers written back (file bin order). `groups`,
    `factors`: merged thin bins (binmerge) shared back among their members before anything is written;
    `dark_radius`: darkness.dark_bins' radius (their colour is written as it was, 0)."""
    img = replace_nonfinite(img, m.depth_channels())[0]    # one NaN/Inf policy for every channel of the output
    file_vals = copy_values(img.values)
    ch = img.channels
    replaced = []

    def write(names, data):
        write_columns(file_vals, ch, names, data)
        replaced.extend(names)

    def back(a):   # sorted (merged) order -> file order (read only here, so not copied when already in order)
        return unsort(a if groups is None else binmerge.split(a, groups, factors), perm, copy=False)

    diffuse = back(outs["diffuse"])
    emission = layer_values(img, m.layers.get("emission"))
    emission = 0 if emission is None else emission
    if m.split:
        for chans, part in split_layer(img, m.layers["diffuse"], diffuse[:, :3]):
            write(chans, part)
        specular = back(outs["specular"])
        for chans, part in split_layer(img, m.layers["specular"], specular):
            write(chans, part)
        beauty = diffuse[:, :3] + specular + emission + diffuse[:, 3:6]
    else:
        beauty = diffuse[:, :3] + emission
    write(m.beauty, beauty)
    dark = darkness.dark_bins(img, m, dark_radius)
    if dark is not None:
        cols = [ch.index(c) for c in darkness.colour_channels(m)]
        file_vals[np.ix_(dark, cols)] = img.values[np.ix_(dark, cols)]
    if "alpha" in outs:
        alpha = np.clip(outs["alpha"], 0, 1)
        write([m.alpha], np.clip(unsort(alpha if groups is None else binmerge.split_alpha(alpha, groups, factors)
                                        [:, None], perm, copy=False), 0, 1))
    if "depth" in outs:
        z_new = np.maximum(outs["depth"][:, 0], 0)
        if groups is None:
            thick = np.maximum(srt.values[:, srt.channels.index(DEPTH_BACK)] - srt.channel(DEPTH), 0) \
                if m.depth_back else 0
        else:
            z_new, thick = binmerge.split_depth(z_new, groups), groups.thick.astype(np.float32)
        write([m.depth], unsort(z_new, perm, copy=False)[:, None])
        if m.depth_back:
            write([m.depth_back], unsort(z_new + thick, perm, copy=False)[:, None])
    out = img.with_values(file_vals)
    if keep_noisy:
        names = [f"{keep_noisy}{c}" for c in replaced]
        clash = [c for c in names if c in ch]
        if clash:
            raise ValueError(f"--keep-noisy prefix {keep_noisy!r} collides with existing channels {clash}")
        types = {**img.channel_types, **{f"{keep_noisy}{c}": img.channel_types.get(c, "half") for c in replaced}}
        out = DeepImage(values=np.concatenate([file_vals, img.values[:, [ch.index(c) for c in replaced]]], 1),
                        offsets=img.offsets, channels=ch + names, ids=img.ids, data_window=img.data_window,
                        display_window=img.display_window, channel_types=types, header=img.header)
    return out
