"""Motion compensation of deep frames onto a centre frame (paper Sec. 4.2): every bin of a neighbouring frame is
re-bucketed into the centre frame's pixel where its surface point is at the centre frame's time.

Channel conventions (what `ranad synth` writes, in pixels, x right, y down):

- per-bin motion: `motion_prev.X/Y` (offset to the bin's position in the previous frame) and `motion_next.X/Y`
  (in the next frame). A frame before the centre moves by its `motion_next`, one after by its `motion_prev`.
- per-pixel flow (when the deep file has no per-bin motion): flat images with the same channel names, one per
  frame, given as arrays [H, W, 4] in the order motion_prev.X, motion_prev.Y, motion_next.X, motion_next.Y
  (`read_flow`); every bin of a pixel moves with its pixel.
- neither: no motion (the frames are assumed aligned).

Frames two or more steps away are moved hop by hop: the first hop with the frame's own motion, each further hop
with the intermediate frame's dominant per-pixel motion at the position reached (the motion of the bin that
contributes most to that pixel), or the previous hop's motion again where that pixel is empty. Bins that leave the frame are dropped and counted. Within a target pixel the
moved bins keep their frame's relative order; the model sorts by depth anyway.
"""

from __future__ import annotations

import numpy as np

from .deep import DeepImage, gather_bins

PREV, NEXT = "motion_prev", "motion_next"
FLOW_CHANNELS = (f"{PREV}.X", f"{PREV}.Y", f"{NEXT}.X", f"{NEXT}.Y")


def has_bin_motion(img: DeepImage) -> bool:
    return all(c in img.channels for c in FLOW_CHANNELS)


def bin_motion(img: DeepImage, name: str) -> np.ndarray:
    """[N, 2] per-bin motion (dx, dy) of channel layer `name` (motion_prev or motion_next)."""
    return np.stack([img.channel(f"{name}.X"), img.channel(f"{name}.Y")], 1).astype(np.float32)


def dominant_flow(img: DeepImage, name: str) -> np.ndarray:
    """[H, W, 2] per-pixel motion: the motion of the bin with the largest visible contribution (T_i * alpha_i);
    NaN where the pixel has no bins."""
    flow = np.full((img.num_pixels, 2), np.nan, np.float32)
    if img.num_bins == 0:
        return flow.reshape(img.height, img.width, 2)
    srt, perm = img.sorted()
    a = np.clip(srt.channel("A"), 0, 1).astype(np.float32)
    pix = srt.pixel_index()
    logt = np.log1p(-np.minimum(a, 1 - 1e-6)).astype(np.float64)
    excl = np.cumsum(logt) - logt                           # sum over all earlier bins of the image
    before = excl - excl[srt.offsets[:-1][pix]]             # ... of the same pixel: log transmittance in front
    weight = np.exp(before) * a
    order = np.lexsort((-weight, pix))                      # per pixel, the heaviest bin first
    heads = order[np.r_[True, pix[order][1:] != pix[order][:-1]]]
    flow[pix[heads]] = bin_motion(srt, name)[heads]
    return flow.reshape(img.height, img.width, 2)


def rebucket(img: DeepImage, dxy: np.ndarray) -> tuple[DeepImage, int]:
    """Move every bin by dxy [N, 2] pixels to the nearest pixel; returns (moved image, bins dropped at borders)."""
    w, h = img.width, img.height
    pix = img.pixel_index()
    y, x = np.divmod(pix, w)
    tx = np.floor(x + dxy[:, 0] + 0.5).astype(np.int64)
    ty = np.floor(y + dxy[:, 1] + 0.5).astype(np.int64)
    inside = (tx >= 0) & (tx < w) & (ty >= 0) & (ty < h)
    keep = np.flatnonzero(inside)
    target = ty[keep] * w + tx[keep]
    order = keep[np.argsort(target, kind="stable")]
    counts = np.bincount(target, minlength=w * h)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return gather_bins(img, order, offsets), int(len(pix) - len(keep))


def _sample(flow: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    h, w = flow.shape[:2]
    xi = np.clip(np.floor(x + 0.5).astype(np.int64), 0, w - 1)
    yi = np.clip(np.floor(y + 0.5).astype(np.int64), 0, h - 1)
    return flow[yi, xi]


def displacement(frames: list, index: int, centre: int, flows: list | None = None) -> np.ndarray:
    """[N, 2] offsets that carry frame `index`'s bins to frame `centre` (zeros without motion data)."""
    img = frames[index]
    n = img.num_bins
    if index == centre:
        return np.zeros((n, 2), np.float32)
    step = 1 if index < centre else -1
    name = NEXT if step > 0 else PREV
    col = 2 if step > 0 else 0

    def per_pixel(k):
        if has_bin_motion(frames[k]):
            return dominant_flow(frames[k], name)
        if flows is not None and flows[k] is not None:
            return np.asarray(flows[k], np.float32)[..., col:col + 2]
        return None

    if has_bin_motion(img):
        d = bin_motion(img, name)
    else:
        f = per_pixel(index)
        if f is None:
            return np.zeros((n, 2), np.float32)
        d = np.nan_to_num(f.reshape(-1, 2)[img.pixel_index()])
    y, x = np.divmod(img.pixel_index(), img.width)
    d = np.nan_to_num(d.astype(np.float64))
    hop = d.copy()
    for k in range(index + step, centre, step):
        f = per_pixel(k)
        if f is None:
            break
        nxt = _sample(f, x + d[:, 0], y + d[:, 1]).astype(np.float64)
        hop = np.where(np.isnan(nxt), hop, nxt)            # empty pixel: keep moving as before
        d = d + hop
    return d.astype(np.float32)


def compensate(frames: list, centre: int, flows: list | None = None) -> tuple[list, int]:
    """Every frame of a window moved onto frame `centre`; returns (frames, bins dropped in all)."""
    out, dropped = [], 0
    for i, img in enumerate(frames):
        if i == centre:
            out.append(img)
            continue
        moved, lost = rebucket(img, displacement(frames, i, centre, flows))
        out.append(moved)
        dropped += lost
    return out, dropped
