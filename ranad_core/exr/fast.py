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
                     STRUCTURAL, COMPRESSION_NAMES, VERSION_MULTIPART, PartGeometry)

_DTYPES = {"half": np.dtype("<f2"), "float": np.dtype("<f4"), "uint": np.dtype("<u4")}
READ_COMPRESSIONS = (codec.NONE, codec.RLE, codec.ZIPS, codec.ZIP)
WRITE_COMPRESSIONS = {"none": codec.NONE, "rle": codec.RLE, "zips": codec.ZIPS}
#: ZIP (16 lines per chunk) is valid EXR and read here, but OpenEXR 3.5 refuses it for deep parts ("Invalid
#: compression for deep data"), so only tests write it (to exercise multi-line chunks); users get none/rle/zips.
_ALL_WRITE_COMPRESSIONS = dict(WRITE_COMPRESSIONS, zip=codec.ZIP)


class Unsupported(Exception):
    """This file or request is valid EXR but outside the fast codec; use the OpenImageIO path."""


def _threads() -> int:
    return max(1, min(8, os.cpu_count() or 1))


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

    # (1) chunk headers: first what the offsets alone show (each chunk needs at least its header's bytes, and
    # chunks do not share bytes), then each header, checked before its sizes are used
    ordered = np.sort(starts)
    if n_chunks and (ordered[0] <= 0 or ordered[-1] + head_size > src.size):
        k = int(np.flatnonzero((starts <= 0) | (starts + head_size > src.size))[0])
        raise RanadError(f"truncated file ({where(k)} is missing)", path)  # past the end, >= 2^63, or 0
    if n_chunks and ordered[0] < chunks_begin:
        raise RanadError(f"corrupt chunk offset table ({where(int(np.argmin(starts)))} points into the header)", path)
    if n_chunks > 1 and np.any(np.diff(ordered) < head_size):
        raise RanadError("corrupt chunk offset table (chunks overlap)", path)
    heads = np.empty((n_chunks, 4), dtype=np.int64)  # start of the table, packed table, packed data, unpacked data
    for k in range(n_chunks):
        r0, r1, c0, c1 = geo.chunk(k)
        start = int(starts[k])
        fields = struct.unpack(head_fmt, src.read(start, head_size, "a chunk header"))
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
        heads[k] = (p, packed_table, packed_data, unpacked_data)
    spans = sorted(zip(starts.tolist(), (heads[:, 0] + heads[:, 1] + heads[:, 2]).tolist(), range(n_chunks)))
    for (_, end, k), (nxt, _, j) in zip(spans, spans[1:]):
        if nxt < end:
            raise RanadError(f"corrupt chunk offset table ({where(k)} and {where(j)} overlap)", path)

    # (2) sample-count tables: per-pixel counts, each table decoded and checked before anything of the image's
    # size is allocated (a header can claim a window its tables do not hold)
    cap = max_samples_per_pixel()
    chunk_counts = []
    for k in range(n_chunks):
        r0, r1, c0, c1 = geo.chunk(k)
        rows, cols = r1 - r0, c1 - c0
        table_pos, packed_table, _, unpacked_data = (int(v) for v in heads[k])
        want = rows * cols * 4
        if comp == codec.NONE and geo.tiled and packed_table == geo.chunk_w * geo.chunk_h * 4 > want:
            # OpenEXR stores an uncompressed edge tile's table at the full tile's size, its rows x cols counts
            # first (what OpenEXR and OpenImageIO read back); the rest is not part of the image
            packed_table = want
        try:
            table = unpack(comp, src.read(table_pos, packed_table, f"{where(k)}'s sample counts"), want)
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
        if int(counts.sum(dtype=np.int64)) * row_size != unpacked_data:
            raise RanadError(f"corrupt chunk ({where(k)}: {int(counts.sum(dtype=np.int64))} samples of {row_size} "
                             f"bytes, but {unpacked_data} bytes of sample data)", path)
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
        table_pos, packed_table, packed_data, unpacked_data = (int(v) for v in heads[k])
        try:
            data = unpack(comp, src.read(table_pos + packed_table, packed_data, f"{where(k)}'s samples"), unpacked_data)
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
            list(pool.map(scatter, np.flatnonzero(heads[:, 3]).tolist()))
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
#: line orders (the lineOrder attribute's byte): the order chunks are stored in, not their offset-table order
INCREASING_Y, DECREASING_Y, RANDOM_Y = 0, 1, 2


