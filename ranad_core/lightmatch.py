"""Light matching: the denoised colour of each pixel times a gain close to 1 that brings the local light of ranad's
flattened image (a box mean of luminance) to that of the noisy render itself.

Why (runs/generalization-s29): a denoised pixel is a weighted average of noisy neighbours, and where the kernels
lean towards darker samples a region comes out slightly dark: on box-filtered held-out interiors ranad trailed flat
OIDN's HDR-FLIP by smooth low-frequency blotches and about 1% lost light (runs/generalization-s28, section 1). The
noisy render's mean over a wide box is an unbiased estimate of the true local light, so each pixel's gain is the
ratio of that mean to ranad's own (33x33 pixels), held within [1 / CLAMP, CLAMP]: the noise of the estimate, and its
fireflies, can move nothing by more than 2%. (Flat OIDN's light as the target, the first version, scored the same
within 0.2% in the held-out means and 0.4% worse in a bare grid; it is biased where OIDN is, in fog and through
Gaussian pixel filters, and on renders unlike OIDN's training data; study section 5.)

The gain is one number per pixel and multiplies every denoised bin of the pixel (the diffuse and specular layers
and the residual the model denoises with the diffuse; not the emission, which passes through). So every output
stays linear in the noisy values: `ranad aov` applies the same gain (the cache keeps it) and light groups still
sum to the beauty. A ratio of two luminances, it does not change when the render's exposure does; it is computed
on the whole assembled frame, so tiles agree.
"""

from __future__ import annotations

import numpy as np

from .channels import ALPHA, EMISSION, FLAT_NOISY
from .deep import DeepImage, transmittance
from .model.prior import LUMA

RADIUS = 16     # box half-width in pixels: a (2R + 1)^2 window
CLAMP = 1.02    # gains kept within [1 / CLAMP, CLAMP]


def box_mean(x: np.ndarray, r: int) -> np.ndarray:
    """Mean of x [H, W] over a (2r+1)^2 box, the box cut at the frame's edges (a summed-area table, float64)."""
    h, w = x.shape
    s = np.zeros((h + 1, w + 1))
    s[1:, 1:] = np.asarray(x, np.float64).cumsum(0).cumsum(1)
    y0, y1 = np.clip(np.arange(h) - r, 0, h), np.clip(np.arange(h) + r + 1, 0, h)
    x0, x1 = np.clip(np.arange(w) - r, 0, w), np.clip(np.arange(w) + r + 1, 0, w)
    tot = s[y1][:, x1] - s[y0][:, x1] - s[y1][:, x0] + s[y0][:, x0]
    return tot / ((y1 - y0)[:, None] * (x1 - x0)[None, :])


def pixel_gain(target: np.ndarray, current: np.ndarray, radius: int = RADIUS, clamp: float = CLAMP) -> np.ndarray:
    """float32 [H, W]: box_R(target) / box_R(current) held within [1 / clamp, clamp] (1 where the box holds no
    light); target and current are [H, W] luminances (negative values count as 0)."""
    t = box_mean(np.maximum(np.nan_to_num(target), 0), radius)
    c = box_mean(np.maximum(np.nan_to_num(current), 0), radius)
    g = np.divide(t, c, out=np.ones_like(t), where=(c > 0) & (t > 0))
    return np.clip(g, 1.0 / clamp, clamp).astype(np.float32)


def denoised_luminance(outs: dict) -> np.ndarray:
    """float64 [N]: luminance of the model's denoised colour per bin: diffuse (+ the residual it carries in columns
    3-5) + specular. Layer by layer, so that no [N, 3] float64 copy of a frame's bins is made."""
    luma = LUMA.astype(np.float32)
    d = outs["diffuse"]
    lum = (d[:, :3] @ luma).astype(np.float64)
    if d.shape[1] >= 6:
        lum += d[:, 3:6] @ luma
    if "specular" in outs:
        lum += outs["specular"] @ luma
    return lum


def flat_luminance(lum: np.ndarray, alpha: np.ndarray, offsets: np.ndarray, height: int, width: int) -> np.ndarray:
    """[H, W] the composite of premultiplied bins' luminances [N] front to back (bins in depth order per pixel)."""
    offsets = np.asarray(offsets, np.int64)
    counts = np.diff(offsets)
    pix = np.repeat(np.arange(len(counts)), counts)
    w = np.asarray(lum, np.float64) * transmittance(np.asarray(alpha).reshape(-1), offsets)
    return np.bincount(pix, weights=w, minlength=len(counts)).reshape(height, width)


def frame_gain(srt: DeepImage, outs: dict, radius: int = RADIUS, clamp: float = CLAMP) -> np.ndarray:
    """float32 [H * W]: the gain of every pixel of a denoised frame. `srt`: the frame as the model read it (bins in
    depth order, with the flat prior's channels, which include the pixel's flattened noisy beauty: prior.with_prior);
    `outs`: the model's outputs in that bin order (name -> [N, C]; the denoised alpha where there is one)."""
    h, w = srt.height, srt.width
    alpha = np.clip(outs["alpha"][:, 0], 0, 1) if "alpha" in outs else np.clip(srt.channel(ALPHA), 0, 1)
    lum = denoised_luminance(outs)
    if all(c in srt.channels for c in EMISSION):   # emission passes through the model, but it is light in the frame
        for name, weight in zip(EMISSION, LUMA):
            lum += weight * srt.channel(name)
    current = flat_luminance(lum, alpha, srt.offsets, h, w)
    has = np.diff(srt.offsets) > 0
    target = np.zeros(h * w)   # the flat noisy beauty is the same on every bin of a pixel: read it from the first
    rows = srt.offsets[:-1][has]
    target[has] = srt.values[np.ix_(rows, [srt.channels.index(c) for c in FLAT_NOISY])].astype(np.float64) @ LUMA
    return pixel_gain(target.reshape(h, w), current, radius, clamp).reshape(-1)


def bin_factors(gain: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """float32 [N, 1]: each bin's pixel gain."""
    return np.repeat(np.asarray(gain, np.float32).reshape(-1), np.diff(np.asarray(offsets, np.int64)))[:, None]


def apply(outs: dict, gain: np.ndarray, offsets: np.ndarray) -> None:
    """Multiplies the denoised colour layers of `outs` (diffuse with its residual, specular) by their pixels'
    gains, in place."""
    f = bin_factors(gain, offsets)
    for name in ("diffuse", "specular"):
        if name in outs:
            outs[name] *= f
