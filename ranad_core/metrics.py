"""Image-quality metrics and the deep-compositing tests of `ranad eval`.

Flat metrics compare flattened (composited) RGB images: SMAPE, DSSIM and HDR-FLIP. The deep metrics compare deep
images with the reference's bin layout: per-bin SMAPE, and two edits a compositor makes that a flat denoiser
cannot survive (paper Fig. 2):

- compositing: insert a semi-transparent coloured layer at a split depth (between foreground and background)
  and recolour every bin in front of it; flatten; compare with the same edit on the reference.
- depth separation: keep only the bins in front of the split depth, or only those behind it; flatten each;
  compare each with the reference's (SMAPE and DSSIM, the mean of the two slices; HDR-FLIP costs about a second
  per 128x128 image, so it is kept for the flat images and the compositing edit).

The split depth is the median depth of the reference's bins, shared by every method on a frame. The edits use the
reference's bin depths for every method (the layouts are identical: references are binned into the noisy bins),
so they measure how well colour and alpha stay separated between foreground and background; depth accuracy has
its own figure, the mean relative depth error per bin (z_rel).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from .deep import DeepImage
from .channels import ALPHA, DEPTH, DEPTH_BACK, DEPTHS, RGB

INSERT_COLOUR = (0.08, 0.25, 0.6)    # premultiplied colour of the inserted layer
INSERT_ALPHA = 0.5
RECOLOUR_GAIN = (1.6, 0.8, 0.5)      # applied to the foreground bins


def tonemap(rgb):
    """HDR -> [0, 1): x / (1 + x), so highlights do not dominate and darks keep their detail (numpy or torch)."""
    x = rgb.clamp(min=0) if isinstance(rgb, torch.Tensor) else np.maximum(rgb, 0)
    return x / (1 + x)


def _gaussian(size: int = 7, sigma: float = 1.5) -> torch.Tensor:
    x = torch.arange(size, dtype=torch.float32) - (size - 1) / 2
    g = torch.exp(-x * x / (2 * sigma * sigma))
    return g / g.sum()


def ssim(a: torch.Tensor, b: torch.Tensor, data_range: float = 1.0) -> torch.Tensor:
    """Mean SSIM of two [C, H, W] tensors (Gaussian window 7x7, sigma 1.5, borders reflected); differentiable."""
    c = a.shape[0]
    g = _gaussian().to(a)
    win = (g[:, None] * g[None, :]).expand(c, 1, -1, -1)
    pad = win.shape[-1] // 2

    def blur(x):
        mode = "reflect" if min(x.shape[1:]) > pad else "replicate"
        return F.conv2d(F.pad(x[None], (pad,) * 4, mode=mode), win, groups=c)[0]

    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    ma, mb = blur(a), blur(b)
    va, vb, cov = blur(a * a) - ma * ma, blur(b * b) - mb * mb, blur(a * b) - ma * mb
    s = ((2 * ma * mb + c1) * (2 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2))
    return s.mean()


def smape(ref: np.ndarray, test: np.ndarray, eps: float = 1e-2) -> float:
    """Mean |test - ref| / (|test| + |ref| + eps)."""
    ref, test = np.asarray(ref, np.float64), np.asarray(test, np.float64)
    return float(np.mean(np.abs(test - ref) / (np.abs(test) + np.abs(ref) + eps))) if ref.size else 0.0


def dssim(ref: np.ndarray, test: np.ndarray) -> float:
    """(1 - SSIM) / 2 of two [H, W, 3] HDR images, tone-mapped by :func:`tonemap`."""
    t = lambda x: torch.from_numpy(tonemap(np.ascontiguousarray(x, np.float32))).permute(2, 0, 1)  # noqa: E731
    return float((1 - ssim(t(ref), t(test))) / 2)


def flip(ref: np.ndarray, test: np.ndarray) -> float:
    """Mean HDR-FLIP (NVIDIA's flip-evaluator) of two [H, W, 3] linear HDR images (negatives clamped to 0).

    The evaluator picks its exposure range from the reference; an all-black reference has no range, so two
    black images score 0 and anything else against black scores FLIP against a reference lifted by 1e-6."""
    import flip_evaluator

    ref = np.ascontiguousarray(np.maximum(np.nan_to_num(ref), 0), np.float32)
    test = np.ascontiguousarray(np.maximum(np.nan_to_num(test), 0), np.float32)
    if ref.max() <= 0:
        if test.max() <= 0:
            return 0.0
        ref = ref + 1e-6
    return float(flip_evaluator.evaluate(ref, test, "HDR", applyMagma=False)[1])


def light(ref: np.ndarray, test: np.ndarray) -> float:
    """The light a flat image holds over the reference's: the sum of its Rec. 709 luminance over the reference's
    (NaN for a black reference). A denoiser that dims fireflies and caustic speckles instead of spreading them
    scores below 1 where FLIP may still improve (runs/generalization-s25, section 4)."""
    from .model.prior import LUMA   # the luminance the exposure scale uses

    r, t = (float((np.nan_to_num(np.asarray(x, np.float64)) @ LUMA).sum()) for x in (ref, test))
    return t / r if r > 0 else float("nan")


def flat_scores(ref: np.ndarray, test: np.ndarray) -> dict:
    return {"smape": smape(ref, test), "dssim": dssim(ref, test), "flip": flip(ref, test)}


def beauty(img: DeepImage) -> DeepImage:
    """The beauty part used by the edits: R, G, B, A, Z (and ZBack), ids dropped."""
    names = [c for c in (*RGB, ALPHA, DEPTH, DEPTH_BACK) if c in img.channels]
    out = img.select(names)
    out.ids = {}
    return out


def flat_rgb(img: DeepImage) -> np.ndarray:
    """[H, W, 3] composited beauty."""
    b = beauty(img)
    flat = b.flatten()
    return flat[..., [b.channels.index(c) for c in RGB]]


def bin_smape(ref: DeepImage, test: DeepImage) -> float:
    """SMAPE over the RGB of every bin (test must have the reference's bin layout)."""
    if not np.array_equal(ref.offsets, test.offsets):
        raise ValueError("bin_smape needs identical bin layouts")
    cols = lambda img: img.values[:, [img.channels.index(c) for c in RGB]]  # noqa: E731
    return smape(cols(ref), cols(test))


def split_depth(ref: DeepImage) -> float:
    """The median depth of the reference's bins: the split of the compositing and separation tests."""
    z = ref.channel(DEPTH)
    return float(np.median(z)) if z.size else 0.0


def with_depths_of(img: DeepImage, ref: DeepImage) -> DeepImage:
    """`img` with the reference's Z/ZBack (identical bin layouts required)."""
    if not np.array_equal(img.offsets, ref.offsets):
        raise ValueError("the deep scores need the reference's bin layout")
    vals = img.values.copy()
    for c in DEPTHS:
        if c in img.channels and c in ref.channels:
            vals[:, img.channels.index(c)] = ref.channel(c)
    return img.with_values(vals)


def z_rel(ref: DeepImage, test: DeepImage) -> float:
    """Mean relative depth error |Z - Zref| / Zref over the bins."""
    zr, zt = ref.channel(DEPTH).astype(np.float64), test.channel(DEPTH).astype(np.float64)
    return float(np.mean(np.abs(zt - zr) / np.maximum(np.abs(zr), 1e-6))) if zr.size else 0.0


def composite_edit(img: DeepImage, z_split: float) -> np.ndarray:
    """[H, W, 3]: foreground bins (Z < z_split) recoloured, a semi-transparent layer inserted at z_split."""
    b = beauty(img)
    vals = b.values.copy()
    fg = vals[:, b.channels.index(DEPTH)] < z_split
    for i, c in enumerate(RGB):
        vals[fg, b.channels.index(c)] *= RECOLOUR_GAIN[i]
    b = b.with_values(vals)
    p = b.num_pixels
    layer = np.zeros((p, len(b.channels)), np.float32)
    for i, c in enumerate(RGB):
        layer[:, b.channels.index(c)] = INSERT_COLOUR[i]
    layer[:, b.channels.index(ALPHA)] = INSERT_ALPHA
    for c in DEPTHS:
        if c in b.channels:
            layer[:, b.channels.index(c)] = z_split
    plane = DeepImage(values=layer, offsets=np.arange(p + 1), channels=b.channels, data_window=b.data_window,
                      display_window=b.display_window, channel_types=dict(b.channel_types))
    edited = b.merge(plane)
    flat = edited.flatten()
    return flat[..., [edited.channels.index(c) for c in RGB]]


def depth_slices(img: DeepImage, z_split: float) -> tuple[np.ndarray, np.ndarray]:
    """([H, W, 3] front, [H, W, 3] back): the bins in front of / behind z_split, each flattened alone."""
    b = beauty(img)
    z = b.channel(DEPTH)
    return flat_rgb(b.keep(z < z_split)), flat_rgb(b.keep(z >= z_split))


def deep_scores(ref: DeepImage, test: DeepImage, z_split: float | None = None) -> dict:
    """Per-bin SMAPE, the compositing edit and the depth separation of `test` against `ref` (FLIP and SMAPE)."""
    z = split_depth(ref) if z_split is None else z_split
    zt = z_rel(ref, test)
    test = with_depths_of(test, ref)
    ce_ref, ce_test = composite_edit(ref, z), composite_edit(test, z)
    (f_ref, b_ref), (f_test, b_test) = depth_slices(ref, z), depth_slices(test, z)
    return {"bin_smape": bin_smape(ref, test), "z_rel": zt,
            "comp_flip": flip(ce_ref, ce_test), "comp_smape": smape(ce_ref, ce_test),
            "sep_smape": (smape(f_ref, f_test) + smape(b_ref, b_test)) / 2,
            "sep_dssim": (dssim(f_ref, f_test) + dssim(b_ref, b_test)) / 2}


def temporal_error(outputs: list, references: list) -> float:
    """Mean over consecutive frames of |(o[t+1] - o[t]) - (r[t+1] - r[t])| on tone-mapped [H, W, 3] images:
    flicker the reference does not have (0 for a perfect sequence; a static error does not count)."""
    if len(outputs) < 2:
        return float("nan")
    errs = []
    for t in range(len(outputs) - 1):
        do = tonemap(outputs[t + 1]).astype(np.float64) - tonemap(outputs[t])
        dr = tonemap(references[t + 1]).astype(np.float64) - tonemap(references[t])
        errs.append(np.abs(do - dr).mean())
    return float(np.mean(errs))


def reference_improvement(noisy: DeepImage, denoised: DeepImage, reference: DeepImage) -> tuple[float, float]:
    """(SMAPE of the flattened noisy frame, of the flattened denoised frame) against the flattened reference:
    what `ranad denoise --reference` reports per frame."""
    flat_ref = flat_rgb(reference)
    return smape(flat_ref, flat_rgb(noisy)), smape(flat_ref, flat_rgb(denoised))
