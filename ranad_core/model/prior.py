"""Frame-level inputs of the model: the exposure scale and the flat prior (issue 24).

- Exposure: radiance features are divided by one robust scale per frame (the median luminance of the frame's
  flattened noisy beauty over its covered pixels) before log1p, so the features, and with them the kernels, do not
  change when a render is brighter or darker; since every output is a softmax-weighted average of noisy values,
  scaling the input by k scales the output by exactly k. The scale is computed over the whole frame (tiles agree),
  like OIDN's auto-exposure.
- Flat prior: OIDN's denoised flattened beauty of each bin's pixel (with the flattened albedo/normal guides when
  the frame has them) and the pixel's flattened noisy beauty, copied onto every bin of the pixel as extra
  channels (names in channels.py). OIDN was trained on far more scenes than ranad can render; given to the model
  as features, it steers the kernels (which neighbours look like the clean image), while the outputs stay
  softmax-weighted combinations of the noisy values, so AOV reuse and sum-to-beauty stay exact.
"""

from __future__ import annotations

import contextlib
import contextvars
import warnings

import numpy as np

from ..channels import ALBEDO, DIFFUSE, EMISSION, FLAT_NOISY, NORMAL, PRIOR, PRIOR_NOAUX, RGB, SPECULAR
from ..baselines import composite_groups, oidn_run
from ..deep import DeepImage
from ..errors import RanadError

LUMA = np.array([0.2126, 0.7152, 0.0722], np.float64)
AUX = (ALBEDO, NORMAL)


def beauty(img: DeepImage, residual: np.ndarray | None = None) -> np.ndarray:
    """[N, 3] per-bin beauty of a canonical image: diffuse + specular + emission (+ the residual the split leaves
    out); a file in ranad synth's convention may be passed as is (its R, G, B are used)."""
    if all(c in img.channels for c in RGB):
        return img.columns(RGB).astype(np.float32)
    out = np.zeros((img.num_bins, 3), np.float32)
    for names in (DIFFUSE, SPECULAR, EMISSION):
        if names[0] in img.channels:
            out += img.columns(names)
    if residual is not None:
        out += residual
    return out


def exposure_scale(flat_rgb: np.ndarray) -> float:
    """The frame's exposure: median luminance of its covered pixels (those with positive luminance); 1 for a black
    frame. A median commutes with scaling, so a frame scaled by k has scale k times this one."""
    lum = np.asarray(flat_rgb, np.float64) @ LUMA
    lum = lum[np.isfinite(lum) & (lum > 0)]
    if lum.size == 0:
        return 1.0
    return float(np.median(lum))


# Where OIDN runs: "cpu", or "cuda" while a model on the GPU denoises (denoise_window sets it, so `ranad denoise
# --device cuda` runs the prior on the GPU too). pyoidn takes torch CUDA tensors and picks its CUDA device for them.
OIDN_DEVICE: contextvars.ContextVar[str] = contextvars.ContextVar("oidn_device", default="cpu")
_gpu_failed: list = []


@contextlib.contextmanager
def oidn_on(device_type: str):
    """Run the flat prior's OIDN on `device_type` ("cpu" or "cuda") inside the block."""
    token = OIDN_DEVICE.set(device_type)
    try:
        yield
    finally:
        OIDN_DEVICE.reset(token)


def _oidn(colour: np.ndarray, albedo: np.ndarray | None, normal: np.ndarray | None) -> np.ndarray:
    try:
        import pyoidn
    except ImportError as e:  # a core dependency; this only happens in a broken environment
        raise RanadError("the flat prior needs pyoidn (pip install pyoidn)", "pyoidn") from e
    aux = {}
    if albedo is not None:
        aux["albedo"] = albedo
        if normal is not None:
            aux["normal"] = normal
    if OIDN_DEVICE.get() == "cuda" and not _gpu_failed:
        import torch

        try:
            on = {k: torch.from_numpy(v).cuda() for k, v in aux.items()}
            out = pyoidn.denoise(torch.from_numpy(colour).cuda(), hdr=True, **on)
            return np.asarray(out.cpu().numpy(), np.float32)
        except Exception as e:  # noqa: BLE001 - a pyoidn without its CUDA device: the CPU gives the same prior
            _gpu_failed.append(e)
            warnings.warn(f"ranad: OIDN could not run on the GPU ({e}); the flat prior runs on the CPU",
                          RuntimeWarning, stacklevel=2)
    return released_oidn(pyoidn, colour, aux)