class PartLayout(NamedTuple):
    """How a deep part is stored: its compression (a WRITE_COMPRESSIONS name), tile size (None: scan lines;
    one resolution level) and line order (the order its chunks are stored in)."""

    compression: str = "zips"
    tiles: tuple[int, int] | None = None
    line_order: int = INCREASING_Y


def layout_of(header: dict, compression: str | None = None) -> PartLayout:
    """The layout a part with the attributes ``header`` is written with: its compression where OpenEXR allows
    it for deep data (none, rle, zips; OpenEXR refuses ZIP for deep parts, any other code becomes zips), its
    tiling (a one-level deep tiled part keeps its tile size) and its line order (random y only for tiles).
    ``compression`` overrides the header's."""
    def get(name):
        a = header.get(name)
        return None if a is None else a.value()

    if compression is None:
        code = get("compression")
        compression = next((n for n, c in WRITE_COMPRESSIONS.items() if c == code), "zips")
    tiles = None
    desc = get("tiles")
    if str(get("type") or "").endswith("tile") and isinstance(desc, tuple) and desc[2] == 0:
        tiles = (int(desc[0]), int(desc[1]))
    order = get("lineOrder")
    order = order if order in (INCREASING_Y, DECREASING_Y, RANDOM_Y) else INCREASING_Y
    if order == RANDOM_Y and tiles is None:
        order = INCREASING_Y
    return PartLayout(compression, tiles, order)


def _geometry(image: DeepImage, comp: int, tiles) -> PartGeometry:
    if tiles is not None:
        return PartGeometry(image.width, image.height, True, int(tiles[0]), int(tiles[1]))
    return PartGeometry(image.width, image.height, False, image.width, LINES_PER_CHUNK[comp])


def build_header(image: DeepImage, comp: int, state: int | None, tiles=None, line_order: int = INCREASING_Y,
                 n_chunks: int | None = None) -> dict[str, Attribute]:
    """The input's attributes (passed through) plus the structural ones regenerated for what we write."""
    attrs = {k: v for k, v in image.header.items() if k not in STRUCTURAL and k != "lineOrder"}
    chans = [ChannelInfo(n, image.channel_types.get(n, "float")) for n in image.channels]
    chans += [ChannelInfo(n, "uint") for n in image.ids]
    attrs["channels"] = Attribute("chlist", encode_chlist(chans))
    attrs["compression"] = Attribute("compression", bytes([comp]))
    attrs["dataWindow"] = encode_box2i(image.data_window)
    attrs["displayWindow"] = encode_box2i(image.display_window)
    attrs["lineOrder"] = Attribute("lineOrder", bytes([line_order]))
    attrs.setdefault("pixelAspectRatio", Attribute("float", struct.pack("<f", 1.0)))
    attrs.setdefault("screenWindowCenter", Attribute("v2f", struct.pack("<2f", 0.0, 0.0)))
    attrs.setdefault("screenWindowWidth", Attribute("float", struct.pack("<f", 1.0)))
    attrs["type"] = encode_string("deeptile" if tiles is not None else "deepscanline")
    if tiles is not None:
        attrs["tiles"] = Attribute("tiledesc", struct.pack("<IIB", int(tiles[0]), int(tiles[1]), 0))
    attrs["version"] = encode_int(1)
    if n_chunks is None:
        n_chunks = _geometry(image, comp, tiles).n_chunks
    attrs["chunkCount"] = encode_int(n_chunks)
    if "name" in image.header:
        attrs["name"] = image.header["name"]
    if state is not None:
        attrs["deepImageState"] = Attribute("deepImageState", bytes([state]))
    return dict(sorted(attrs.items()))


