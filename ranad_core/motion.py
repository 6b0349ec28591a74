"""Motion compensation of deep frames onto a centre frame (paper Sec. 4.2): every bin of a neighbouring frame is
re-bucketed into the centre frame's pixel where its surface point is at the centre frame's time.

Where motion comes from (channel names and unit conversion live in channels.py, `MotionSpec`):

- per-bin motion in canonical form (pixels per frame, x right, y down): `motion_prev` (offset to the bin's
  position in the previous frame) and `motion_next` (in the next frame); by default the channels
  `motion_prev.X/Y` and `motion_next.X/Y` (what `ranad synth` writes), or any two channels a `--map` or a
  `--preset` names, converted from pixels, NDC or per-second velocity and y up or down. A frame before the
  centre moves by its `motion_next`, one after by its `motion_prev`.
- one direction is enough. Without `motion_next`, a frame k before the centre is carried with frame k+1's
  `motion_prev` vectors: every bin of frame k+1 says where its surface was in frame k, so a bin of frame k takes
  (minus) the vector of the frame k+1 bin that lands on its pixel with the closest depth, or, where none lands,
  the inverted per-pixel field (the front-most landing bin's, holes filled from their neighbours). Symmetrically
  without `motion_prev`, a frame after the centre is carried back with frame k-1's `motion_next`.
- per-pixel flow (when the deep file has no per-bin motion in a direction; `ranad denoise --flow`, read by
  flow.py): arrays [H, W, 4] per frame over its data window, canonical units, in the order motion_prev.X,
  motion_prev.Y, motion_next.X, motion_next.Y (NaN for a direction not given); every bin of a pixel moves with
  its pixel, and a missing direction is carried back from the neighbour's flow like per-bin motion.
- none of these: no motion (the frames are assumed aligned; `ranad denoise` warns).

Frames two or more steps away are moved hop by hop: the first hop with the frame's own motion, each further hop
with the motion of the intermediate frame's bin at the position reached whose depth is closest (and whose
object id is the same, where frames have ids), else that pixel's dominant motion (the bin that contributes most
to it), or the previous hop's motion again where the pixel is empty. Bins that leave
the frame are dropped and counted. Within a target pixel the moved bins keep their frame's relative order; the
model sorts by depth anyway.
"""

from __future__ import annotations

import numpy as np

from .channels import ALPHA, CANONICAL_MOTION, DEPTH, MotionSpec  # A, Z: required (detect refuses frames without)
from .deep import DeepImage, gather_bins
from .exr.inspect import object_ids

PREV, NEXT = "motion_prev", "motion_next"
FLOW_CHANNELS = (*CANONICAL_MOTION[PREV], *CANONICAL_MOTION[NEXT])
MATCH_DEPTH = float(np.log(2.0))      # a carried-back bin only takes the vector of a bin within 2x its depth
MATCH_RADIUS = 3                      # ... landing within this many pixels of its pixel centre (nearest first)
FILL_STEPS = 16                       # hole filling of inverted fields: neighbour averaging rounds


def has_bin_motion(img: DeepImage, motion: MotionSpec | None = None) -> bool:
    """Both directions of per-bin motion present."""
    spec = motion or MotionSpec.canonical()
    return spec.vectors(img, PREV) is not None and spec.vectors(img, NEXT) is not None


def has_any_motion(frames: list, motion: MotionSpec | None = None, flows: list | None = None) -> bool:
    """Whether any frame of a window carries motion in either direction (per bin or per-pixel flow)."""
    spec = motion or MotionSpec.canonical()
    if any(spec.vectors(f, d) is not None for f in frames for d in (PREV, NEXT)):
        return True
    return bool(flows) and any(f is not None for f in flows)


def bin_motion(img: DeepImage, name: str, motion: MotionSpec | None = None) -> np.ndarray | None:
    """[N, 2] canonical per-bin motion (dx, dy) towards `name` (motion_prev or motion_next), None if absent."""
    return (motion or MotionSpec.canonical()).vectors(img, name)