def released_oidn(pyoidn, colour: np.ndarray, aux: dict) -> np.ndarray:
    """OIDN (HDR) on the CPU with its device and filter released afterwards. pyoidn.denoise keeps them, with the
    filter's scratch memory, for the life of the process: about 1.2 GB for a 1080p frame, which would sit beside
    every tile of the frame (and of the shot) and count against --max-memory. Releasing costs about 0.1 s per
    frame; the result is bitwise pyoidn.denoise's."""
    return oidn_run(pyoidn, {"color": colour, **aux}, "on the flat prior", hdr=True)


def flat_images(srt: DeepImage, rgb: np.ndarray, guides: bool) -> tuple[np.ndarray, np.ndarray]:
    """(noisy flattened beauty [P, 3], OIDN's denoised one [P, 3]) of a sorted image with per-bin beauty `rgb`.
    OIDN sees the colour divided by the frame's exposure scale (so its output, too, scales with the input)."""
    h, w = srt.height, srt.width
    groups = [(np.maximum(np.nan_to_num(rgb, nan=0.0, posinf=0.0), 0), True)]
    aux = guides and all(c in srt.channels for names in AUX for c in names)
    if aux:
        groups += [(srt.columns(names), False) for names in AUX]
    flat, *flat_aux = composite_groups(srt, groups)
    if srt.num_bins == 0 or h * w == 0:
        return flat, flat.copy()
    s = exposure_scale(flat)
    img = lambda x: np.ascontiguousarray(x.reshape(h, w, 3), np.float32)  # noqa: E731
    albedo = normal = None
    if aux:
        albedo, normal = img(np.clip(flat_aux[0], 0, 1)), img(np.clip(flat_aux[1], -1, 1))
    den = _oidn(img(flat / s), albedo, normal).reshape(-1, 3) * s
    return flat, np.maximum(np.nan_to_num(den, nan=0.0, posinf=0.0), 0)


def with_prior(img: DeepImage, residual: np.ndarray | None = None, both: bool = False,
               presorted: bool = False) -> DeepImage:
    """`img` (any bin order) plus the per-bin channels of the flat prior and the flattened noisy beauty (channels.py
    PRIOR and FLAT_NOISY); `both` also adds the prior computed without guides (PRIOR_NOAUX, for training).
    `presorted`: the caller's image is already in depth order (DeepImage.sorted), so neither the sort (3 s at 4.7 M
    bins) nor the way back is needed; the result is the same."""
    srt, perm = (img, None) if presorted else img.sorted()
    rgb = beauty(img, residual)
    if perm is not None:
        rgb = rgb[perm]
    pix = srt.pixel_index()
    flat, den = flat_images(srt, rgb, guides=True)
    cols = [den[pix], flat[pix]]
    names = list(PRIOR) + list(FLAT_NOISY)
    if both:
        has_aux = all(c in srt.channels for names_ in AUX for c in names_)
        cols.append(flat_images(srt, rgb, guides=False)[1][pix] if has_aux else den[pix])
        names += list(PRIOR_NOAUX)
    extra = np.concatenate(cols, 1).astype(np.float32)
    from ..deep import unsort

    if perm is not None:
        extra = unsort(extra, perm)  # back to the image's own bin order
    types = {**img.channel_types, **{n: "float" for n in names}}
    return DeepImage(values=np.concatenate([img.values, extra], 1), offsets=img.offsets,
                     channels=list(img.channels) + names, ids=img.ids, data_window=img.data_window,
                     display_window=img.display_window, channel_types=types, header=img.header)


def frame_scale(img: DeepImage) -> float:
    """The exposure scale of an image that carries FLAT_NOISY channels (with_prior), from its pixels' flattened
    noisy beauty (each covered pixel counted once)."""
    if img.num_bins == 0:
        return 1.0
    starts = img.offsets[:-1][np.diff(img.offsets) > 0]
    flat = img.columns(FLAT_NOISY)[starts]
    return exposure_scale(flat)
