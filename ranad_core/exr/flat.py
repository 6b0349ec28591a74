"""Flat (non-deep) image outputs for review: a flattened EXR, or an 8-bit PNG/JPEG preview.

A deep denoiser's real product is a deep EXR, but people judge results by looking at them: compositors
want a flat EXR they can drop into Nuke, supervisors want a PNG/JPEG they can open anywhere. Everything
is written through OpenImageIO (which knows all three formats) and always via
:func:`ranad_core.fileutil.atomic_output`, so a killed farm job never leaves a truncated image that
looks finished.

Conventions, matching OpenEXR's:

- Pixel arrays are float32 ``[H, W, C]`` covering the *data window* (``xmin, ymin, xmax, ymax``,
  inclusive, in display coordinates; the window may start anywhere, also at negative coordinates).
- Colour is *premultiplied* (associated) by alpha, as in every EXR a renderer writes.
- Values are scene-linear. The 8-bit previews are display-referred sRGB; the EXR keeps linear data.
"""

from __future__ import annotations

import os
from typing import Mapping, Sequence

import numpy as np
import OpenImageIO as oiio

from ..errors import RanadError
from ..fileutil import atomic_output, check_writable_target, free_bytes, not_a_file

__all__ = ["write_flat", "read_flat", "srgb_oetf", "PREVIEW_EXTENSIONS", "FLAT_EXTENSIONS"]

Window = tuple[int, int, int, int]

PREVIEW_EXTENSIONS = (".png", ".jpg", ".jpeg")
FLAT_EXTENSIONS = (".exr",) + PREVIEW_EXTENSIONS

_EXR_TYPES = {"half": oiio.HALF, "float": oiio.FLOAT}
_JPEG_QUALITY = 95  # previews are for judging noise: JPEG's own artefacts must not look like noise