def _heads(img: DeepImage) -> tuple[np.ndarray, np.ndarray]:
    """(bin index in `img`, pixel) of each covered pixel's bin with the largest visible contribution
    (T_i * alpha_i, the transmittance in front of it times its alpha)."""
    srt, perm = img.sorted()
    a = np.clip(np.nan_to_num(srt.channel(ALPHA)), 0, 1).astype(np.float32)
    pix = srt.pixel_index()
    logt = np.log1p(-np.minimum(a, 1 - 1e-6)).astype(np.float64)
    excl = np.cumsum(logt) - logt                           # sum over all earlier bins of the image
    before = excl - excl[srt.offsets[:-1][pix]]             # ... of the same pixel: log transmittance in front
    weight = np.exp(before) * a
    order = np.lexsort((-weight, pix))                      # per pixel, the heaviest bin first
    heads = order[np.r_[True, pix[order][1:] != pix[order][:-1]]]
    return perm[heads], pix[heads]


def dominant_flow(img: DeepImage, name_or_vectors, motion: MotionSpec | None = None) -> np.ndarray:
    """[H, W, 2] per-pixel motion: the motion of the bin with the largest visible contribution (T_i * alpha_i);
    NaN where the pixel has no bins. `name_or_vectors`: a direction name, or [N, 2] per-bin vectors."""
    flow = np.full((img.num_pixels, 2), np.nan, np.float32)
    vec = (bin_motion(img, name_or_vectors, motion) if isinstance(name_or_vectors, str)
           else np.asarray(name_or_vectors, np.float32))
    if img.num_bins and vec is not None:
        b, p = _heads(img)
        flow[p] = vec[b]
    return flow.reshape(img.height, img.width, 2)


