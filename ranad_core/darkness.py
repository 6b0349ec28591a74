"""Exactly black neighbourhoods stay exactly black.

A renderer writes exactly 0 where no sample of a pixel found light (glass over an empty background, the black
surroundings of a lit object). The reconstruction kernels are softmax averages over a neighbourhood, so such a
pixel next to lit ones gets a faint share of their light: 1e-5..1e-4 where a lit pixel holds 1e-3, invisible at
the frame's exposure but a glow many stops up, which is where HDR-FLIP and a compositor's grade look (on the
held-out glass family it made the default's flat FLIP worse than the noisy input's: runs/dark-s16).

One exactly black pixel is no evidence (a dark dot of a dim, noisy region: the denoiser must fill it in), a
black neighbourhood is, unless the region is sampled so sparsely that black windows come by chance. Every pixel of
a (2 radius + 1)^2 window exactly black in every colour channel the primary pass writes stays black, unless a
"speck" lies within SPECK_REACH pixels of it or of the window's centre: a lit pixel with at least SPECK_BLACK of
its 8 neighbours black, the mark of a dim region where few samples find light. (Windows' centres alone left the
black pixels next to lit ones glowing; without the speck test, 3x3 windows darkened dim regions at 4 spp by up
to 9% FLIP, with it by up to 3%: runs/dark-s16.) Those bins keep their noisy colour (0) in the beauty and in every
light group denoised through the cached kernels (their kernel becomes the identity, so the output stays linear in
the noisy values and light groups still sum to the beauty); their alpha and depth are denoised as any other
bin's. Windows are clipped to the data window.

Objects work the same way where the file has an object id channel: an object none of whose bins in the frame is
lit (at least HOLDOUT_MIN_BINS of them) stays black in every bin, wherever it is. That is a holdout matte (deep
holdouts are written with alpha and no colour, so that a composite cuts the object out) or an object no light
reaches; the kernels gave the bins of one object of the bundled example, held out, more colour on average than the
median lit bin has, which a composite shows as light where the holdout should cut (tests/test_darkness.py).
"""

from __future__ import annotations

import numpy as np

from .channels import ChannelMap, layer_parts
from .deep import DeepImage

DARK_RADIUS = 1    # 3x3 windows: wider ones keep less of the leak out, a single pixel keeps dark dots
SPECK_BLACK = 7    # a lit pixel with this many black neighbours (of 8) marks a sparsely sampled region
SPECK_REACH = 3    # no black window within this many pixels of a speck is trusted
LIT_BLOCK = 16384  # rows per block when finding lit bins
HOLDOUT_MIN_BINS = 16   # fewer all-black bins of one object may be a small dim one that no sample reached by chance


def _box_sum(mask: np.ndarray, radius: int) -> np.ndarray:
    """int16 [H, W]: how many True pixels lie in each pixel's (2 radius + 1)^2 window, clipped to the image
    (shifted adds, rows then columns: a few ms at 1080p; int16 holds the counts of windows up to radius 90)."""
    one = mask.astype(np.int16)
    rows = one.copy()
    for d in range(1, radius + 1):
        rows[d:] += one[:-d]
        rows[:-d] += one[d:]
    out = rows.copy()
    for d in range(1, radius + 1):
        out[:, d:] += rows[:, :-d]
        out[:, :-d] += rows[:, d:]
    return out


def _lit_bins(values: np.ndarray, cols: list) -> np.ndarray:
    """bool [N]: bins with a non-zero value in one of the columns, read in blocks of rows that stay in cache (a
    column gather over the whole [N, C] array cost 0.3 s at 1080p, the blocks 0.06 s)."""
    out = np.empty(len(values), bool)
    for i in range(0, len(values), LIT_BLOCK):
        out[i:i + LIT_BLOCK] = (values[i:i + LIT_BLOCK][:, cols] != 0).any(1)
    return out


def colour_channels(m: ChannelMap) -> list:
    """The colour channels the primary pass writes (denoise._assemble): the beauty, and with a diffuse/specular
    split every part of those two layers."""
    names = list(m.beauty)
    if m.split:
        for layer in ("diffuse", "specular"):
            for part in layer_parts(m.layers[layer]):
                names += [c for c in part if c not in names]
    return names


def holdout_bins(img: DeepImage, lit_bin: np.ndarray) -> np.ndarray | None:
    """bool [N]: the bins of objects (the object id channel) with at least HOLDOUT_MIN_BINS bins and none lit, or
    None (no id channel, no such object)."""
    from .exr.inspect import object_ids

    ids = object_ids(img)
    if ids is None:
        return None
    black_ids, counts = np.unique(ids[~lit_bin], return_counts=True)
    hold = black_ids[(counts >= HOLDOUT_MIN_BINS) & ~np.isin(black_ids, np.unique(ids[lit_bin]))]
    return np.isin(ids, hold) if hold.size else None


def dark_bins(img: DeepImage, m: ChannelMap, radius: int = DARK_RADIUS) -> np.ndarray | None:
    """bool [N] in the file's bin order: the bins that stay black (black windows and holdout objects, see the
    module's docstring), or None when radius is 0 or no bin qualifies. `img`: the noisy frame after the NaN/Inf
    policy."""
    if radius <= 0 or img.num_bins == 0:
        return None
    cols = [img.channel_index(c) for c in colour_channels(m)]
    lit_bin = _lit_bins(img.values, cols)
    pixel = img.pixel_index()
    lit = np.zeros(img.num_pixels, bool)
    lit[pixel[lit_bin]] = True
    lit = lit.reshape(img.height, img.width)
    black_neighbours = _box_sum(~lit, 1) - ~lit
    speck = lit & (black_neighbours >= SPECK_BLACK)
    calm = _box_sum(speck, SPECK_REACH) == 0
    centre = (_box_sum(lit, radius) == 0) & calm   # centres of black windows
    keep = (_box_sum(centre, radius) > 0) & calm     # every pixel of their windows
    dark = keep.reshape(-1)[pixel]
    held = holdout_bins(img, lit_bin)
    if held is not None:
        dark |= held
    return dark if dark.any() else None
