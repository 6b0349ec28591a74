"""The OpenImageIO path for deep EXRs: header validation, fallback reader/writer, and test oracle.

OpenImageIO's Python binding moves deep samples one value at a time, so this path is slow (DESIGN.md:
~0.16 M samples/s); it serves files the fast codec does not handle and checks the fast codec in tests.
Pitfalls worked around here: channel order is changed by OpenImageIO (everything is mapped by name), and
``ImageBuf.get_pixels`` on deep images crashes (only ImageInput/DeepData are used).
"""

from __future__ import annotations

import numpy as np

from ..deep import DeepImage
from ..errors import RanadError
from .header import Attribute, PartHeader, max_samples_per_pixel

_TYPES = {"half": "half", "float": "float", "uint": "uint"}


def _oiio():
    import OpenImageIO as oiio  # imported lazily: it is heavy and only some commands need it

    return oiio


def _last_error(source=None) -> str:
    """OpenImageIO's last error message as one line (its text may not even be valid UTF-8 on hostile files)."""
    try:
        text = (source.geterror() if source is not None else _oiio().geterror()) or ""
    except Exception:  # noqa: BLE001 - e.g. UnicodeDecodeError from the binding
        return "unreadable error message"
    lines = [line.strip() for line in str(text).strip().splitlines() if line.strip()]
    return lines[-1][:300] if lines else "unknown error"


def _foreign(e: Exception, what: str, path: str) -> RanadError:
    """A RanadError for an exception the OpenImageIO binding raised (RuntimeError, ValueError, ...)."""
    first = (str(e).strip().splitlines() or [""])[0][:300]
    return RanadError(f"{what} ({type(e).__name__}: {first})", path)


def open_input(path: str):
    oiio = _oiio()
    try:
        inp = oiio.ImageInput.open(path)
    except Exception as e:  # noqa: BLE001 - the binding's exceptions become one-line user errors
        raise _foreign(e, "cannot be opened by OpenImageIO", path) from None
    if inp is None:
        raise RanadError(f"cannot be opened by OpenImageIO ({_last_error()})", path)
    return inp


def _deep_part_spec(inp, path: str, part_index: int):
    """Seek ``inp`` to the part and return its spec, or say why it is not a deep part OpenImageIO reads."""
    try:
        found = inp.seek_subimage(part_index, 0)
        spec = inp.spec() if found else None
    except Exception as e:  # noqa: BLE001
        raise _foreign(e, f"OpenImageIO cannot read part {part_index}", path) from None
    if not found:
        raise RanadError(f"OpenImageIO cannot find part {part_index} ({_last_error(inp)})", path)
    if not spec.deep:
        raise RanadError("not a deep image (flat EXR); ranad needs deep EXRs", path)
    return spec


def _formats(spec) -> list[str]:
    return [str(t) for t in (spec.channelformats or [spec.format] * spec.nchannels)]


def validate(path: str, part_index: int, part: PartHeader) -> None:
    """Ask OpenImageIO whether the part is a readable deep image with the channels our parser found."""
    inp = open_input(path)
    try:
        spec = _deep_part_spec(inp, path, part_index)
        ours = {c.name: c.type for c in part.channels}
        theirs = dict(zip(spec.channelnames, _formats(spec)))
    except RanadError:
        raise
    except Exception as e:  # noqa: BLE001
        raise _foreign(e, "OpenImageIO cannot read the header", path) from None
    finally:
        inp.close()
    if set(ours) != set(theirs) or any(theirs[n] != _TYPES.get(t) for n, t in ours.items()):
        raise RanadError(f"channel list disagrees with OpenImageIO ({sorted(ours)} vs {sorted(theirs)})", path)


def read_part(path: str, part_index: int, part: PartHeader, channels: list[str] | None = None) -> DeepImage:
    """Read one deep part sample by sample through OpenImageIO (slow, always available).

    The caller has checked the part's sizes against the file (:func:`~.header.check_part_size`); here every
    failure of the binding becomes a RanadError, and the sample counts OpenImageIO reports are held to the same
    per-pixel cap as the fast reader's before the output is allocated."""
    try:
        return _read_part(path, part_index, part, channels)
    except RanadError:
        raise
    except MemoryError:
        raise RanadError("OpenImageIO ran out of memory reading the deep data (corrupt sample counts?)",
                         path) from None
    except Exception as e:  # noqa: BLE001 - the binding's exceptions become one-line user errors
        raise _foreign(e, "OpenImageIO could not read the deep data", path) from None


