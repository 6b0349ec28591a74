"""Fast vectorised reader/writer for deep scan-line and deep tiled EXR parts.

The OpenImageIO/OpenEXR Python bindings move deep samples one value at a time (~0.16 M samples/s,
DESIGN.md); this codec reads whole chunks with zlib and numpy instead. Chunk layout (OpenEXR file layout,
"deep data"): a chunk header (line y, or tile x/y/level), the packed sizes, a sample-count table (int32,
cumulative within each row of the chunk) and the sample data (row by row; within a row channel by channel
in name order; within a channel every sample of every pixel of the row). zlib calls release the GIL, so
chunks are (de)compressed on a small thread pool.

Anything outside what is handled here raises :class:`Unsupported`, and the caller falls back to OpenImageIO;
inconsistencies in the file raise RanadError naming the chunk.
"""

from __future__ import annotations

import os
import struct
import zlib
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numpy as np

from ..deep import DeepImage
from ..errors import RanadError
from . import compression as codec
from .header import (LINES_PER_CHUNK, MAX_EXPANSION, VERSION_LONG_NAMES, VERSION_NONIMAGE, Attribute, ChannelInfo,
                     ExrLayout, as_source, check_part_size, encode_box2i, encode_chlist, encode_int, encode_string,
                     max_samples_per_pixel, offset_table_span, offsets_array, part_geometry, write_header, MAGIC,
                     STRUCTURAL, COMPRESSION_NAMES)

_DTYPES = {"half": np.dtype("<f2"), "float": np.dtype("<f4"), "uint": np.dtype("<u4")}
READ_COMPRESSIONS = (codec.NONE, codec.RLE, codec.ZIPS, codec.ZIP)
WRITE_COMPRESSIONS = {"none": codec.NONE, "zips": codec.ZIPS}
#: ZIP (16 lines per chunk) is valid EXR and read here, but OpenEXR 3.5 refuses it for deep parts, so only
#: tests write it (to exercise multi-line chunks); users get none/zips.
_ALL_WRITE_COMPRESSIONS = dict(WRITE_COMPRESSIONS, zip=codec.ZIP)


class Unsupported(Exception):
    """This file or request is valid EXR but outside the fast codec; use the OpenImageIO path."""


def _threads() -> int:
    return max(1, min(8, os.cpu_count() or 1))


class _Chunk(NamedTuple):
    """One chunk's place in the file, from its header (checked against the file before any payload is read)."""

    start: int
    table_pos: int
    packed_table: int
    data_pos: int
    packed_data: int
    unpacked_data: int


def _inflate(data: bytes, expected: int) -> bytes:
    """zlib-decode ``data`` to exactly ``expected`` bytes, never producing more (``max_length``)."""
    d = zlib.decompressobj()
    try:
        raw = d.decompress(data, expected)
        # the stream may hold exactly `expected` bytes and still need its end marker and checksum read
        while not d.eof and d.unconsumed_tail:
            if d.decompress(d.unconsumed_tail, 1):
                raise codec.CodecError(f"zip block decodes to more than {expected} bytes")
    except zlib.error as e:
        raise codec.CodecError(f"zlib: {e}") from None
    if len(raw) != expected:
        raise codec.CodecError(f"zip block decodes to {len(raw)} bytes, expected {expected}")
    if not d.eof:
        raise codec.CodecError("zlib: incomplete or truncated stream")
    return raw


def unpack(comp: int, data: bytes, expected: int) -> bytes:
    """Decode one packed block (sample-count table or sample data) into exactly ``expected`` bytes.

    ``expected`` is checked against what ``data`` can possibly hold before anything is allocated: a block can
    unpack to at most :data:`MAX_EXPANSION` times its size, so a claimed size beyond that is refused, and zlib
    is told to stop at ``expected`` (a decompression bomb cannot produce more).
    """
    if expected == 0:
        return b""
    if comp == codec.NONE or len(data) == expected:
        if len(data) != expected:
            raise codec.CodecError(f"uncompressed block has {len(data)} bytes, expected {expected}")
        return data
    if expected > MAX_EXPANSION[comp] * len(data):
        raise codec.CodecError(f"{len(data)} packed bytes cannot hold the {expected} bytes claimed")
    if comp in (codec.ZIPS, codec.ZIP):
        raw = np.frombuffer(_inflate(data, expected), dtype=np.uint8)
    elif comp == codec.RLE:
        raw = codec._rle_decode(data, expected)
    else:
        raise codec.CodecError(f"compression {comp} is not handled by the fast codec")
    return codec._unpredict_deinterleave(raw)


