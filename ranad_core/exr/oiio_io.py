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
from .header import Attribute, PartHeader

_TYPES = {"half": "half", "float": "float", "uint": "uint"}


def _oiio():
    import OpenImageIO as oiio  # imported lazily: it is heavy and only some commands need it

    return oiio


def open_input(path: str):
    oiio = _oiio()
    inp = oiio.ImageInput.open(path)
    if inp is None:
        msg = oiio.geterror().strip().splitlines()
        raise RanadError(f"cannot be opened by OpenImageIO ({msg[-1] if msg else 'unknown error'})", path)
    return inp


def _deep_part_spec(inp, path: str, part_index: int):
    """Seek ``inp`` to the part and return its spec, or say why it is not a deep part OpenImageIO reads."""
    if not inp.seek_subimage(part_index, 0):
        raise RanadError(f"OpenImageIO cannot find part {part_index}", path)
    spec = inp.spec()
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
    finally:
        inp.close()
    ours = {c.name: c.type for c in part.channels}
    theirs = dict(zip(spec.channelnames, _formats(spec)))
    if set(ours) != set(theirs) or any(theirs[n] != _TYPES.get(t) for n, t in ours.items()):
        raise RanadError(f"channel list disagrees with OpenImageIO ({sorted(ours)} vs {sorted(theirs)})", path)


def read_part(path: str, part_index: int, part: PartHeader, channels: list[str] | None = None) -> DeepImage:
    """Read one deep part sample by sample through OpenImageIO (slow, always available)."""
    inp = open_input(path)
    try:
        spec = _deep_part_spec(inp, path, part_index)
        dd = inp.read_native_deep_image(part_index, 0)
        if dd is None:
            msg = inp.geterror().strip().splitlines()
            raise RanadError(f"OpenImageIO could not read the deep data ({msg[-1] if msg else 'error'})", path)
    finally:
        inp.close()
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