class EncodedPart(NamedTuple):
    """One part ready to be written: its attributes, its chunks (offset-table order, each with its chunk
    header) and the order they are stored in."""

    attrs: dict
    chunks: list
    order: list


def _store_order(geo: PartGeometry, line_order: int) -> list[int]:
    n = geo.n_chunks
    if line_order != DECREASING_Y:
        return list(range(n))
    rows = [list(range(r * geo.chunks_x, (r + 1) * geo.chunks_x)) for r in range(geo.chunks_y)]
    return [k for row in reversed(rows) for k in row]


def encode_part(image: DeepImage, layout: PartLayout = PartLayout(), state: int | None = None,
                part_number: int | None = None) -> EncodedPart:
    """Encode ``image`` as a deep part (scan lines or one-level tiles); ``part_number``: its index in a
    multi-part file (each chunk then starts with it), None for a single-part file."""
    if layout.compression not in _ALL_WRITE_COMPRESSIONS:
        raise Unsupported(f"writing compression {layout.compression}")
    comp = _ALL_WRITE_COMPRESSIONS[layout.compression]
    tiles = layout.tiles
    if tiles is not None and (int(tiles[0]) < 1 or int(tiles[1]) < 1):
        raise ValueError(f"tile size {tiles}")
    geo = _geometry(image, comp, tiles)
    attrs = build_header(image, comp, state, tiles, layout.line_order, geo.n_chunks)

    # channels in name order, grouped into runs that one transposing copy per row turns into file bytes
    names = sorted(list(image.channels) + list(image.ids), key=str.encode)
    infos = [ChannelInfo(n, "uint" if n in image.ids else image.channel_types.get(n, "float")) for n in names]
    runs = _channel_runs(infos, list(image.channels))
    w = image.width
    counts = image.counts.reshape(image.height, w)
    offsets = image.offsets
    prefix = b"" if part_number is None else struct.pack("<i", part_number)
    x0, y0 = image.data_window[:2]

    def encode(k: int) -> bytes:
        r0, r1, c0, c1 = geo.chunk(k)
        rows = []
        for y in range(r0, r1):
            s0, s1 = int(offsets[y * w + c0]), int(offsets[y * w + c1])
            for dtype, _, run_names, col0 in runs:
                if col0 is not None:
                    rows.append(image.values[s0:s1, col0:col0 + len(run_names)].T.astype(dtype).tobytes())
                else:
                    rows.extend(image.ids[n][s0:s1].astype(dtype).tobytes() for n in run_names)
        data = b"".join(rows)
        table = np.cumsum(counts[r0:r1, c0:c1], axis=1).astype("<i4").tobytes()
        pt, pd = codec.compress(comp, table), codec.compress(comp, data)
        if geo.tiled:
            head = struct.pack("<4iQQQ", c0 // geo.chunk_w, r0 // geo.chunk_h, 0, 0, len(pt), len(pd), len(data))
        else:
            head = struct.pack("<iQQQ", y0 + r0, len(pt), len(pd), len(data))
        return prefix + head + pt + pd

    with ThreadPoolExecutor(_threads()) as pool:
        chunks = list(pool.map(encode, range(geo.n_chunks)))
    return EncodedPart(attrs, chunks, _store_order(geo, layout.line_order))


def _long_names(attrs: dict) -> bool:
    if any(len(k) > 31 or len(a.type) > 31 for k, a in attrs.items()):
        return True
    chans = attrs.get("channels")
    return chans is not None and any(len(c.name) > 31 for c in (chans.value() or []) if hasattr(c, "name"))


def write_file(f, parts: list[EncodedPart], multipart: bool, deep: bool = True) -> None:
    """Write encoded parts to the open binary file ``f``: magic and version flags, the headers, the offset
    tables, then each part's chunks in its storage order. ``deep``: some part is deep (the non-image flag)."""
    if not multipart and len(parts) != 1:
        raise ValueError("a single-part file holds one part")
    long_names = any(_long_names(p.attrs) for p in parts)
    flags = (VERSION_NONIMAGE if deep else 0) | (VERSION_LONG_NAMES if long_names else 0)
    flags |= VERSION_MULTIPART if multipart else 0
    head = struct.pack("<ii", MAGIC, 2 | flags) + b"".join(write_header(p.attrs) for p in parts)
    if multipart:
        head += b"\0"
    pos = len(head) + 8 * sum(len(p.chunks) for p in parts)
    tables = []
    for p in parts:
        table = np.zeros(len(p.chunks), dtype="<u8")
        for k in p.order:
            table[k] = pos
            pos += len(p.chunks[k])
        tables.append(table.tobytes())
    f.write(head)
    for t in tables:
        f.write(t)
    for p in parts:
        for k in p.order:
            f.write(p.chunks[k])


def chunk_extents(src, layout: ExrLayout, index: int, path: str) -> tuple[list, list]:
    """(start, size) of each of part ``index``'s chunks (its header included), from the offset table and each
    chunk's own header (deep: the packed table and data sizes; flat: the data size), checked against the file:
    what copying the part needs, read without its chunks' bodies."""
    src = as_source(src, path)
    table_pos, count, _ = offset_table_span(layout, index, path)
    if count is None:
        raise RanadError(f"cannot copy part {index} (its chunk count is unknown)", path)
    starts = offsets_array(src, table_pos, count, path).tolist()
    deep, tiled = layout.part_is_deep(index), layout.part_is_tiled(index)
    fmt = ("<i" if layout.multipart else "<") + ("4i" if tiled else "i") + ("QQQ" if deep else "i")
    size = struct.calcsize(fmt)
    sizes = []
    for k, start in enumerate(starts):
        if start <= 0 or start + size > src.size:
            raise RanadError(f"truncated file (part {index}, chunk {k} is missing)", path)
        fields = struct.unpack(fmt, src.read(start, size, f"part {index}, chunk {k}'s header"))
        body = fields[-3] + fields[-2] if deep else fields[-1]
        if body < 0 or start + size + body > src.size:
            raise RanadError(f"truncated file (part {index}, chunk {k} is cut short)", path)
        sizes.append(size + body)
    return starts, sizes


def raw_part(src, layout: ExrLayout, index: int, path: str, part_number: int | None = -1) -> EncodedPart:
    """Part ``index`` of a file exactly as stored (attributes and every chunk's bytes, in the order the file
    stores them), to be written into another file unchanged. Each chunk's extent comes from its own header
    (deep: the packed table and data sizes; flat: the data size), checked against the file. ``part_number``:
    the part's index in the file it goes to (None: a single-part file; -1: as in the source), which each
    chunk's first field says in multi-part files."""
    src = as_source(src, path)
    part = layout.parts[index]
    starts, sizes = chunk_extents(src, layout, index, path)
    count = len(starts)
    chunks = [src.read(start, size, f"part {index}, chunk {k}") for k, (start, size) in enumerate(zip(starts, sizes))]
    if part_number != -1 and part_number != (index if layout.multipart else None):
        skip = 4 if layout.multipart else 0
        prefix = b"" if part_number is None else struct.pack("<i", part_number)
        chunks = [prefix + c[skip:] for c in chunks]
    order = sorted(range(count), key=lambda k: int(starts[k]))
    return EncodedPart(dict(part.attrs), chunks, order)


def write_part(f, image: DeepImage, compression: str = "zips", state: int | None = None, tiles=None,
               line_order: int = INCREASING_Y) -> None:
    """Write ``image`` as a single-part deep file (scan lines, or tiles of size ``tiles``) to the open binary
    file ``f``."""
    write_file(f, [encode_part(image, PartLayout(compression, tiles, line_order), state)], multipart=False)