def read_part(buf, layout: ExrLayout, index: int, path: str,
              channels: list[str] | None = None) -> DeepImage:
    """Decode deep part ``index``; ``buf`` is a :class:`~.header.ByteSource` (read as needed) or the file's bytes.

    Streamed in three steps so that memory follows the image, not the file's claims: (1) every chunk header,
    checked against the file's length, the part's geometry, the compression's largest expansion and the other
    chunks (no overlaps); (2) the sample-count tables, checked (never decreasing, at most
    :func:`~.header.max_samples_per_pixel` per pixel, and matching each chunk's claimed data size) before the
    output arrays are allocated; (3) each chunk's samples, decoded and scattered into the output, one chunk per
    thread at a time.
    """
    src = as_source(buf, path)
    part = layout.parts[index]
    comp = part.compression
    if comp not in READ_COMPRESSIONS:
        raise Unsupported(f"compression {COMPRESSION_NAMES.get(comp, comp)}")
    chans = part.channels
    for c in chans:
        if c.type not in _DTYPES:
            raise RanadError(f"channel {c.name!r} has an unknown pixel type", path)
        if c.xsampling != 1 or c.ysampling != 1:
            raise Unsupported("sub-sampled channels")
    if not chans:
        raise RanadError("corrupt header (empty channel list)", path)
    chans = sorted(chans, key=lambda c: c.name.encode())
    if channels is not None:
        missing = [n for n in channels if n not in {c.name for c in chans}]
        if missing:
            raise RanadError(f"missing channel(s) {', '.join(missing)}", path)
    tiled = layout.part_is_tiled(index)
    geo = part_geometry(layout, index, path)
    if geo.level_mode != 0:
        raise Unsupported("multi-resolution deep tiles")
    check_part_size(layout, index, src.size, path)
    xmin, ymin, xmax, ymax = part.data_window
    width, height = geo.width, geo.height
    n_chunks = geo.n_chunks
    table_pos, count, chunks_begin = offset_table_span(layout, index, path)
    if count != n_chunks:
        raise RanadError(f"corrupt header (chunkCount {count}, expected {n_chunks})", path)
    starts = offsets_array(src, table_pos, n_chunks, path)
    chunks_begin = chunks_begin or table_pos + 8 * n_chunks
    multipart = layout.multipart
    head_fmt = ("<i" if multipart else "<") + ("4i" if tiled else "i") + "QQQ"
    head_size = struct.calcsize(head_fmt)
    ratio = MAX_EXPANSION[comp]
    row_size = sum(c.size for c in chans)

    def where(k: int) -> str:
        return f"tile {k}" if tiled else f"scan line {ymin + geo.chunk(k)[0]}"

    # (1) chunk headers
    heads: list[_Chunk] = []
    total_table = total_data = 0
    for k in range(n_chunks):
        r0, r1, c0, c1 = geo.chunk(k)
        start = int(starts[k])
        if start <= 0 or start + head_size > src.size:  # past the end (or >= 2^63), or 0: never written
            raise RanadError(f"truncated file ({where(k)} is missing)", path)
        if start < chunks_begin:
            raise RanadError(f"corrupt chunk offset table ({where(k)} points into the header)", path)
        fields = struct.unpack(head_fmt, src.read(start, head_size, f"{where(k)}'s header"))
        if multipart:
            if fields[0] != index:
                raise RanadError(f"corrupt chunk ({where(k)} belongs to part {fields[0]})", path)
            fields = fields[1:]
        if tiled:
            tx, ty, lx, ly = fields[:4]
            if (tx * geo.chunk_w, ty * geo.chunk_h, lx, ly) != (c0, r0, 0, 0):
                raise RanadError(f"corrupt chunk ({where(k)} has coordinates {tx},{ty})", path)
        elif fields[0] != ymin + r0:
            raise RanadError(f"corrupt chunk ({where(k)} says it starts at line {fields[0]})", path)
        packed_table, packed_data, unpacked_data = fields[-3:]
        p = start + head_size
        if p + packed_table + packed_data > src.size:
            raise RanadError(f"truncated file ({where(k)} is cut short)", path)
        table_bytes = (r1 - r0) * (c1 - c0) * 4
        if table_bytes > ratio * packed_table or unpacked_data > ratio * packed_data:
            raise RanadError(f"corrupt chunk ({where(k)}: its packed sizes {packed_table} and {packed_data} cannot "
                             f"hold {table_bytes} and {unpacked_data} bytes)", path)
        if unpacked_data % row_size:
            raise RanadError(f"corrupt chunk ({where(k)}: {unpacked_data} bytes of samples is not a whole number "
                             f"of {row_size}-byte samples)", path)
        heads.append(_Chunk(start, p, packed_table, p + packed_table, packed_data, unpacked_data))
        total_table += table_bytes
        total_data += unpacked_data
    spans = sorted((h.start, h.data_pos + h.packed_data, k) for k, h in enumerate(heads))
    for (_, end, k), (nxt, _, j) in zip(spans, spans[1:]):
        if nxt < end:
            raise RanadError(f"corrupt chunk offset table ({where(k)} and {where(j)} overlap)", path)

    # (2) sample-count tables: per-pixel counts, each table decoded and checked before anything of the image's
    # size is allocated (a header can claim a window its tables do not hold)
    cap = max_samples_per_pixel()
    chunk_counts = []
    for k, h in enumerate(heads):
        r0, r1, c0, c1 = geo.chunk(k)
        rows, cols = r1 - r0, c1 - c0
        try:
            table = unpack(comp, src.read(h.table_pos, h.packed_table, f"{where(k)}'s sample counts"), rows * cols * 4)
        except codec.CodecError as e:
            raise RanadError(f"corrupt chunk ({where(k)}: sample counts: {e})", path) from None
        cum = np.frombuffer(table, dtype="<i4").reshape(rows, cols).astype(np.int64)
        counts = np.diff(cum, axis=1, prepend=0)
        if np.any(counts < 0):
            raise RanadError(f"corrupt chunk ({where(k)}: sample counts decrease)", path)
        if counts.size and int(counts.max()) > cap:
            y, x = np.unravel_index(int(np.argmax(counts)), counts.shape)
            raise RanadError(f"{where(k)}: pixel ({xmin + c0 + x}, {ymin + r0 + y}) has {int(counts.max())} samples, "
                             f"more than the limit of {cap} per pixel (set RANAD_MAX_SAMPLES_PER_PIXEL to raise it)",
                             path)
        if int(counts.sum(dtype=np.int64)) * row_size != h.unpacked_data:
            raise RanadError(f"corrupt chunk ({where(k)}: {int(counts.sum(dtype=np.int64))} samples of {row_size} "
                             f"bytes, but {h.unpacked_data} bytes of sample data)", path)
        chunk_counts.append(counts.astype(np.int32))
    counts_img = np.empty((height, width), dtype=np.int32)
    for k in range(n_chunks):
        r0, r1, c0, c1 = geo.chunk(k)
        counts_img[r0:r1, c0:c1] = chunk_counts[k]
        chunk_counts[k] = None
    offsets = np.zeros(width * height + 1, dtype=np.int64)
    np.cumsum(counts_img.ravel(), out=offsets[1:])
    del counts_img
    n = int(offsets[-1])

    keep = [c for c in chans if channels is None or c.name in channels]
    value_names = [c.name for c in keep if c.type != "uint"]
    values = np.empty((n, len(value_names)), dtype=np.float32)
    ids = {c.name: np.empty(n, dtype=np.uint32) for c in keep if c.type == "uint"}
    runs = _channel_runs(chans, value_names)

    # (3) sample data, one chunk at a time per thread
    def scatter(k: int) -> None:
        """Decode one chunk and copy its rows into the ragged arrays: per row, one transposing copy per run."""
        r0, r1, c0, c1 = geo.chunk(k)
        h = heads[k]
        try:
            data = unpack(comp, src.read(h.data_pos, h.packed_data, f"{where(k)}'s samples"), h.unpacked_data)
        except codec.CodecError as e:
            raise RanadError(f"corrupt chunk ({where(k)}: {e})", path) from None
        p = 0
        for r in range(r0, r1):
            # a row of a chunk (a full scan line, or a tile row) is contiguous in the ragged layout
            dst = int(offsets[r * width + c0])
            m = int(offsets[r * width + c1]) - dst
            if m == 0:
                continue
            for dtype, size, names, col0 in runs:
                block = np.frombuffer(data, dtype=dtype, count=m * len(names), offset=p).reshape(len(names), m)
                if col0 is not None:
                    values[dst:dst + m, col0:col0 + len(names)] = block.T
                else:
                    for j, name in enumerate(names):
                        if name in ids:
                            ids[name][dst:dst + m] = block[j]
                p += m * size * len(names)

    if n:
        with ThreadPoolExecutor(_threads()) as pool:
            list(pool.map(scatter, [k for k, h in enumerate(heads) if h.unpacked_data]))
    return DeepImage(values=values, offsets=offsets, channels=value_names, ids=ids,
                     data_window=part.data_window, display_window=part.display_window,
                     channel_types={c.name: c.type for c in keep}, header=dict(part.attrs))


