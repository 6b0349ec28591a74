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
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..deep import DeepImage
from ..errors import RanadError
from . import compression as codec
from .header import (LINES_PER_CHUNK, VERSION_LONG_NAMES, VERSION_NONIMAGE, Attribute, ChannelInfo, ExrLayout,
                     PartHeader, encode_box2i, encode_chlist, encode_int, encode_string, offsets_array,
                     write_header, MAGIC, STRUCTURAL, COMPRESSION_NAMES)

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


def _chunk_geometry(part: PartHeader, tiled: bool):
    """Yield (row0, row1, col0, col1) in data-window-relative pixels for each chunk, in offset-table order."""
    xmin, ymin, xmax, ymax = part.data_window
    w, h = xmax - xmin + 1, ymax - ymin + 1
    if tiled:
        xs, ys, level_mode, _ = part.tiles
        if level_mode != 0:
            raise Unsupported("multi-resolution deep tiles")
        for ty in range((h + ys - 1) // ys):
            for tx in range((w + xs - 1) // xs):
                yield ty * ys, min(h, (ty + 1) * ys), tx * xs, min(w, (tx + 1) * xs)
    else:
        lpc = LINES_PER_CHUNK[part.compression]
        for y in range(0, h, lpc):
            yield y, min(h, y + lpc), 0, w


def read_part(buf: bytes, layout: ExrLayout, index: int, path: str,
              channels: list[str] | None = None) -> DeepImage:
    """Decode deep part ``index`` of a file held in memory as ``buf``."""
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
    chans = sorted(chans, key=lambda c: c.name.encode())
    if channels is not None:
        missing = [n for n in channels if n not in {c.name for c in chans}]
        if missing:
            raise RanadError(f"missing channel(s) {', '.join(missing)}", path)
    tiled = layout.part_is_tiled(index)
    geometry = list(_chunk_geometry(part, tiled))
    xmin, ymin, xmax, ymax = part.data_window
    width, height = xmax - xmin + 1, ymax - ymin + 1

    # offset tables of all parts follow the headers back to back
    pos = layout.header_end
    for i in range(index):
        pos += 8 * _chunk_count(layout, i)
    n_chunks = _chunk_count(layout, index)
    if n_chunks != len(geometry):
        raise RanadError(f"corrupt header (chunkCount {n_chunks}, expected {len(geometry)})", path)
    starts = offsets_array(buf, pos, n_chunks, path)
    multipart = layout.multipart
    head_fmt = ("<i" if multipart else "<") + ("4i" if tiled else "i") + "QQQ"
    head_size = struct.calcsize(head_fmt)

    def decode(k: int):
        r0, r1, c0, c1 = geometry[k]
        where = f"tile {k}" if tiled else f"scan line {ymin + r0}"
        start = int(starts[k])
        if start <= 0 or start + head_size > len(buf):
            raise RanadError(f"truncated file ({where} is missing)", path)
        fields = struct.unpack_from(head_fmt, buf, start)
        if multipart:
            if fields[0] != index:
                raise RanadError(f"corrupt chunk ({where} belongs to part {fields[0]})", path)
            fields = fields[1:]
        if tiled:
            tx, ty, lx, ly = fields[:4]
            xs, ys = part.tiles[:2]
            if (tx * xs, ty * ys, lx, ly) != (c0, r0, 0, 0):
                raise RanadError(f"corrupt chunk ({where} has coordinates {tx},{ty})", path)
        elif fields[0] != ymin + r0:
            raise RanadError(f"corrupt chunk ({where} says it starts at line {fields[0]})", path)
        packed_table, packed_data, unpacked_data = fields[-3:]
        p = start + head_size
        if p + packed_table + packed_data > len(buf):
            raise RanadError(f"truncated file ({where} is cut short)", path)
        rows, cols = r1 - r0, c1 - c0
        try:
            table = codec.decompress(comp, buf[p:p + packed_table], rows * cols * 4)
            data = codec.decompress(comp, buf[p + packed_table:p + packed_table + packed_data], unpacked_data)
        except codec.CodecError as e:
            raise RanadError(f"corrupt chunk ({where}: {e})", path) from None
        cum = np.frombuffer(table, dtype="<i4").reshape(rows, cols).astype(np.int64)
        counts = np.diff(cum, axis=1, prepend=0)
        if np.any(counts < 0):
            raise RanadError(f"corrupt chunk ({where}: sample counts decrease)", path)
        return counts, data

    with ThreadPoolExecutor(_threads()) as pool:
        decoded = list(pool.map(decode, range(n_chunks)))

    counts_img = np.zeros((height, width), dtype=np.int64)
    for (r0, r1, c0, c1), (counts, _) in zip(geometry, decoded):
        counts_img[r0:r1, c0:c1] = counts
    offsets = np.zeros(width * height + 1, dtype=np.int64)
    np.cumsum(counts_img.ravel(), out=offsets[1:])
    n = int(offsets[-1])

    keep = [c for c in chans if channels is None or c.name in channels]
    value_names = [c.name for c in keep if c.type != "uint"]
    values = np.empty((n, len(value_names)), dtype=np.float32)
    ids = {c.name: np.empty(n, dtype=np.uint32) for c in keep if c.type == "uint"}
    runs = _channel_runs(chans, value_names)
    row_size = sum(c.size for c in chans)

    def scatter(k: int) -> None:
        """Copy one chunk's rows into the ragged arrays: per row, one transposing copy per channel run."""
        r0, r1, c0, c1 = geometry[k]
        counts, data = decoded[k]
        row_totals = counts.sum(axis=1)
        if int(row_totals.sum()) * row_size != len(data):
            raise RanadError(f"corrupt chunk (rows {ymin + r0}-{ymin + r1 - 1}: sample data size mismatch)", path)
        p = 0
        for r in range(r0, r1):
            m = int(row_totals[r - r0])
            if m == 0:
                continue
            # a row of a chunk (a full scan line, or a tile row) is contiguous in the ragged layout
            dst = int(offsets[r * width + c0])
            for dtype, size, names, col0 in runs:
                block = np.frombuffer(data, dtype=dtype, count=m * len(names), offset=p).reshape(len(names), m)
                if col0 is not None:
                    values[dst:dst + m, col0:col0 + len(names)] = block.T
                else:
                    for j, name in enumerate(names):
                        if name in ids:
                            ids[name][dst:dst + m] = block[j]
                p += m * size * len(names)

    with ThreadPoolExecutor(_threads()) as pool:
        list(pool.map(scatter, range(n_chunks)))
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


def _chunk_count(layout: ExrLayout, i: int) -> int:
    part = layout.parts[i]
    cc = part.get("chunkCount")
    if cc is not None:
        return int(cc)
    return sum(1 for _ in _chunk_geometry(part, layout.part_is_tiled(i)))


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
