"""What studios use today, measured against in `ranad eval` (DESIGN.md, "Baselines"):

- flat OIDN: flatten the noisy deep image (with its albedo and normal) and denoise it with Intel Open Image
  Denoise (pyoidn). Best flat quality, but the deep layout is gone.
- flat OIDN with prefiltered guides (OIDN's documented highest-quality mode): the flattened albedo and normal
  denoised first by OIDN's own filters for them, then the beauty with `cleanAux`. At low spp a render's albedo and
  normal are noisy too (texture, edges, glass), and OIDN without prefiltering keeps their noise as detail: on
  box-filtered held-out interiors this mode scores 6% below plain OIDN's flat FLIP, on glass and layers 7-33%, in
  fog and on Gaussian-filtered interiors 0.5-4% above it (runs/generalization-s31). It costs three OIDN passes.
- OIDN then recolour (Nuke's DeepRecolor, Arnold's documented workflow): every bin of a pixel gets the flat
  denoised colour in proportion to its share of that pixel's composited colour, so the deep image flattens to
  exactly the OIDN image while foreground and background share one flat correction (FG leaks into BG).
"""

from __future__ import annotations

import numpy as np
import torch

from .deep import DeepImage, flatten_torch, unsort
from .errors import RanadError
from .channels import ALBEDO, ALPHA, NORMAL, RGB

EPS = 1e-6


def _composite(img: DeepImage, names, premultiplied: bool) -> np.ndarray:
    """[P, len(names)] front-to-back composite of sorted `img`; unpremultiplied channels (albedo, normal) are
    weighted by each bin's visible coverage T_i a_i and normalised by the pixel's alpha."""
    return composite_columns(img, img.columns(names), premultiplied)


def composite_columns(img: DeepImage, cols: np.ndarray, premultiplied: bool) -> np.ndarray:
    """`_composite` of per-bin columns [N, C] given as an array rather than channel names."""
    return composite_groups(img, [(cols, premultiplied)])[0]


def composite_groups(img: DeepImage, groups: list) -> list:
    """composite_columns of several (cols [N, C_i], premultiplied) groups in one pass over the bins: the
    transmittance, most of a composite's cost, is computed once for all of them. The C++ kernel where it is built
    (each group read where it lies, deterministic at any thread count), else flatten_torch (the differentiable
    composite training uses; the two agree to rounding, tests/test_deep.py)."""
    from .rana.extension import cpu_extension_or_none

    ext = cpu_extension_or_none()
    if ext is not None:
        f32 = lambda x: torch.from_numpy(np.ascontiguousarray(x, np.float32))   # noqa: E731
        outs = ext.composite_blocks([f32(cols) for cols, _ in groups], [bool(p) for _, p in groups],
                                    f32(img.channel(ALPHA)), torch.from_numpy(img.offsets.astype(np.int64)), EPS)
        return [o.numpy() for o in outs]
    a = img.channel(ALPHA)[:, None]
    vals = [cols if premultiplied else cols * a for cols, premultiplied in groups]
    width = sum(v.shape[1] for v in vals)
    out = flatten_torch(torch.from_numpy(np.concatenate([*vals, a], 1).astype(np.float32)),
                        torch.from_numpy(img.offsets), width).numpy()
    res, at = [], 0
    for cols, premultiplied in groups:
        part = out[:, at:at + cols.shape[1]]
        at += cols.shape[1]
        res.append(part if premultiplied else part / np.maximum(out[:, -1:], EPS))
    return res


def oidn_run(pyoidn, images: dict, what: str, **flags: bool) -> np.ndarray:
    """OIDN's RT filter on `images` (OIDN's image names -> [H, W, 3], the first one's shape the output's) with the
    boolean parameters `flags`, on a device and filter released afterwards (pyoidn.denoise keeps them, and the
    filter's scratch memory, for the life of the process). `what` finishes the error: "OIDN failed {what}: ..."."""
    images = {k: np.ascontiguousarray(v, np.float32) for k, v in images.items()}
    out = np.empty_like(next(iter(images.values())))
    with pyoidn.Device() as device:
        device.commit()
        with pyoidn.Filter(device, pyoidn.OIDN_FILTER_TYPE_RT) as flt:
            for name, image in (*images.items(), ("output", out)):
                flt.set_image(name, image, pyoidn.OIDN_FORMAT_FLOAT3)
            for name, value in flags.items():
                flt.set_bool(name, value)
            flt.commit()
            flt.execute()
        error = device.get_error()
    if error is not None:
        raise RanadError(f"OIDN failed {what}: {error}", None)
    return out


def prefiltered(pyoidn, name: str, image: np.ndarray) -> np.ndarray:
    """An auxiliary image ("albedo" or "normal", [H, W, 3]) denoised by OIDN's filter for it: the RT filter with
    only that image set (OIDN's prefiltering for `cleanAux`)."""
    return oidn_run(pyoidn, {name: image}, f"prefiltering the {name}")


def oidn_flat(noisy: DeepImage, clean_aux: bool = False) -> np.ndarray:
    """[H, W, 3]: the flattened noisy beauty denoised by OIDN (HDR), with flattened albedo and normal when the
    file has them; `clean_aux`: with those guides prefiltered by OIDN (`prefiltered`) and OIDN told so."""
    try:
        import pyoidn
    except ImportError as e:
        raise RanadError("the OIDN baseline needs pyoidn (pip install pyoidn)", "pyoidn") from e
    srt, _ = noisy.sorted()
    h, w = noisy.height, noisy.width
    shape = lambda x: np.ascontiguousarray(x.reshape(h, w, 3), np.float32)  # noqa: E731
    colour = shape(np.maximum(_composite(srt, RGB, True), 0))
    aux = {}
    if all(c in noisy.channels for c in ALBEDO):
        aux["albedo"] = shape(np.clip(_composite(srt, list(ALBEDO), False), 0, 1))
        if all(c in noisy.channels for c in NORMAL):
            aux["normal"] = shape(np.clip(_composite(srt, list(NORMAL), False), -1, 1))
    clean = clean_aux and bool(aux)
    if clean:
        aux = {k: prefiltered(pyoidn, k, v) for k, v in aux.items()}
    return np.asarray(pyoidn.denoise(colour, hdr=True, clean_aux=clean, **aux), np.float32)


def recolour(noisy: DeepImage, flat: np.ndarray) -> DeepImage:
    """`noisy` with its bins' R, G, B rescaled so that the pixel composites to `flat` [H, W, 3]: each bin keeps
    its share of the noisy composite (gain flat / noisy-composite per pixel and channel); where the noisy
    composite is black the colour is spread by visible coverage instead."""
    srt, perm = noisy.sorted()
    cols = [srt.channels.index(c) for c in RGB]
    target = flat.reshape(-1, 3).astype(np.float64)
    comp = _composite(srt, RGB, True).astype(np.float64)
    alpha_flat = _composite(srt, [ALPHA], True)[:, 0].astype(np.float64)
    pix = srt.pixel_index()
    vals = srt.values.copy()
    a = srt.channel(ALPHA).astype(np.float64)
    for j, c in enumerate(cols):
        f, d = comp[pix, j], target[pix, j]
        by_share = vals[:, c] * np.divide(d, f, out=np.zeros_like(d), where=np.abs(f) > EPS)
        by_alpha = d * np.divide(a, alpha_flat[pix], out=np.zeros_like(a), where=alpha_flat[pix] > EPS)
        vals[:, c] = np.where(np.abs(f) > EPS, by_share, by_alpha)
    return noisy.with_values(unsort(vals, perm))
