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
from dataclasses import dataclass, field

import numpy as np
import torch

from .channels import ChannelMap, canonical, detect
from .deep import DeepImage, unsort
from .model.inputs import depth_stats, prepare

ALIGN = 16                 # tile origins: multiples of the position encoding's longest period
BYTES_PER_BIN = 2048       # model working memory per bin at inference (measured ~1.6 KB for cpu-small)


@dataclass
class FrameResult:
    image: DeepImage
    bins: int
    nonfinite: int                       # bins that had a non-finite value in a channel the model reads
    tiles: int
    embeddings: np.ndarray | None = None  # [N, dim] float16, sorted bin order (for the AOV cache)
    perm: np.ndarray | None = None        # sort permutation (sorted row i is file row perm[i])
    z_stats: tuple = (0.0, 1.0)
    mapping: ChannelMap | None = None
    extra: dict = field(default_factory=dict)


def receptive_field(model) -> int:
    """An upper bound, in pixels, of how far a bin's output can depend on other pixels: the sum of the radii of
    the backbone's attention ops (all on one path) plus the deepest reconstruction path (its down-sampling
    chain and the widest per-scale kernel)."""
    from .model.layers import MultiHeadRaNA

    rf = sum(m.radius for m in model.backbone.modules() if isinstance(m, MultiHeadRaNA))
    rec = max((sum(d.radius for d in r.down) + max(p.radius for p in r.per_scale) for r in model.recon.values()),
              default=0.0)
    return int(math.ceil(rf + rec))


def halo_for(model) -> int:
    return int(math.ceil(receptive_field(model) / ALIGN) * ALIGN)


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


