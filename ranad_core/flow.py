"""Per-pixel flow from flat EXR sequences (`ranad denoise --flow PATTERN --flow-direction prev|next`).

Some renders carry no per-bin motion in the deep file; a flat EXR per frame holds the motion instead (a
renderer's flat motion AOV, or optical flow from a compositing package). Two of its channels are the motion of
every pixel towards the previous (`prev`) or next (`next`) frame, read with the same conventions as per-bin
motion (`--map motion_prev=...`): pixels per frame, x right, y down by default, converted with the explicit
`--motion-units`, `--fps`, `--shutter` and `--motion-y` options (a preset's conventions are for its deep
channels, not for flow files). The flow is placed into each deep frame's data window by display coordinates
(NaN where the flat file does not cover it), and motion compensation uses it where the deep frame has no
per-bin motion in that direction (motion.py): every bin of a pixel moves with its pixel.
"""

from __future__ import annotations

import numpy as np

from .channels import COMPONENTS, MotionSpec
from .deep import DeepImage
from .errors import RanadError

DIRECTIONS = ("prev", "next")


def flow_channels(names: list, wanted: tuple | None, path: str) -> tuple[str, str]:
    """The (x, y) channels of a flow file: `wanted` (--flow-channels), else the only pair of components
    (X/Y, x/y, R/G, r/g, u/v, U/V, with or without a common layer prefix) the file has."""
    if wanted:
        missing = [c for c in wanted if c not in names]
        if missing:
            raise RanadError(f"--flow-channels: no channel(s) {', '.join(missing)} (have {', '.join(names)})", path)
        return tuple(wanted)
    found = []
    prefixes = {n.rsplit(".", 1)[0] + "." if "." in n else "" for n in names}
    for prefix in sorted(prefixes):
        for cx, cy in COMPONENTS["xy"]:
            pair = (prefix + cx, prefix + cy)
            if all(c in names for c in pair) and pair not in found:
                found.append(pair)
    if len(found) != 1:
        why = "no" if not found else f"{len(found)} candidate"
        raise RanadError(f"{why} x/y channel pairs for the flow (have {', '.join(names)}); name them with "
                         "--flow-channels X,Y", path)
    return found[0]


def flow_spec(overrides: dict | None) -> MotionSpec:
    """The unit conversion of flow files: the explicit --motion-* options (overrides['motion']), else pixels per
    frame, y down."""
    conv = dict((overrides or {}).get("motion") or {})
    return MotionSpec(units=conv.get("units") or "pixels", fps=conv.get("fps"), shutter=conv.get("shutter") or 1.0,
                      y_up=conv.get("y") == "up")


def read_flow(path: str, img: DeepImage, direction: str, channels: tuple | None = None,
              overrides: dict | None = None) -> np.ndarray:
    """[H, W, 4] canonical per-pixel flow of the deep frame `img` (its data window) from the flat EXR at `path`:
    columns motion_prev.X/Y, motion_next.X/Y, the direction not given NaN."""
    from .exr.flat import read_flat
    from .motion import place_field

    if direction not in DIRECTIONS:
        raise RanadError(f"--flow-direction {direction!r}: use prev or next", path)
    data, names, dw, disp = read_flat(path)
    if disp != img.display_window:
        raise RanadError(f"display window {disp} differs from the deep frame's {img.display_window}", path)
    cx, cy = flow_channels(names, channels, path)
    xy = np.stack([data[..., names.index(cx)], data[..., names.index(cy)]], -1).astype(np.float64)
    xy = np.where(np.isfinite(xy), xy, 0.0) * np.asarray(flow_spec(overrides).scale(img))
    out = np.full(xy.shape[:2] + (4,), np.nan, np.float32)
    col = 0 if direction == "prev" else 2
    out[..., col:col + 2] = xy
    return place_field(out, dw, img.data_window)