def _read_part(path: str, part_index: int, part: PartHeader, channels: list[str] | None) -> DeepImage:
    inp = open_input(path)
    try:
        spec = _deep_part_spec(inp, path, part_index)
        dd = inp.read_native_deep_image(part_index, 0)
        if dd is None:
            raise RanadError(f"OpenImageIO could not read the deep data ({_last_error(inp)})", path)
    finally:
        inp.close()
    x0, y0, x1, y1 = part.data_window
    if (spec.x, spec.y, spec.width, spec.height) != (x0, y0, x1 - x0 + 1, y1 - y0 + 1):
        raise RanadError("data window disagrees with OpenImageIO", path)
    names = list(spec.channelnames)
    formats = _formats(spec)
    order = sorted(range(len(names)), key=lambda i: names[i].encode())
    if channels is not None:
        missing = [n for n in channels if n not in names]
        if missing:
            raise RanadError(f"missing channel(s) {', '.join(missing)}", path)
        order = [i for i in order if names[i] in channels]
    npix = spec.width * spec.height
    counts = np.array([dd.samples(p) for p in range(npix)], dtype=np.int64)
    cap = max_samples_per_pixel()
    if npix and int(counts.max()) > cap:
        p = int(np.argmax(counts))
        raise RanadError(f"pixel ({x0 + p % spec.width}, {y0 + p // spec.width}) has {int(counts.max())} samples, "
                         f"more than the limit of {cap} per pixel (set RANAD_MAX_SAMPLES_PER_PIXEL to raise it)", path)
    offsets = np.zeros(npix + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    value_idx = [i for i in order if formats[i] != "uint"]
    id_idx = [i for i in order if formats[i] == "uint"]
    values = np.empty((int(offsets[-1]), len(value_idx)), dtype=np.float32)
    ids = {names[i]: np.empty(int(offsets[-1]), dtype=np.uint32) for i in id_idx}
    for p in np.nonzero(counts)[0]:
        base = offsets[p]
        for s in range(counts[p]):
            for j, i in enumerate(value_idx):
                values[base + s, j] = dd.deep_value(int(p), i, s)
            for i in id_idx:
                ids[names[i]][base + s] = dd.deep_value_uint(int(p), i, s)
    dw = (spec.x, spec.y, spec.x + spec.width - 1, spec.y + spec.height - 1)
    disp = (spec.full_x, spec.full_y, spec.full_x + spec.full_width - 1, spec.full_y + spec.full_height - 1)
    return DeepImage(values=values, offsets=offsets, channels=[names[i] for i in value_idx], ids=ids,
                     data_window=dw, display_window=disp,
                     channel_types={names[i]: formats[i] for i in order}, header=dict(part.attrs))


def _set_attribute(spec, name: str, attr: Attribute) -> None:
    v = attr.value()
    if isinstance(v, str):
        spec.attribute(name, v)
    elif isinstance(v, float):
        spec.attribute(name, v)
    elif isinstance(v, int) and attr.type == "int":
        spec.attribute(name, v)


def write(path: str, image: DeepImage, compression: str = "zips") -> None:
    """Write through OpenImageIO (slow). Only string/int/float attributes survive this path."""
    oiio = _oiio()
    names = list(image.channels) + list(image.ids)
    types = [image.channel_types.get(n, "float") for n in image.channels] + ["uint"] * len(image.ids)
    spec = oiio.ImageSpec(image.width, image.height, len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    spec.channelformats = tuple(oiio.TypeDesc(t) for t in types)
    spec.x, spec.y = image.data_window[0], image.data_window[1]
    dx0, dy0, dx1, dy1 = image.display_window
    spec.full_x, spec.full_y, spec.full_width, spec.full_height = dx0, dy0, dx1 - dx0 + 1, dy1 - dy0 + 1
    spec.deep = True
    spec.attribute("compression", compression)
    for k, a in image.header.items():
        if k not in ("channels", "compression", "dataWindow", "displayWindow", "type", "chunkCount", "version",
                     "tiles", "deepImageState", "lineOrder"):
            _set_attribute(spec, k, a)
    out = oiio.ImageOutput.create(path)
    if out is None or not out.open(path, spec):
        raise RanadError(f"OpenImageIO cannot write ({oiio.geterror().strip() or (out and out.geterror())})", path)
    try:
        dd = oiio.DeepData()
        dd.init(image.num_pixels, len(names), spec.channelformats, spec.channelnames)
        counts = image.counts
        for p in np.nonzero(counts)[0]:
            dd.set_samples(int(p), int(counts[p]))
        nv = len(image.channels)
        id_cols = list(image.ids.values())
        for p in np.nonzero(counts)[0]:
            base = image.offsets[p]
            for s in range(counts[p]):
                for j in range(nv):
                    dd.set_deep_value(int(p), j, s, float(image.values[base + s, j]))
                for j, col in enumerate(id_cols):
                    dd.set_deep_value_uint(int(p), nv + j, s, int(col[base + s]))
        if not out.write_deep_image(dd):
            raise RanadError(f"OpenImageIO write failed ({out.geterror()})", path)
    finally:
        out.close()
