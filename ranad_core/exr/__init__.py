"""Deep EXR reading and writing: ``read_deep`` / ``write_deep``, plus the file-level facts ``ranad info`` shows.

Two paths, one result: the fast numpy codec (:mod:`.fast`) for deep scan-line and tiled parts with
NONE/RLE/ZIPS/ZIP, and OpenImageIO (:mod:`.oiio_io`) for anything else. OpenImageIO also validates every file
the fast path reads, so a file OpenImageIO rejects is never silently decoded by our own code. The I/O mode is
``auto`` (fast where possible), ``fast`` (fail instead of falling back) or ``oiio`` (always OpenImageIO).
"""

from __future__ import annotations

import os
from typing import Literal

from ..deep import DeepImage
from ..errors import RanadError
from ..fileutil import atomic_output
from . import fast, oiio_io
from .header import (ByteSource, ExrLayout, FileSource, as_source, check_part_size, deep_state_code,
                     read_source_layout)

IoMode = Literal["auto", "oiio", "fast"]
_io_mode: IoMode = "auto"

__all__ = ["read_deep", "read_part", "write_deep", "write_parts", "read_layout", "set_io_mode", "get_io_mode",
           "DeepImage", "ExrLayout"]


def set_io_mode(mode: IoMode) -> None:
    """Choose the deep I/O path process-wide (the CLI's global ``--io`` switch)."""
    global _io_mode
    if mode not in ("auto", "oiio", "fast"):
        raise ValueError(f"unknown I/O mode {mode!r}")
    _io_mode = mode


def get_io_mode() -> IoMode:
    return _io_mode


def read_layout(path: str | os.PathLike) -> tuple[ExrLayout, ByteSource]:
    """Parse the headers of an EXR file, reading only the bytes they take; returns the layout and the open file
    (a :class:`~.header.ByteSource` that :func:`read_part` reads chunks from as it needs them)."""
    path = os.fspath(path)
    src = FileSource(path)
    return read_source_layout(src), src


def read_header(path: str | os.PathLike, head_bytes: int = 1 << 16) -> ExrLayout:
    """The headers only, reading no more of the file than they take: cheap checks of a whole sequence (deep or
    not, data windows, channels) before any frame is processed."""
    with FileSource(os.fspath(path)) as src:
        return read_source_layout(src, head_bytes)


def resolve_part(layout: ExrLayout, part: int | str | None, path: str) -> int:
    """Index of the requested part: an index, a part name, or None for the first deep part."""
    n = len(layout.parts)
    if part is None:
        for i in range(n):
            if layout.part_is_deep(i):
                return i
        raise RanadError("not a deep image (flat EXR); ranad needs deep EXRs", path)
    if isinstance(part, str) and not part.lstrip("-").isdigit():
        for i, p in enumerate(layout.parts):
            if p.name == part:
                return i
        names = ", ".join(str(p.name) for p in layout.parts)
        raise RanadError(f"no part named {part!r} (parts: {names})", path)
    i = int(part)
    if not 0 <= i < n:
        raise RanadError(f"no part {i} (the file has {n})", path)
    if not layout.part_is_deep(i):
        raise RanadError(f"part {i} is not deep (flat EXR part)", path)
    return i


def read_deep(path: str | os.PathLike, part: int | str | None = None, channels: list[str] | None = None,
              io: IoMode | None = None) -> DeepImage:
    """Read one deep part of an EXR file into a DeepImage (bins in file order, header kept raw).

    ``part``: index or name (default: the first deep part); ``channels``: read only these (all by default).
    """
    path = os.fspath(path)
    layout, src = read_layout(path)
    with src:
        return read_part(path, layout, src, resolve_part(layout, part, path), channels, io)


def read_part(path: str, layout: ExrLayout, buf, index: int, channels: list[str] | None = None,
              io: IoMode | None = None) -> DeepImage:
    """Read deep part ``index`` of a file whose layout and source :func:`read_layout` returned (``buf`` may also
    be the file's bytes). The part's sizes are checked against the file before either reader touches it."""
    mode = io or _io_mode
    header = layout.parts[index]
    src = as_source(buf, path)
    check_part_size(layout, index, src.size, path)
    oiio_io.validate(path, index, header)
    if mode != "oiio":
        try:
            return fast.read_part(src, layout, index, path, channels)
        except fast.Unsupported as e:
            if mode == "fast":
                raise RanadError(f"the fast reader does not handle this file ({e}); use --io auto", path) from None
    return oiio_io.read_part(path, index, header, channels)