def _channel_runs(chans: list[ChannelInfo], value_names: list[str]):
    """Group the file's channels (name order) into runs that one numpy copy can move per row.

    A run is consecutive channels of one pixel type that land in consecutive columns of ``values``
    (``col0`` is the first column) or are all ids / all skipped (``col0`` None).
    """
    col = {name: j for j, name in enumerate(value_names)}
    runs: list[tuple[np.dtype, int, list[str], int | None]] = []
    for c in chans:
        j = col.get(c.name)
        if runs:
            dtype, size, names, col0 = runs[-1]
            prev_j = col.get(names[-1])
            same_kind = dtype == _DTYPES[c.type] and ((j is None and col0 is None) or
                                                     (j is not None and prev_j is not None and j == prev_j + 1))
            if same_kind:
                names.append(c.name)
                continue
        runs.append((_DTYPES[c.type], c.size, [c.name], j))
    return runs


# ---- writing -----------------------------------------------------------------------------------------
def build_header(image: DeepImage, comp: int, state: int | None) -> dict[str, Attribute]:
    """The input's attributes (passed through) plus the structural ones regenerated for what we write."""
    attrs = {k: v for k, v in image.header.items() if k not in STRUCTURAL and k != "lineOrder"}
    chans = [ChannelInfo(n, image.channel_types.get(n, "float")) for n in image.channels]
    chans += [ChannelInfo(n, "uint") for n in image.ids]
    attrs["channels"] = Attribute("chlist", encode_chlist(chans))
    attrs["compression"] = Attribute("compression", bytes([comp]))
    attrs["dataWindow"] = encode_box2i(image.data_window)
    attrs["displayWindow"] = encode_box2i(image.display_window)
    attrs["lineOrder"] = Attribute("lineOrder", bytes([0]))
    attrs.setdefault("pixelAspectRatio", Attribute("float", struct.pack("<f", 1.0)))
    attrs.setdefault("screenWindowCenter", Attribute("v2f", struct.pack("<2f", 0.0, 0.0)))
    attrs.setdefault("screenWindowWidth", Attribute("float", struct.pack("<f", 1.0)))
    attrs["type"] = encode_string("deepscanline")
    attrs["version"] = encode_int(1)
    attrs["chunkCount"] = encode_int(-(-image.height // LINES_PER_CHUNK[comp]))
    if "name" in image.header:
        attrs["name"] = image.header["name"]
    if state is not None:
        attrs["deepImageState"] = Attribute("deepImageState", bytes([state]))
    return dict(sorted(attrs.items()))


def write_part(f, image: DeepImage, compression: str = "zips", state: int | None = None) -> None:
    """Write ``image`` as a single-part deep scan-line file to the open binary file ``f``."""
    if compression not in _ALL_WRITE_COMPRESSIONS:
        raise Unsupported(f"writing compression {compression}")
    comp = _ALL_WRITE_COMPRESSIONS[compression]
    attrs = build_header(image, comp, state)
    long_names = any(len(k) > 31 or len(a.type) > 31 for k, a in attrs.items())
    long_names |= any(len(n) > 31 for n in list(image.channels) + list(image.ids))
    flags = VERSION_NONIMAGE | (VERSION_LONG_NAMES if long_names else 0)
    head = struct.pack("<ii", MAGIC, 2 | flags) + write_header(attrs)

    # channels in name order, grouped into runs that one transposing copy per row turns into file bytes
    names = sorted(list(image.channels) + list(image.ids), key=str.encode)
    infos = [ChannelInfo(n, "uint" if n in image.ids else image.channel_types.get(n, "float")) for n in names]
    runs = _channel_runs(infos, list(image.channels))
    w, h = image.width, image.height
    counts = image.counts.reshape(h, w)
    cum_rows = np.cumsum(counts, axis=1).astype("<i4")
    row_start = image.offsets[:-1:w] if w > 0 else np.zeros(h, np.int64)
    row_end = image.offsets[w::w]

    lpc = LINES_PER_CHUNK[comp]

    def encode(y0: int) -> bytes:
        y1 = min(h, y0 + lpc)
        rows = []
        for y in range(y0, y1):
            s0, s1 = int(row_start[y]), int(row_end[y])
            for dtype, _, run_names, col0 in runs:
                if col0 is not None:
                    block = image.values[s0:s1, col0:col0 + len(run_names)].T.astype(dtype)
                    rows.append(block.tobytes())
                else:
                    rows.extend(image.ids[n][s0:s1].astype(dtype).tobytes() for n in run_names)
        data = b"".join(rows)
        table = cum_rows[y0:y1].tobytes()
        pt, pd = codec.compress(comp, table), codec.compress(comp, data)
        return struct.pack("<iQQQ", image.data_window[1] + y0, len(pt), len(pd), len(data)) + pt + pd

    with ThreadPoolExecutor(_threads()) as pool:
        chunks = list(pool.map(encode, range(0, h, lpc)))
    pos = len(head) + 8 * len(chunks)
    table = np.empty(len(chunks), dtype="<u8")
    for k, c in enumerate(chunks):
        table[k] = pos
        pos += len(c)
    f.write(head)
    f.write(table.tobytes())
    for c in chunks:
        f.write(c)