def choose_tile(offsets: np.ndarray, width: int, height: int, halo: int, budget_bytes: float) -> int:
    """The largest aligned tile whose haloed windows all fit the memory budget (at least ALIGN)."""
    counts = np.diff(offsets).reshape(height, width)
    integral = np.zeros((height + 1, width + 1), np.int64)
    integral[1:, 1:] = counts.cumsum(0).cumsum(1)
    limit = max(1, int(budget_bytes // BYTES_PER_BIN))
    tile = ALIGN * max(1, math.ceil(max(width, height) / ALIGN))
    while tile > ALIGN:
        worst = max(integral[y1 + 1, x1 + 1] - integral[y0, x1 + 1] - integral[y1 + 1, x0] + integral[y0, x0]
                    for _, (x0, y0, x1, y1) in tile_windows(width, height, tile, halo))
        if worst <= limit:
            return tile
        tile = max(ALIGN, (tile // 2) // ALIGN * ALIGN)
    return ALIGN


def _fix_nonfinite(img: DeepImage) -> tuple[DeepImage, int]:
    vals = img.values
    bad = ~np.isfinite(vals)
    if not bad.any():
        return img, 0
    n = int(bad.any(axis=1).sum())
    vals = vals.copy()
    for col in ("Z", "ZBack"):
        if col in img.channels:
            j = img.channels.index(col)
            fin = np.isfinite(vals[:, j])
            vals[~fin, j] = vals[fin, j].max() if fin.any() else 0.0
    vals[~np.isfinite(vals)] = 0.0
    return img.with_values(vals), n


def denoise_frame(model, img: DeepImage, mapping: ChannelMap | None = None, tile: int | None = None,
                  halo: int | None = None, keep_noisy: str | None = None, want_embeddings: bool = False,
                  progress=None) -> FrameResult:
    """Denoise one frame. `tile`: tile size in pixels (None: the whole frame as one tile); `halo`: None for the
    model's receptive field; `keep_noisy`: a prefix under which the noisy versions of the replaced channels are
    kept; `progress(n)` is called per tile."""
    mapping = mapping or detect(img)
    canon, residual = canonical(img, mapping)
    canon, nonfinite = _fix_nonfinite(canon)
    if residual is not None:
        residual = np.nan_to_num(residual, nan=0.0, posinf=0.0, neginf=0.0)
    srt, perm = canon.sorted()
    res_sorted = residual[perm] if residual is not None else None
    n = srt.num_bins
    h, w = srt.height, srt.width
    halo = halo_for(model) if halo is None else int(math.ceil(halo / ALIGN) * ALIGN)
    tile = max(w, h) if tile is None else max(ALIGN, int(tile) // ALIGN * ALIGN)
    stats = depth_stats(srt)
    outs: dict = {}
    emb_all = None
    tiles = 0
    for core, win in tile_windows(w, h, tile, halo):
        idx, local = window_bins(srt.offsets, w, win)
        tiles += 1
        if idx.size:
            sub = DeepImage(values=srt.values[idx], offsets=local, channels=srt.channels,
                            data_window=(0, 0, win[2] - win[0], win[3] - win[1]))
            inputs = prepare(sub, stats)
            if res_sorted is not None:
                inputs.layers["diffuse"] = torch.cat([inputs.layers["diffuse"], torch.from_numpy(res_sorted[idx])], 1)
            with torch.inference_mode():
                emb = model.embeddings(inputs)
                pred = {k: m(emb, inputs.layout, inputs.layers[k]) for k, m in model.recon.items()
                        if k in inputs.layers}
            pix = np.repeat(np.arange(local.size - 1), np.diff(local))
            py, px = pix // (win[2] - win[0] + 1) + win[1], pix % (win[2] - win[0] + 1) + win[0]
            keep = (py >= core[1]) & (py <= core[3]) & (px >= core[0]) & (px <= core[2])
            dst = idx[keep]
            for k, v in pred.items():
                if k not in outs:
                    outs[k] = np.zeros((n, v.shape[1]), np.float32)
                outs[k][dst] = v.numpy()[keep]
            if want_embeddings:
                if emb_all is None:
                    emb_all = np.zeros((n, emb.shape[1]), np.float16)
                emb_all[dst] = emb.numpy()[keep].astype(np.float16)
        if progress:
            progress(1)
    out = _assemble(img, mapping, srt, perm, outs, keep_noisy) if n else img
    return FrameResult(out, n, nonfinite, tiles, emb_all, perm, stats, mapping)


def _assemble(img: DeepImage, m: ChannelMap, srt: DeepImage, perm: np.ndarray, outs: dict,
              keep_noisy: str | None) -> DeepImage:
    """The output image: the file's channels with the denoised layers written back (file bin order)."""
    file_vals = img.values.copy()
    ch = img.channels
    replaced = []

    def write(names, data):
        for i, name in enumerate(names):
            file_vals[:, ch.index(name)] = data[:, i]
            replaced.append(name)

    back = lambda a: unsort(a, perm)  # noqa: E731  sorted order -> file order
    diffuse = back(outs["diffuse"])
    emission = np.stack([img.channel(c) for c in m.layers["emission"]], 1) if m.layers.get("emission") else 0
    emission = np.nan_to_num(emission, nan=0.0, posinf=0.0, neginf=0.0)
    if m.split:
        write(m.layers["diffuse"], diffuse[:, :3])
        specular = back(outs["specular"])
        write(m.layers["specular"], specular)
        beauty = diffuse[:, :3] + specular + emission + diffuse[:, 3:6]
    else:
        beauty = diffuse[:, :3] + emission
    write(m.beauty, beauty)
    if "alpha" in outs:
        write([m.alpha], np.clip(back(outs["alpha"]), 0, 1))
    if "depth" in outs:
        z_noisy = srt.values[:, srt.channels.index("Z")]
        z_new = np.maximum(outs["depth"][:, 0], 0)
        write([m.depth], back(z_new)[:, None])
        if m.depth_back:
            thick = np.maximum(srt.values[:, srt.channels.index("ZBack")] - z_noisy, 0)
            write([m.depth_back], back(z_new + thick)[:, None])
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