def srgb_oetf(linear: np.ndarray) -> np.ndarray:
    """Linear light -> sRGB-encoded value (IEC 61966-2-1 piecewise curve), for values in [0, 1].

    Inputs are clamped to [0, 1] first (NaN becomes 0): a preview cannot show more than display white,
    and a NaN from a bad sample must not poison the 8-bit conversion.
    """
    x = np.clip(np.nan_to_num(np.asarray(linear, dtype=np.float32), nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055).astype(np.float32)


def _extension(path: str) -> str:
    ext = os.path.splitext(path)[1].lower()
    if ext not in FLAT_EXTENSIONS:
        raise RanadError(f"unsupported output format '{ext or os.path.basename(path)}' (use .exr, .png, .jpg)", path)
    return ext


def _check_window(window: Sequence[int], what: str) -> Window:
    xmin, ymin, xmax, ymax = (int(v) for v in window)
    if xmax < xmin or ymax < ymin:
        raise ValueError(f"{what} {tuple(window)} is empty (windows are inclusive: xmin, ymin, xmax, ymax)")
    return xmin, ymin, xmax, ymax


def _set_attributes(spec: oiio.ImageSpec, attributes: Mapping[str, object] | None) -> None:
    """Copy metadata (software version, model name, settings) into the header for traceability.

    Only str/int/float are accepted: they map to EXR string/int/float attributes everywhere, whereas
    other Python types would be silently mangled or dropped by some readers.
    """
    for name, value in (attributes or {}).items():
        if isinstance(value, bool):
            value = int(value)
        if not isinstance(value, (str, int, float)):
            raise TypeError(f"attribute {name!r}: only str, int and float values are supported, got {type(value).__name__}")
        spec.attribute(name, value)


def _write_image(tmp: str, spec: oiio.ImageSpec, data: np.ndarray, path: str | None = None) -> None:
    """Write ``data`` to ``tmp`` with OIIO, turning any failure into a RanadError with OIIO's message, naming
    ``path`` (the output the temporary becomes).

    The caller's ``atomic_output`` removes ``tmp`` when this raises, so a failed write leaves nothing. OIIO's PNG
    writer reports no error on a full disk (a truncated file came out, exit 0) and libjpeg ends the process on
    one, so the folder's free space is checked before a preview is written and the preview read back after.
    """
    path = path or tmp
    folder = os.path.dirname(os.path.abspath(tmp))
    preview = os.path.splitext(tmp)[1].lower() in PREVIEW_EXTENSIONS
    if preview:
        free = free_bytes(folder)
        if free is not None and free < data.size + (1 << 16):   # at most a byte a value, plus headers
            raise RanadError(f"cannot write (no space left on device: {free} bytes free)", path)
    def failed(message: str) -> RanadError:   # OIIO names the temporary and says only that the write failed
        full = free_bytes(folder) == 0
        return RanadError("cannot write (no space left on device)" if full else f"cannot write image: {message}", path)

    out = oiio.ImageOutput.create(tmp)
    if out is None:
        raise failed(oiio.geterror() or "no OpenImageIO writer for this format")
    try:
        if not out.open(tmp, spec):
            raise failed(out.geterror() or oiio.geterror())
        if not out.write_image(data):
            raise failed(out.geterror() or oiio.geterror())
    finally:
        closed = out.close()
    if not closed:
        raise failed(out.geterror() or oiio.geterror())
    if preview:
        inp = oiio.ImageInput.open(tmp)
        ok = inp is not None and inp.read_image(0, 0, 0, -1, oiio.UINT8) is not None
        if inp is not None:
            inp.close()
        if not ok:
            raise RanadError(f"cannot write image (it does not read back: {oiio.geterror() or 'truncated'}; "
                             "is the disk full?)", path)


def _find_channel(channels: Sequence[str], key: str) -> int | None:
    """Index of channel ``key`` ("R", "G", "B", "A", "Y"): the exact name first, else a layered name
    whose last part matches case-insensitively (``beauty.R``, ``r``)."""
    if key in channels:
        return list(channels).index(key)
    for i, name in enumerate(channels):
        if name.rsplit(".", 1)[-1].upper() == key:
            return i
    return None


def _preview(
    pixels: np.ndarray, channels: Sequence[str], data_window: Window, display_window: Window,
    exposure: float, keep_alpha: bool,
) -> tuple[np.ndarray, list[str]]:
    """The 8-bit sRGB image of the display window: ``(uint8 [H, W, C], channel names)``.

    Colour channels: R, G, B when present (a missing one of them is black); a single colour channel
    (or Y, or failing that the first non-alpha channel, e.g. a lone Z) gives a grey image. Colour is
    premultiplied in the EXR; a PNG with alpha stores *unpremultiplied* colour, so where alpha > 0
    colour is divided by alpha (alpha itself is neither exposed nor sRGB-encoded). A JPEG has no alpha:
    premultiplied colour is already the image composited over black, so alpha is simply dropped.
    Pixels of the display window outside the data window are 0 (black, transparent).
    """
    idx = {k: _find_channel(channels, k) for k in ("R", "G", "B", "A", "Y")}
    rgb = [idx[k] for k in ("R", "G", "B")]
    present = [i for i in rgb if i is not None]
    if len(present) >= 2:
        zero = np.zeros(pixels.shape[:2], np.float32)
        colour = np.stack([pixels[..., i] if i is not None else zero for i in rgb], axis=-1)
        names = ["R", "G", "B"]
    else:
        grey = present[0] if present else idx["Y"]
        if grey is None:
            others = [i for i in range(len(channels)) if i != idx["A"]]
            grey = others[0] if others else idx["A"]  # only alpha: show alpha itself as grey
        colour = pixels[..., grey : grey + 1]
        names = ["Y"]
    alpha = None
    if keep_alpha and idx["A"] is not None and not (names == ["Y"] and grey == idx["A"]):
        alpha = pixels[..., idx["A"]]
    colour = colour.astype(np.float32, copy=True)
    if alpha is not None:
        a = alpha[..., None]
        np.divide(colour, a, out=colour, where=a > 0)
    colour *= np.float32(2.0 ** float(exposure))
    planes = [srgb_oetf(colour)]
    if alpha is not None:
        planes.append(np.clip(np.nan_to_num(alpha, nan=0.0), 0.0, 1.0)[..., None].astype(np.float32))
        names = names + ["A"]
    img = np.concatenate(planes, axis=-1)
    img8 = np.rint(img * 255.0).astype(np.uint8)

    # Place the data window inside the display window, clipping what lies outside it.
    dx0, dy0, dx1, dy1 = display_window
    x0, y0, x1, y1 = data_window
    canvas = np.zeros((dy1 - dy0 + 1, dx1 - dx0 + 1, img8.shape[-1]), np.uint8)
    cx0, cy0, cx1, cy1 = max(x0, dx0), max(y0, dy0), min(x1, dx1), min(y1, dy1)
    if cx0 <= cx1 and cy0 <= cy1:
        canvas[cy0 - dy0 : cy1 - dy0 + 1, cx0 - dx0 : cx1 - dx0 + 1] = img8[cy0 - y0 : cy1 - y0 + 1, cx0 - x0 : cx1 - x0 + 1]
    return canvas, names


def write_flat(
    path: str | os.PathLike,
    pixels: np.ndarray,
    channels: Sequence[str],
    data_window: Sequence[int],
    display_window: Sequence[int] | None = None,
    dtype: str | Sequence[str] = "half",
    exposure: float = 0.0,
    attributes: Mapping[str, object] | None = None,
) -> None:
    """Write a flat image, choosing the format from the extension of ``path``.

    ``pixels`` is float32 ``[H, W, C]`` for ``data_window`` (inclusive ``xmin, ymin, xmax, ymax``);
    ``display_window`` defaults to the data window.

    - ``.exr``: the channels as named, each stored as ``dtype`` (``"half"`` or ``"float"``, or one per
      channel, e.g. float for Z), ZIP compressed, with the data and display windows kept, so the
      result lines up with the source in a compositor. ``exposure`` is *not* applied: an EXR is data
      for further work, and baking a viewing adjustment into it would silently change the pixels.
    - ``.png`` / ``.jpg`` / ``.jpeg``: an 8-bit sRGB preview of the display window (see
      :func:`_preview`), scaled by ``2 ** exposure`` before encoding.

    ``attributes`` (str/int/float values) go into the header. An unknown extension, an unwritable
    target or an OpenImageIO failure raises RanadError, and no file (not even a temporary) is left.
    """
    path = os.fspath(path)
    ext = _extension(path)
    check_writable_target(path)  # fail before any work
    pixels = np.ascontiguousarray(pixels, dtype=np.float32)
    channels = [str(c) for c in channels]
    if pixels.ndim != 3 or pixels.shape[2] != len(channels) or not channels:
        raise ValueError(f"pixels must be [H, W, {len(channels)}] for channels {channels}, got shape {pixels.shape}")
    dw = _check_window(data_window, "data window")
    fw = _check_window(display_window, "display window") if display_window is not None else dw
    if pixels.shape[:2] != (dw[3] - dw[1] + 1, dw[2] - dw[0] + 1):
        raise ValueError(f"pixels of shape {pixels.shape} do not fill data window {dw}")

    if ext == ".exr":
        types = [dtype] * len(channels) if isinstance(dtype, str) else list(dtype)
        if len(types) != len(channels) or any(t not in _EXR_TYPES for t in types):
            raise ValueError(f"dtype must be 'half' or 'float' (or one per channel), got {dtype!r}")
        spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], len(channels), _EXR_TYPES[types[0]])
        if len(set(types)) > 1:
            spec.channelformats = tuple(oiio.TypeDesc(_EXR_TYPES[t]) for t in types)
        spec.channelnames = tuple(channels)
        if "A" in channels:
            spec.alpha_channel = channels.index("A")
        if "Z" in channels:
            spec.z_channel = channels.index("Z")
        spec.x, spec.y = dw[0], dw[1]
        spec.full_x, spec.full_y = fw[0], fw[1]
        spec.full_width, spec.full_height = fw[2] - fw[0] + 1, fw[3] - fw[1] + 1
        spec.attribute("compression", "zip")
        data = pixels
    else:
        data, names = _preview(pixels, channels, dw, fw, exposure, keep_alpha=(ext == ".png"))
        spec = oiio.ImageSpec(data.shape[1], data.shape[0], data.shape[2], oiio.UINT8)
        spec.channelnames = tuple(names)
        if "A" in names:
            spec.alpha_channel = names.index("A")
            # We store unpremultiplied colour ourselves; without this OIIO would divide by alpha again.
            spec.attribute("oiio:UnassociatedAlpha", 1)
        spec.attribute("oiio:ColorSpace", "sRGB")
        if ext != ".png":
            spec.attribute("Compression", f"jpeg:{_JPEG_QUALITY}")
    _set_attributes(spec, attributes)

    with atomic_output(path) as tmp:
        _write_image(tmp, spec, data, os.fspath(path))


def read_flat(path: str | os.PathLike) -> tuple[np.ndarray, list[str], Window, Window]:
    """Read a flat image (first subimage): ``(float32 [H, W, C], channel names, data window, display window)``.

    Windows are inclusive ``(xmin, ymin, xmax, ymax)``. 8-bit files come back as value / 255, and PNG
    colour as stored (unpremultiplied: OIIO is told not to premultiply it), so tests see the file's
    actual values. Deep files and unreadable files raise RanadError.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise not_a_file(path)
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(path, config)
    if inp is None:
        raise RanadError(f"cannot read image: {oiio.geterror()}", path)
    try:
        spec = inp.spec()
        if spec.deep:
            raise RanadError("is a deep image, expected a flat one", path)
        data = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
        if data is None:
            raise RanadError(f"cannot read image: {inp.geterror() or oiio.geterror()}", path)
    finally:
        inp.close()
    data = np.ascontiguousarray(np.asarray(data, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels))
    dw = (spec.x, spec.y, spec.x + spec.width - 1, spec.y + spec.height - 1)
    fw = (spec.full_x, spec.full_y, spec.full_x + spec.full_width - 1, spec.full_y + spec.full_height - 1)
    return data, list(spec.channelnames), dw, fw
