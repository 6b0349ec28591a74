"""Synthetic deep images for tests: seeded, ragged, with the awkward cases (empty pixels, many bins)."""

from __future__ import annotations

import numpy as np

from ranad_core.deep import DeepImage


def random_deep(width=13, height=7, max_bins=4, seed=0, origin=(0, 0), ids=("id",), many_bins_pixel=True,
                channels=("R", "G", "B", "A", "Z"), types=None) -> DeepImage:
    """A random deep image whose values survive a half/float round trip exactly."""
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, max_bins + 1, size=width * height)
    counts[0] = 0
    if many_bins_pixel:
        counts[min(len(counts) - 1, 5)] = 12
    offsets = np.concatenate([[0], np.cumsum(counts)])
    n = int(offsets[-1])
    types = dict(types or {})
    for c in channels:
        types.setdefault(c, "float" if c in ("Z", "ZBack") else "half")
    values = rng.uniform(0, 4, size=(n, len(channels))).astype(np.float32)
    for j, c in enumerate(channels):
        if types[c] == "half":
            values[:, j] = values[:, j].astype(np.float16).astype(np.float32)
    idmap = {name: rng.integers(0, 2**32, size=n, dtype=np.uint64).astype(np.uint32) for name in ids}
    x0, y0 = origin
    return DeepImage(values=values, offsets=offsets, channels=list(channels), ids=idmap,
                     data_window=(x0, y0, x0 + width - 1, y0 + height - 1),
                     display_window=(0, 0, x0 + width + 3, y0 + height + 2), channel_types=types)


def assert_same_deep(a: DeepImage, b: DeepImage) -> None:
    """Bit-exact equality of layout, channels (by name), float bits and ids."""
    assert a.data_window == b.data_window
    assert np.array_equal(a.offsets, b.offsets)
    assert sorted(a.channels) == sorted(b.channels)
    for name in a.channels:
        assert np.array_equal(a.channel(name).view(np.uint32), b.channel(name).view(np.uint32)), name
    assert sorted(a.ids) == sorted(b.ids)
    for name in a.ids:
        assert np.array_equal(a.ids[name], b.ids[name]), name


def write_corrupt_chunk(src: str, dst, line: int = 128) -> None:
    """Copy a single-part ZIPS deep file, scrambling the zlib stream of one scan line's sample data."""
    import struct

    from ranad_core.exr.header import parse_layout

    data = bytearray(open(src, "rb").read())
    layout = parse_layout(bytes(data), src)
    n = layout.parts[0].get("chunkCount")
    starts = np.frombuffer(bytes(data), dtype="<u8", count=n, offset=layout.header_end)
    chunk = int(starts[line])
    _, packed_table, _, _ = struct.unpack_from("<iQQQ", data, chunk)
    body = chunk + 28 + packed_table
    for k in range(8):
        data[body + 4 + k] ^= 0x5A
    open(dst, "wb").write(bytes(data))


def write_bad_compression(src: str, dst, code: int = 200) -> None:
    """Copy a file with its compression attribute set to a code that does not exist."""
    data = bytearray(open(src, "rb").read())
    i = data.index(b"compression\0compression\0")
    data[i + 24 + 4] = code
    open(dst, "wb").write(bytes(data))


def openexr_deep_channel(counts: np.ndarray, dtype: str, make) -> np.ndarray:
    """A deep channel as the OpenEXR Python module takes it: an [H, W] object array whose pixel (y, x) holds
    make(counts[y, x]) (an array of that many samples) as `dtype` ("e" half, "f" float)."""
    h, w = counts.shape
    a = np.empty((h, w), dtype=object)
    for y in range(h):
        for x in range(w):
            a[y, x] = np.asarray(make(counts[y, x])).astype(dtype)
    return a