def _targets(img: DeepImage, dxy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(target pixel of every bin moved by dxy, rounded to the nearest; whether it is inside the frame)."""
    w, h = img.width, img.height
    y, x = np.divmod(img.pixel_index(), w)
    # a motion beyond the frame's size lands outside it whatever its size; clipped, 3e38 px casts to int64 cleanly
    lim = 2.0 * (w + h) + 2.0
    tx = np.floor(x + np.clip(dxy[:, 0], -lim, lim) + 0.5).astype(np.int64)
    ty = np.floor(y + np.clip(dxy[:, 1], -lim, lim) + 0.5).astype(np.int64)
    inside = (tx >= 0) & (tx < w) & (ty >= 0) & (ty < h)
    return np.where(inside, ty * w + tx, -1), inside


def rebucket(img: DeepImage, dxy: np.ndarray) -> tuple[DeepImage, int]:
    """Move every bin by dxy [N, 2] pixels to the nearest pixel; returns (moved image, bins dropped at borders)."""
    target, inside = _targets(img, dxy)
    keep = np.flatnonzero(inside)
    target = target[keep]
    order = keep[np.argsort(target, kind="stable")]
    counts = np.bincount(target, minlength=img.width * img.height)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return gather_bins(img, order, offsets), int(img.num_bins - len(keep))


def _fill_holes(field: np.ndarray, steps: int = FILL_STEPS) -> np.ndarray:
    """NaN pixels of a [H, W, 2] field take the mean of their valid 8-neighbours, repeatedly; what is still
    empty after `steps` rounds (far from any data) stays NaN."""
    f = field.astype(np.float64).copy()
    for _ in range(steps):
        bad = np.isnan(f[..., 0])
        if not bad.any():
            break
        valid = (~bad).astype(np.float64)
        vals = np.where(bad[..., None], 0.0, f)
        pv = np.pad(valid, 1)
        pf = np.pad(vals, ((1, 1), (1, 1), (0, 0)))
        h, w = bad.shape
        cnt = sum(pv[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1))
        tot = sum(pf[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1))
        fill = bad & (cnt > 0)
        if not fill.any():
            break
        f[fill] = tot[fill] / cnt[fill][:, None]
    return f.astype(np.float32)


def _log_depth(img: DeepImage) -> np.ndarray:
    z = np.nan_to_num(img.channel(DEPTH).astype(np.float64), nan=1e30, posinf=1e30)
    return np.log(np.maximum(z, 1e-6))


class _Candidates:
    """Bins of one frame placed at (sub-pixel) positions, sorted by the pixel they fall in, for `match`."""

    def __init__(self, img: DeepImage, xy: np.ndarray, rows: np.ndarray | None = None):
        w, h = img.width, img.height
        rows = np.arange(img.num_bins) if rows is None else rows
        xy = np.asarray(xy, np.float64)[rows]
        tx, ty = np.floor(xy[:, 0] + 0.5).astype(np.int64), np.floor(xy[:, 1] + 0.5).astype(np.int64)
        inside = (tx >= 0) & (tx < w) & (ty >= 0) & (ty < h)
        rows, xy, pix = rows[inside], xy[inside], (ty * w + tx)[inside]
        logz = _log_depth(img)[rows]
        order = np.lexsort((logz, pix))                   # by pixel, front-most first
        self.rows, self.xy, self.pix, self.logz = rows[order], xy[order], pix[order], logz[order]
        ids = object_ids(img)
        self.ids = None if ids is None else ids[self.rows]
        self.w, self.h = w, h

    def front(self) -> tuple[np.ndarray, np.ndarray]:
        """(pixel, bin) of the front-most bin in every pixel that has one."""
        first = np.r_[True, self.pix[1:] != self.pix[:-1]] if self.pix.size else np.zeros(0, bool)
        return self.pix[first], self.rows[first]

    def match(self, xy: np.ndarray, logz: np.ndarray, ids: np.ndarray | None, radius: int) -> np.ndarray:
        """For each query (position [Q, 2], log depth, object id), the candidate bin nearest to it among those
        within `radius` pixels, MATCH_DEPTH in log depth and of the same id (where both have ids); cost:
        distance + log-depth difference. Returns bin indices, -1 where none qualifies. Pixels within one ring
        are searched for every query, wider rings only for the queries still unmatched."""
        n = len(logz)
        best_cost, best = np.full(n, np.inf), np.full(n, -1, np.int64)
        if n == 0 or self.pix.size == 0:
            return best
        qx, qy = np.floor(xy[:, 0] + 0.5).astype(np.int64), np.floor(xy[:, 1] + 0.5).astype(np.int64)
        ids = ids if self.ids is not None else None
        rings = [[(0, 0)]] + [[(oy, ox) for oy in range(-r, r + 1) for ox in range(-r, r + 1)
                               if max(abs(oy), abs(ox)) == r] for r in range(1, radius + 1)]
        stages = [sum(rings[:2], [])] + rings[2:]           # the pixel and its 8 neighbours, then wider rings
        for stage, offsets in enumerate(stages):
            rows = np.arange(n) if stage == 0 else np.flatnonzero(best < 0)
            for oy, ox in offsets:
                cx, cy = qx[rows] + ox, qy[rows] + oy
                ok = (cx >= 0) & (cx < self.w) & (cy >= 0) & (cy < self.h)
                cell = np.where(ok, cy * self.w + cx, -1)
                lo = np.searchsorted(self.pix, cell, "left")
                cnt = np.where(ok, np.searchsorted(self.pix, cell, "right") - lo, 0)
                i = np.repeat(rows, cnt)
                if not i.size:
                    continue
                k = np.repeat(lo - np.concatenate([[0], np.cumsum(cnt)[:-1]]), cnt) + np.arange(i.size)
                dz = np.abs(logz[i] - self.logz[k])
                dist = np.hypot(self.xy[k, 0] - xy[i, 0], self.xy[k, 1] - xy[i, 1])
                good = (dz <= MATCH_DEPTH) & (dist <= radius + 0.75)
                if ids is not None:
                    good &= self.ids[k] == ids[i]
                cost = np.where(good, dist + dz, np.inf)
                better = cost < best_cost[i]
                # several candidates of one query may improve it: write in descending cost, the cheapest lands last
                o = np.argsort(-cost[better], kind="stable")
                ib, kb = i[better][o], k[better][o]
                best_cost[ib] = cost[better][o]
                best[ib] = kb
        hit = best >= 0
        best[hit] = self.rows[best[hit]]
        return best


def _pixel_xy(img: DeepImage) -> np.ndarray:
    y, x = np.divmod(img.pixel_index(), img.width)
    return np.stack([x, y], 1).astype(np.float64)


def _inverse(src: DeepImage, dst: DeepImage, dst_vec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Motion of `src`'s bins to the frame `dst`, from `dst`'s per-bin vectors that point from each `dst` bin to
    its position in `src` (the other direction). Returns ([N_src, 2] per-bin motion: minus the vector of the
    `dst` bin that lands nearest the bin's pixel centre (within MATCH_RADIUS pixels), within MATCH_DEPTH of its
    log depth and with the same object id where both frames have ids; NaN where none does) and [H, W, 2] the
    per-pixel field of `src`: the front-most landing bin's inverted vector, holes filled from their neighbours."""
    h, w = src.height, src.width
    field = np.full((h * w, 2), np.nan, np.float32)
    per_bin = np.full((src.num_bins, 2), np.nan, np.float32)
    if dst.num_bins == 0:
        return per_bin, field.reshape(h, w, 2)
    landing = _Candidates(dst, _pixel_xy(dst) + dst_vec)
    pix, rows = landing.front()
    field[pix] = -dst_vec[rows]
    field = _fill_holes(field.reshape(h, w, 2))
    if src.num_bins:
        best = landing.match(_pixel_xy(src), _log_depth(src), object_ids(src), MATCH_RADIUS)
        hit = best >= 0
        per_bin[hit] = -dst_vec[best[hit]]
    return per_bin, field


class _Window:
    """The motion of a window's frames, per bin and per pixel, each computed once."""

    def __init__(self, frames: list, motion: MotionSpec | None, flows: list | None):
        self.frames, self.spec, self.flows = frames, motion or MotionSpec.canonical(), flows
        self._vec, self._field, self._inv, self._bins, self._cand = {}, {}, {}, {}, {}

    def vectors(self, k: int, name: str):
        """[N, 2] motion of frame k's bins towards `name`: its per-bin channels, else its per-pixel flow in that
        direction (every bin of a pixel moves with the pixel), else None."""
        if (k, name) not in self._vec:
            v = self.spec.vectors(self.frames[k], name)
            if v is None and self.flows is not None and self.flows[k] is not None:
                col = 2 if name == NEXT else 0
                flow = np.asarray(self.flows[k], np.float32).reshape(-1, 4)[:, col:col + 2]
                if not np.isnan(flow).all():
                    v = np.nan_to_num(flow[self.frames[k].pixel_index()], nan=0.0, posinf=0.0, neginf=0.0)
            self._vec[k, name] = v
        return self._vec[k, name]

    def inverse(self, k: int, name: str):
        """Frame k's motion towards `name` from its neighbour's opposite vectors, or None."""
        if (k, name) not in self._inv:
            other = k + (1 if name == NEXT else -1)
            back = PREV if name == NEXT else NEXT
            vec = self.vectors(other, back) if 0 <= other < len(self.frames) else None
            self._inv[k, name] = None if vec is None else _inverse(self.frames[k], self.frames[other], vec)
        return self._inv[k, name]

    def field(self, k: int, name: str):
        """[H, W, 2] per-pixel motion of frame k towards `name`, or None."""
        if (k, name) not in self._field:
            f, vec = None, self.vectors(k, name)
            if vec is not None:
                f = dominant_flow(self.frames[k], vec)
            elif self.inverse(k, name) is not None:
                f = self.inverse(k, name)[1]
            elif self.flows is not None and self.flows[k] is not None:
                col = 2 if name == NEXT else 0
                f = np.asarray(self.flows[k], np.float32)[..., col:col + 2]
            self._field[k, name] = f
        return self._field[k, name]

    def per_bin(self, k: int, name: str) -> np.ndarray | None:
        """[N, 2] motion of frame k's bins towards `name` (own vectors, carried back, or per pixel), or None."""
        if (k, name) not in self._bins:
            img, d = self.frames[k], None
            vec = self.vectors(k, name)
            if vec is not None:
                d = vec.astype(np.float64)
            elif self.inverse(k, name) is not None:
                per_bin, field = self.inverse(k, name)
                at_pixel = field.reshape(-1, 2)[img.pixel_index()]
                d = np.nan_to_num(np.where(np.isnan(per_bin), at_pixel, per_bin)).astype(np.float64)
            elif self.field(k, name) is not None:
                d = np.nan_to_num(self.field(k, name).reshape(-1, 2)[img.pixel_index()]).astype(np.float64)
            self._bins[k, name] = d
        return self._bins[k, name]

    def hop(self, k: int, name: str, xy: np.ndarray, logz: np.ndarray, ids) -> np.ndarray | None:
        """[Q, 2] motion towards `name` of bins that reached positions `xy` in frame k: the motion of frame k's
        bin at that pixel with the closest depth (and the same id), else the per-pixel field there (NaN where
        that is empty too); None when frame k has no motion towards `name`."""
        d = self.per_bin(k, name)
        if d is None:
            return None
        if k not in self._cand:
            self._cand[k] = _Candidates(self.frames[k], _pixel_xy(self.frames[k]))
        best = self._cand[k].match(xy, logz, ids, 0)
        out = _sample(self.field(k, name), xy[:, 0], xy[:, 1]).astype(np.float64)
        hit = best >= 0
        out[hit] = d[best[hit]]
        return out


def _sample(flow: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    h, w = flow.shape[:2]
    xi = np.clip(np.floor(x + 0.5).astype(np.int64), 0, w - 1)
    yi = np.clip(np.floor(y + 0.5).astype(np.int64), 0, h - 1)
    return flow[yi, xi]


def displacement(frames: list, index: int, centre: int, flows: list | None = None,
                 motion: MotionSpec | None = None, _win: _Window | None = None) -> np.ndarray:
    """[N, 2] offsets that carry frame `index`'s bins to frame `centre` (zeros without motion data).
    `motion`: which channels hold the motion and how to convert them (default: ranad's canonical channels)."""
    win = _win or _Window(frames, motion, flows)
    img = frames[index]
    n = img.num_bins
    if index == centre:
        return np.zeros((n, 2), np.float32)
    step = 1 if index < centre else -1
    name = NEXT if step > 0 else PREV
    d = win.per_bin(index, name)
    if d is None:
        return np.zeros((n, 2), np.float32)
    pos = _pixel_xy(img)
    logz, ids = _log_depth(img), object_ids(img)
    hop = d.copy()
    for k in range(index + step, centre, step):
        nxt = win.hop(k, name, pos + d, logz, ids)
        if nxt is None:
            break
        hop = np.where(np.isnan(nxt), hop, nxt)            # empty pixel: keep moving as before
        d = d + hop
    return d.astype(np.float32)


def compensate(frames: list, centre: int, flows: list | None = None,
               motion: MotionSpec | None = None) -> tuple[list, int]:
    """Every frame of a window moved onto frame `centre`, in the centre frame's data window; returns (frames, bins
    dropped in all). `motion`: the MotionSpec of the shot's channel map (default: ranad's canonical motion
    channels); `flows`: per frame, None or [H, W, 4] per-pixel flow over that frame's data window (see
    `_Window.vectors`).

    Frames whose data windows differ (auto-cropped renders) are compensated in display coordinates: every frame
    is placed, by its window's offset, into the union of the windows, moved there, and the moved neighbours are
    cut to the centre frame's window (bins outside it count as dropped)."""
    windows = [f.data_window for f in frames]
    target = windows[centre]
    if all(w == target for w in windows):
        return _compensate(frames, centre, flows, motion)
    union = (min(w[0] for w in windows), min(w[1] for w in windows), max(w[2] for w in windows),
             max(w[3] for w in windows))
    placed = [f if f.data_window == union else f.crop(union) for f in frames]
    placed_flows = None if flows is None else [None if fl is None else place_field(fl, w, union)
                                               for fl, w in zip(flows, windows)]
    moved, dropped = _compensate(placed, centre, placed_flows, motion)
    out = []
    for i, m in enumerate(moved):
        if i == centre:
            out.append(frames[centre])
            continue
        cut = m.crop(target)
        dropped += m.num_bins - cut.num_bins
        out.append(cut)
    return out, dropped


def place_field(field: np.ndarray, window, target) -> np.ndarray:
    """A per-pixel array [H, W, C] over data window `window` placed into data window `target` (display
    coordinates; NaN where `window` does not cover `target`)."""
    field = np.asarray(field, np.float32)
    x0, y0, x1, y1 = target
    out = np.full((y1 - y0 + 1, x1 - x0 + 1, field.shape[2]), np.nan, np.float32)
    ox0, oy0 = max(x0, window[0]), max(y0, window[1])
    ox1, oy1 = min(x1, window[2]), min(y1, window[3])
    if ox0 <= ox1 and oy0 <= oy1:
        out[oy0 - y0:oy1 - y0 + 1, ox0 - x0:ox1 - x0 + 1] = \
            field[oy0 - window[1]:oy1 - window[1] + 1, ox0 - window[0]:ox1 - window[0] + 1]
    return out


def _compensate(frames: list, centre: int, flows: list | None, motion: MotionSpec | None) -> tuple[list, int]:
    win = _Window(frames, motion, flows)
    out, dropped = [], 0
    for i, img in enumerate(frames):
        if i == centre:
            out.append(img)
            continue
        moved, lost = rebucket(img, displacement(frames, i, centre, flows, motion, win))
        out.append(moved)
        dropped += lost
    return out, dropped