def write_deep(path: str | os.PathLike, image: DeepImage, compression: str | None = None, io: IoMode | None = None,
               state: str | None = None, tiles: tuple[int, int] | None | str = "keep",
               line_order: int | None = None) -> None:
    """Write ``image`` as a single-part deep EXR, atomically (temporary file, then rename).

    By default the part is stored as the header it was read with says (:func:`fast.layout_of`): its
    compression where OpenEXR allows it for deep data (none, rle, zips; anything else becomes zips), its tiles
    (a one-level deep tiled part) and its line order; an image without such a header gets ZIPS scan lines.
    ``compression`` ("none", "rle", "zips"), ``tiles`` ((width, height), or None for scan lines) and
    ``line_order`` (0 increasing, 1 decreasing, 2 random y) override it. ``state``: the deepImageState to record
    ("messy", "sorted", "non_overlapping", "tidy"); by default it is measured from the bins when the input had
    the attribute, and left out otherwise.
    """
    path = os.fspath(path)
    mode = io or _io_mode
    if compression is not None and compression not in fast.WRITE_COMPRESSIONS and mode != "oiio":
        raise RanadError(f"cannot write deep compression {compression!r} (use {', '.join(fast.WRITE_COMPRESSIONS)})",
                         path)
    layout = _part_layout(image, compression, tiles, line_order)
    code = _state_code(image, state)
    with atomic_output(path) as tmp:
        if mode == "oiio":
            oiio_io.write(tmp, image, layout.compression)
        else:
            with open(tmp, "wb") as f:
                fast.write_part(f, image, layout.compression, code, layout.tiles, layout.line_order)


def _part_layout(image: DeepImage, compression, tiles, line_order) -> fast.PartLayout:
    keep = fast.layout_of(image.header, compression)
    return fast.PartLayout(keep.compression, keep.tiles if tiles == "keep" else tiles,
                           keep.line_order if line_order is None else line_order)


def _state_code(image: DeepImage, state: str | None) -> int | None:
    if state is None and "deepImageState" in image.header:
        state = image.measured_state()
    return None if state is None else deep_state_code(state)


def check_copyable_parts(source: str | os.PathLike, layout: ExrLayout, replaced) -> None:
    """Refuse (RanadError) a multi-part ``source`` whose parts other than those in ``replaced`` could not be
    copied by :func:`write_parts`: checked before the work, so a corrupt part a run does not denoise fails it at
    once rather than after the denoising. Reads the offset tables and chunk headers only."""
    if not layout.multipart:
        return
    source = os.fspath(source)
    with FileSource(source) as src:
        for i in range(len(layout.parts)):
            if i not in replaced:
                fast.chunk_extents(src, layout, i, source)


def write_parts(path: str | os.PathLike, source: str | os.PathLike, replaced: dict[int, DeepImage],
                io: IoMode | None = None) -> None:
    """Write a copy of the EXR file ``source`` to ``path`` (atomically) in which each deep part ``i`` of
    ``replaced`` holds that image instead, stored as the source part was (compression, tiles, line order and
    attributes, :func:`write_deep`'s defaults), and every other part is copied byte for byte (its header
    attributes and its chunks). A single-part source gives a single-part file."""
    path, source = os.fspath(path), os.fspath(source)
    mode = io or _io_mode
    layout, src = read_layout(source)
    with src:
        for i in replaced:
            if not 0 <= i < len(layout.parts) or not layout.part_is_deep(i):
                raise RanadError(f"part {i} is not a deep part of the file", source)
        if not layout.multipart:
            if set(replaced) != {0}:
                raise RanadError("a single-part file has only part 0", source)
            write_deep(path, replaced[0], io=mode)
            return
        if mode == "oiio":
            raise RanadError("multi-part outputs are written by ranad's own writer; use --io auto", path)
        parts = []
        for i in range(len(layout.parts)):
            if i in replaced:
                img = replaced[i]
                parts.append(fast.encode_part(img, _part_layout(img, None, "keep", None), _state_code(img, None), i))
            else:
                parts.append(fast.raw_part(src, layout, i, source))
    deep = any(layout.part_is_deep(i) for i in range(len(layout.parts)))
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as f:
            fast.write_file(f, parts, multipart=True, deep=deep)
