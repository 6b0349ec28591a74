"""Hostile files: every size a deep EXR claims is checked against the file and sane limits before anything is
allocated or decompressed, every failure is one RanadError line, and checkpoints load without running code.

Each crafted file here reproduces one hole a code read found in the reader (issue 26); the tests bound time
(CPU seconds, SIGPROF) and memory (tracemalloc peak), so the old reader fails them by hanging, by allocating, or
by raising something other than RanadError.
"""

from __future__ import annotations

import contextlib
import os
import signal
import struct
import tracemalloc
import zlib

import numpy as np
import pytest
from click.testing import CliRunner

from deep_factory import random_deep
from fuzz_exr import FileMap, _write_tiled, real_files
from ranad_cli.main import cli
from ranad_core.errors import RanadError
from ranad_core.exr import compression as codec
from ranad_core.exr import fast, oiio_io, read_deep, read_layout, write_deep
from ranad_core.exr.header import (MAGIC, VERSION_NONIMAGE, Attribute, ChannelInfo, FileSource, decode_attribute,
                                   encode_box2i, encode_chlist, encode_int, encode_string, parse_layout,
                                   write_header)
from ranad_core.exr.inspect import describe

MiB = 1 << 20


@contextlib.contextmanager
def deadline(seconds: float):
    """Raise TimeoutError in the main thread after ``seconds`` of this process's CPU time (not wall time, so a
    busy machine does not fail the test; pure-Python loops are interrupted)."""

    def fire(*_):
        raise TimeoutError(f"took more than {seconds} CPU seconds")

    old = signal.signal(signal.SIGPROF, fire)
    signal.setitimer(signal.ITIMER_PROF, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.signal(signal.SIGPROF, old)


@contextlib.contextmanager
def peak_memory():
    """Yields a dict whose "peak" is the tracemalloc peak (bytes) of the block (numpy arrays and bytes count)."""
    out = {}
    tracemalloc.start()
    try:
        yield out
    finally:
        out["peak"] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()


def refused(fn, match=None, seconds=10.0, max_mib=16):
    """fn() must raise RanadError (one line) within ``seconds`` and a tracemalloc peak of ``max_mib``."""
    with peak_memory() as mem, deadline(seconds):
        with pytest.raises(RanadError, match=match) as e:
            fn()
    assert mem["peak"] < max_mib * MiB, f"peak {mem['peak'] / MiB:.0f} MiB"
    assert "\n" not in str(e.value)
    return e.value


# ---- crafted files ---------------------------------------------------------------------------------------
def deep_file(path, width, height, chunks, comp=0, channels=(("A", "half"),), extra=None, drop=()):
    """A single-part deep scan-line file from explicit chunks: (packed table, packed data, claimed unpacked
    data size) per chunk of LINES_PER_CHUNK[comp] lines; ``extra`` attributes replace or add to the header."""
    win = (0, 0, width - 1, height - 1)
    attrs = {"channels": Attribute("chlist", encode_chlist([ChannelInfo(n, t) for n, t in channels])),
             "compression": Attribute("compression", bytes([comp])), "dataWindow": encode_box2i(win),
             "displayWindow": encode_box2i(win), "lineOrder": Attribute("lineOrder", b"\0"),
             "pixelAspectRatio": Attribute("float", struct.pack("<f", 1)),
             "screenWindowCenter": Attribute("v2f", struct.pack("<2f", 0, 0)),
             "screenWindowWidth": Attribute("float", struct.pack("<f", 1)),
             "type": encode_string("deepscanline"), "version": encode_int(1), "chunkCount": encode_int(len(chunks))}
    attrs.update(extra or {})
    for name in drop:
        attrs.pop(name)
    head = struct.pack("<ii", MAGIC, 2 | VERSION_NONIMAGE) + write_header(attrs)
    lines = {0: 1, 1: 1, 2: 1, 3: 16}[comp]
    pos = len(head) + 8 * len(chunks)
    table, body = [], []
    for k, (t, d, unpacked) in enumerate(chunks):
        c = struct.pack("<iQQQ", k * lines, len(t), len(d), unpacked) + t + d
        table.append(pos)
        pos += len(c)
        body.append(c)
    with open(path, "wb") as f:
        f.write(head + np.array(table, "<u8").tobytes() + b"".join(body))
    return str(path)


def cumulative(counts) -> bytes:
    return np.cumsum(np.asarray(counts, dtype=np.int64)).astype("<i4").tobytes()


def plain_file(path, counts_rows, channels=(("A", "half"),)):
    """A valid NONE file with the given per-pixel sample counts (rows of equal length), zero samples."""
    size = sum(2 if t == "half" else 4 for _, t in channels)
    chunks = [(cumulative(r), bytes(int(sum(r)) * size), int(sum(r)) * size) for r in counts_rows]
    return deep_file(path, len(counts_rows[0]), len(counts_rows), chunks, channels=channels)


def patch_attr(path, name, raw: bytes, type_name: str | None = None, out=None, more=None):
    """Rewrite a valid single-part file with attribute ``name`` (and those in ``more``, name -> raw) replaced,
    the chunk offsets shifted to the new header's length."""
    data = open(path, "rb").read()
    layout = parse_layout(data, str(path))
    part = layout.parts[0]
    n = part.get("chunkCount")
    attrs = dict(part.attrs)
    for k, v in dict(more or {}, **{name: raw}).items():
        attrs[k] = Attribute(type_name if k == name and type_name else (attrs[k].type if k in attrs else "string"), v)
    head = data[:8] + write_header(attrs)
    starts = np.frombuffer(data, "<u8", count=n, offset=layout.header_end).astype(np.int64)
    starts += len(head) - layout.header_end
    rest = data[layout.header_end + 8 * n:]
    out = out or path
    with open(out, "wb") as f:
        f.write(head + starts.astype("<u8").tobytes() + rest)
    return str(out)


@pytest.fixture
def small(tmp_path):
    """A valid ZIPS deep file written by ranad (7 channels, 13x7, ids)."""
    p = tmp_path / "small.exr"
    write_deep(p, random_deep(width=13, height=7, seed=3))
    return str(p)


# ---- header ----------------------------------------------------------------------------------------------
def test_negative_stringvector_length_does_not_loop(tmp_path):
    raw = struct.pack("<i", -4) + b"abcd"
    with deadline(5):
        assert decode_attribute("stringvector", raw) == raw  # undecodable: kept raw, not looped over
        assert decode_attribute("stringvector", struct.pack("<i", 99) + b"ab") == struct.pack("<i", 99) + b"ab"
    good = struct.pack("<i", 2) + b"ab" + struct.pack("<i", 0)
    assert decode_attribute("stringvector", good) == ["ab", ""]
    img = random_deep(width=5, height=4, seed=1)
    img.header["names"] = Attribute("stringvector", raw)
    path = tmp_path / "sv.exr"
    write_deep(path, img)
    with deadline(10):
        back = read_deep(path)
        assert back.header["names"].raw == raw
        describe(path)
        write_deep(tmp_path / "copy.exr", back, io="oiio")  # the OpenImageIO writer decodes every attribute


def test_unterminated_channel_list_is_ranad_error(small, tmp_path):
    raw = encode_chlist([ChannelInfo("A", "half"), ChannelInfo("Z", "float")])[:-1]  # no terminating NUL
    bad = patch_attr(small, "channels", raw, out=tmp_path / "bad.exr")
    data = open(bad, "rb").read()
    # the old reader's raw.index raised ValueError from the first use of the channel list
    refused(lambda: describe(bad, stats=False), r"attribute 'channels' cannot be decoded")
    refused(lambda: fast.read_part(data, parse_layout(data, bad), 0, bad), "channels")
    cut = encode_chlist([ChannelInfo("A", "half")])[:-6]  # a name whose type words are missing
    bad = patch_attr(small, "channels", cut, out=tmp_path / "cut.exr")
    refused(lambda: read_deep(bad), "channels")


@pytest.mark.parametrize("name,raw,type_name,match", [
    ("dataWindow", struct.pack("<4i", 0, 0, 12, 6) + b"\0", "box2i", "dataWindow"),   # 17 bytes
    ("dataWindow", struct.pack("<4f", 0, 0, 12, 6), "box2f", "dataWindow"),
    ("chunkCount", b"seven", "string", "chunkCount"),
    ("chunkCount", struct.pack("<i", -1), "int", "chunkCount -1"),
    ("compression", b"\x02\x02", "compression", "compression"),
    ("type", b"deepsomething", "string", "unknown part type"),
    ("tiles", struct.pack("<II", 4, 4), "tiledesc", "tiles"),
    ("channels", b"", "chlist", "channels"),
    ("channels", encode_chlist([ChannelInfo("A", "half"), ChannelInfo("A", "float")]), "chlist", "twice"),
], ids=lambda v: v if isinstance(v, str) and len(v) < 16 else None)
def test_structural_attributes_of_the_wrong_shape(small, tmp_path, name, raw, type_name, match):
    """Mutated real files raised ValueError/TypeError/IndexError from these (unpacking raw bytes as a window,
    int() of a string chunk count, ...): now one RanadError from the header parser."""
    bad = patch_attr(small, name, raw, type_name, out=tmp_path / "bad.exr")
    data = open(bad, "rb").read()
    refused(lambda: parse_layout(data, bad), match)
    refused(lambda: describe(bad, stats=False), match)
    refused(lambda: read_deep(bad), match)


def test_passthrough_attributes_of_the_wrong_size(small, tmp_path):
    """A preview claiming 60000 x 60000 pixels in 24 bytes (or a v2f of 3 bytes) passed through to the output,
    where the writer put it before 'type': OpenEXR stopped at it, and neither OpenImageIO nor ranad could open
    what `ranad denoise` wrote. Such an attribute is refused on reading, as OpenEXR refuses it."""
    preview = struct.pack("<II", 60000, 60000) + bytes(16)
    for name, raw, type_name, match in (("preview", preview, "preview", "has 24 bytes, expected 14400000008"),
                                        ("screenWindowCenter", b"abc", "v2f", "has 3 bytes, expected 8")):
        bad = patch_attr(small, name, raw, type_name, out=tmp_path / "bad.exr")
        refused(lambda: read_deep(bad), f"attribute '{name}' of type '{type_name}' {match}")
        r = CliRunner().invoke(cli, ["flatten", bad, "-o", str(tmp_path / "o.exr")])
        assert r.exit_code == 2 and "corrupt header" in r.output and not (tmp_path / "o.exr").exists()
    good = patch_attr(small, "preview", struct.pack("<II", 2, 3) + bytes(24), "preview", out=tmp_path / "good.exr")
    assert read_deep(good).header["preview"].raw == struct.pack("<II", 2, 3) + bytes(24)   # passes through


@pytest.mark.parametrize("window", [(5, 0, 4, 6), (0, 6, 12, 5), (0, 0, -1, -1)])
def test_inverted_data_window(small, tmp_path, window):
    bad = patch_attr(small, "dataWindow", struct.pack("<4i", *window), out=tmp_path / "bad.exr")
    data = open(bad, "rb").read()
    # the old reader passed the header and reached np.zeros with a negative size (ValueError)
    refused(lambda: parse_layout(data, bad), "empty or inverted")
    refused(lambda: read_deep(bad, io="fast"), "empty or inverted")


def test_inverted_or_huge_display_window(small, tmp_path):
    bad = patch_attr(small, "displayWindow", struct.pack("<4i", 10, 10, 0, 0), out=tmp_path / "bad.exr")
    refused(lambda: describe(bad, stats=False), r"displayWindow .* empty or inverted")
    bad = patch_attr(small, "displayWindow", struct.pack("<4i", 0, 0, 2**31 - 1, 10), out=tmp_path / "bad.exr")
    refused(lambda: describe(bad, stats=False), r"displayWindow .* out of range")


def test_zero_tile_size(tmp_path):
    path = str(tmp_path / "tiled.exr")
    _write_tiled(path, random_deep(width=13, height=9, seed=2), (4, 3))
    assert read_deep(path).num_bins > 0
    for raw in (struct.pack("<IIB", 0, 3, 0), struct.pack("<IIB", 4, 0, 0)):
        patch_attr(path, "tiles", raw, out=tmp_path / "zero.exr")
        bad = str(tmp_path / "zero.exr")
        data = open(bad, "rb").read()
        # the old reader divided by the tile size (ZeroDivisionError); OpenImageIO's check hid it only in read_deep
        refused(lambda: describe(bad, stats=False), "tile size")
        refused(lambda: parse_layout(data, bad), "tile size")
        refused(lambda: read_deep(bad, io="fast"), "tile size")


def test_huge_data_window_is_refused_before_listing_chunks(small, tmp_path):
    data = open(small, "rb").read()
    layout = parse_layout(data, small)
    x0, y0, x1, y1 = layout.parts[0].data_window
    bad = str(tmp_path / "bad.exr")
    patch_attr(small, "dataWindow", struct.pack("<4i", x0, y0, x1, y0 + (1 << 22) - 1), out=bad)
    layout = parse_layout(open(bad, "rb").read(), bad)
    # the old reader built a list of 4 M chunk tuples (hundreds of MB) before comparing the chunk count
    refused(lambda: fast.read_part(FileSource(bad), layout, 0, bad), "chunkCount", seconds=5, max_mib=8)
    refused(lambda: read_deep(bad), "chunkCount", seconds=5, max_mib=8)
    patch_attr(small, "dataWindow", struct.pack("<4i", x0, y0, x1, y0 + (1 << 22) - 1), out=bad,
               more={"chunkCount": struct.pack("<i", 1 << 22)})
    refused(lambda: read_deep(bad), "too large|incomplete", seconds=5, max_mib=8)
    patch_attr(small, "dataWindow", struct.pack("<4i", x0, y0, x0 + (1 << 29), y1), out=bad)
    refused(lambda: read_deep(bad), "more than the limit of", seconds=5, max_mib=8)   # the pixel cap
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RANAD_MAX_PIXELS", str(1 << 40))   # beyond the cap: the file's size still bounds the window
        refused(lambda: read_deep(bad), "too large", seconds=5, max_mib=8)


def test_window_larger_than_its_tables_allocates_nothing(tmp_path, monkeypatch):
    """12000x12000 pixels in a 1 MB file: each chunk's packed table is just big enough to claim its 48000 bytes
    (at zlib's 1032:1) but holds garbage; nothing of the image's size (576 MB of counts) may be allocated first.
    (The per-part pixel cap, 134 M, would refuse the window from the header: raised here to reach the chunks.)"""
    monkeypatch.setenv("RANAD_MAX_PIXELS", str(200_000_000))
    garbage = bytes(range(47))
    path = deep_file(tmp_path / "wide.exr", 12000, 12000, [(garbage, b"", 0)] * 12000, comp=2)
    assert os.path.getsize(path) < 2 * MiB
    refused(lambda: read_deep(path, io="fast"), "scan line 0: sample counts: zlib", seconds=10, max_mib=8)


def test_chunk_count_without_attribute_is_counted_not_listed(tmp_path):
    rows = [[1, 0, 2]] * 3
    path = plain_file(tmp_path / "p.exr", rows)
    assert read_deep(path).num_bins == 9
    data = open(path, "rb").read()
    layout = parse_layout(data, path)
    del layout.parts[0].attrs["chunkCount"]
    assert fast.read_part(data, layout, 0, path).num_bins == 9
    layout.parts[0].attrs["dataWindow"] = encode_box2i((0, 0, 2, (1 << 28) - 1))
    refused(lambda: fast.read_part(data, layout, 0, path), "too large|incomplete|more than the limit", seconds=5,
            max_mib=8)


# ---- chunks ------------------------------------------------------------------------------------------
def test_zlib_bomb_chunk_is_not_inflated(tmp_path):
    table = codec.compress(codec.ZIPS, cumulative([1, 1, 1, 1]))
    bomb = zlib.compress(bytes(64 * MiB), 9)  # 64 KB that inflate to 64 MiB
    good = codec.compress(codec.ZIPS, bytes(8))
    path = deep_file(tmp_path / "bomb.exr", 4, 2, [(table, good, 8), (table, bomb, 8)], comp=2)
    # the table says 4 half samples (8 bytes); the old reader inflated all 64 MiB first, then compared
    refused(lambda: read_deep(path), r"scan line 1: zip block decodes to more than 8 bytes", max_mib=8)
    # a claim the packed bytes cannot hold is refused before any inflating or allocation
    path = deep_file(tmp_path / "claim.exr", 4, 2, [(table, good, 8), (table, good, 1 << 40)], comp=2)
    refused(lambda: read_deep(path), "cannot hold", max_mib=8)


def test_rle_claimed_size_is_checked_before_allocation(tmp_path):
    raw_table = cumulative([1, 1, 1, 1])  # 16 bytes, stored raw (as long as its unpacked size)
    run = b"\x7f\x00"  # RLE: 128 zero bytes
    path = deep_file(tmp_path / "rle.exr", 4, 1, [(raw_table, run, 1 << 40)], comp=1)
    # the old reader called np.empty(2**40) (MemoryError or a terabyte of address space)
    refused(lambda: read_deep(path), "cannot hold", max_mib=8)
    path = deep_file(tmp_path / "rle2.exr", 4, 1, [(raw_table, run, 128)], comp=1)
    refused(lambda: read_deep(path), "128 bytes", max_mib=8)  # consistent claim, table says 8 bytes


def test_sample_counts_are_checked_before_the_output_is_allocated(tmp_path):
    rows = [[60000] * 64] * 64  # 245 M samples claimed (1 GB of float32), under the per-pixel cap
    chunks = [(cumulative(r), bytes(8), 8) for r in rows]
    path = deep_file(tmp_path / "claims.exr", 64, 64, chunks)
    # the old reader allocated the output for every claimed sample, then found the data size mismatch
    refused(lambda: fast.read_part(FileSource(path), parse_layout(open(path, "rb").read(), path), 0, path),
            r"scan line 0: 3840000 samples of 2 bytes, but 8 bytes", max_mib=8)
    refused(lambda: read_deep(path), "samples of 2 bytes", max_mib=8)


def test_decreasing_or_negative_counts(tmp_path):
    for cum in ([3, 2, 5], [-1, 0, 0], [2**31 - 1, -(2**31), 0]):
        table = np.array(cum, "<i4").tobytes()
        path = deep_file(tmp_path / "dec.exr", 3, 1, [(table, b"", 0)])
        refused(lambda: read_deep(path, io="fast"), "decrease")


def test_per_pixel_sample_cap(tmp_path, monkeypatch):
    path = plain_file(tmp_path / "many.exr", [[1, 70000, 0]])
    e = refused(lambda: read_deep(path, io="fast"), max_mib=8)
    assert "pixel (1, 0) has 70000 samples" in e.problem and "limit of 65536" in e.problem
    assert "RANAD_MAX_SAMPLES_PER_PIXEL" in e.problem
    monkeypatch.setenv("RANAD_MAX_SAMPLES_PER_PIXEL", "100000")
    assert read_deep(path, io="fast").counts.tolist() == [1, 70000, 0]
    monkeypatch.setenv("RANAD_MAX_SAMPLES_PER_PIXEL", "3")
    small = plain_file(tmp_path / "few.exr", [[1, 4, 0]])
    refused(lambda: read_deep(small, io="fast"), "limit of 3 per pixel")
    refused(lambda: read_deep(small, io="oiio"), "limit of 3 per pixel")  # the fallback reader too
    monkeypatch.setenv("RANAD_MAX_SAMPLES_PER_PIXEL", "lots")
    refused(lambda: read_deep(small, io="fast"), "not a positive integer")


def test_per_part_pixel_cap(tmp_path, monkeypatch):
    # an empty 16000 x 16000 deep frame is a 2 MB file (its zero counts compress ~1000:1) whose per-pixel tables
    # took 6.5 GB in `ranad info` and more than a minute in flatten/denoise: the cap refuses it from the header
    path = plain_file(tmp_path / "wide.exr", [[1, 0, 2], [0, 0, 1]])
    assert read_deep(path, io="fast").counts.tolist() == [1, 0, 2, 0, 0, 1]
    monkeypatch.setenv("RANAD_MAX_PIXELS", "5")
    for io in ("fast", "oiio"):
        e = refused(lambda: read_deep(path, io=io), "3x2 holds 6 pixels, more than the limit of 5")
        assert "RANAD_MAX_PIXELS" in e.problem
    monkeypatch.setenv("RANAD_MAX_PIXELS", "6")
    assert read_deep(path, io="oiio").counts.tolist() == [1, 0, 2, 0, 0, 1]
    monkeypatch.setenv("RANAD_MAX_PIXELS", "0")
    refused(lambda: read_deep(path, io="fast"), "RANAD_MAX_PIXELS='0' is not a positive integer")


def test_offset_table_pointing_into_the_header_or_overlapping(tmp_path):
    path = plain_file(tmp_path / "p.exr", [[1, 2], [0, 3], [1, 1]])
    data = bytearray(open(path, "rb").read())
    fm = FileMap(bytes(data))
    table = fm.tables[0][0]
    for value, match in ((8, "points into the header"), (fm.chunks[0][0], "chunks overlap"), (0, "missing"),
                         (len(data) - 4, "missing"), (2**64 - 1, "missing")):
        bad = bytearray(data)
        struct.pack_into("<Q", bad, table + 8, value)
        p = tmp_path / "bad.exr"
        p.write_bytes(bytes(bad))
        refused(lambda: read_deep(p, io="fast"), match)
    # chunk 0 claims packed bytes that run into chunk 1
    s, head, _, tlen, _, dlen, _ = fm.chunks[0]
    bad = bytearray(data)
    struct.pack_into("<QQ", bad, s + head - 16, dlen + 10, dlen + 10)
    p.write_bytes(bytes(bad))
    refused(lambda: read_deep(p, io="fast"), "scan line 0 and scan line 1 overlap")


def test_chunk_header_sizes_past_the_file(tmp_path):
    path = plain_file(tmp_path / "p.exr", [[1, 2], [0, 3]])
    data = open(path, "rb").read()
    fm = FileMap(data)
    s, head = fm.chunks[0][:2]
    for field, value in ((0, 2**64 - 1), (8, 2**63), (16, 2**64 - 1), (8, len(data))):
        bad = bytearray(data)
        struct.pack_into("<Q", bad, s + head - 24 + field, value)
        p = tmp_path / "bad.exr"
        p.write_bytes(bytes(bad))
        refused(lambda: read_deep(p, io="fast"), "cut short|cannot hold|not a whole number|bytes of sample")


# ---- streaming: memory follows what is needed ---------------------------------------------------------
def test_info_no_stats_reads_the_header_only(small, tmp_path):
    big = tmp_path / "big.exr"
    data = open(small, "rb").read()
    with open(big, "wb") as f:
        f.write(data)
        f.truncate(64 * MiB)  # 64 MiB after the header (sparse)
    with peak_memory() as mem:
        d = describe(big, stats=False)
    assert d["file_size"] == 64 * MiB and d["parts"][0]["resolution"] == [13, 7]
    assert mem["peak"] < 2 * MiB, f"peak {mem['peak'] / MiB:.1f} MiB"  # the old reader read the whole file


def test_read_holds_one_chunk_at_a_time_not_the_file(tmp_path):
    img = random_deep(width=160, height=120, max_bins=8, seed=5, channels=("R", "G", "B", "A", "Z"),
                      types={c: "float" for c in "RGBAZ"})
    path = tmp_path / "none.exr"
    write_deep(path, img, compression="none")
    size = os.path.getsize(path)
    output = img.values.nbytes + img.offsets.nbytes + sum(v.nbytes for v in img.ids.values())
    layout, src = read_layout(path)
    with peak_memory() as mem:
        back = fast.read_part(src, layout, 0, str(path))
    src.close()
    assert back.num_bins == img.num_bins
    # the old reader held the file, every decoded chunk and the output at once (> output + 2x the file)
    assert mem["peak"] < output + size // 4, (mem["peak"], output, size)


# ---- OpenImageIO fallback --------------------------------------------------------------------------------
def test_openimageio_failures_are_ranad_errors(small, monkeypatch, tmp_path):
    import OpenImageIO as oiio

    cut = tmp_path / "cut.exr"
    cut.write_bytes(open(small, "rb").read()[:-200])
    refused(lambda: read_deep(cut, io="oiio"), max_mib=64)

    def boom(*a, **k):
        raise RuntimeError("binding failure\nsecond line")

    with monkeypatch.context() as m:
        m.setattr(oiio.ImageInput, "open", boom)
        refused(lambda: read_deep(small, io="oiio"), "RuntimeError: binding failure")

    class NoUtf8:
        def geterror(self):
            return b"\xff\xfe".decode("utf-8")  # what the binding raises on a message that is not UTF-8

    with monkeypatch.context() as m:
        m.setattr(oiio.ImageInput, "open", lambda *a, **k: None)
        m.setattr(oiio, "geterror", NoUtf8().geterror)
        refused(lambda: oiio_io.open_input(small), "cannot be opened by OpenImageIO")

    class Input:
        def __init__(self, real):
            self.real = real

        def __getattr__(self, name):
            return getattr(self.real, name)

        def read_native_deep_image(self, *a):
            raise ValueError("bad deep data")

    real_open = oiio.ImageInput.open
    with monkeypatch.context() as m:
        m.setattr(oiio.ImageInput, "open", lambda p: Input(real_open(p)))
        refused(lambda: read_deep(small, io="oiio"), "ValueError: bad deep data")


# ---- the command line ---------------------------------------------------------------------------------
def test_cli_hostile_files_one_line_exit_2(tmp_path):
    table = codec.compress(codec.ZIPS, cumulative([1, 1, 1, 1]))
    files = {
        "bomb": deep_file(tmp_path / "bomb.exr", 4, 1, [(table, zlib.compress(bytes(8 * MiB)), 8)], comp=2),
        "rle": deep_file(tmp_path / "rle.exr", 4, 1, [(cumulative([1, 1, 1, 1]), b"\x7f\x00", 1 << 40)], comp=1),
        "claims": deep_file(tmp_path / "claims.exr", 4, 1, [(cumulative([60000] * 4), bytes(8), 8)]),
        "inverted": deep_file(tmp_path / "inv.exr", 4, 1, [(cumulative([1] * 4), bytes(8), 8)],
                              extra={"dataWindow": encode_box2i((3, 0, 0, 0))}),
        "chlist": deep_file(tmp_path / "chl.exr", 4, 1, [(cumulative([1] * 4), bytes(8), 8)],
                            extra={"channels": Attribute("chlist", b"A\0\1\0")}),
    }
    for name, path in files.items():
        for args in (["info", path], ["flatten", path, "-o", str(tmp_path / "o.png")]):
            r = CliRunner().invoke(cli, args)
            lines = r.output.strip().splitlines()
            assert r.exit_code == 2, (name, args[0], r.output)
            assert len(lines) == 1 and lines[0].startswith(f"ranad: error: {path}: "), (name, r.output)


def test_cli_fuzzed_real_file_is_one_line(tmp_path):
    src = real_files()[0]
    data = bytearray(open(src, "rb").read())
    fm = FileMap(bytes(data))
    s, head = fm.chunks[len(fm.chunks) // 2][:2]
    struct.pack_into("<Q", data, s + head - 8, 2**62)  # a chunk claims 4 EiB of samples
    p = tmp_path / "claim.exr"
    p.write_bytes(bytes(data))
    r = CliRunner().invoke(cli, ["info", str(p)])
    assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1, r.output


# ---- checkpoints ------------------------------------------------------------------------------------------
class _RunsCode:
    """Pickles to a call of open(marker, "w"): loading it with weights_only=False creates the marker."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def test_crafted_checkpoint_does_not_run_code(tmp_path):
    import torch

    from ranad_core.model.store import load_model
    from ranad_core.train.trainer import CHECKPOINT, resume_step

    marker = tmp_path / "pwned"
    run = tmp_path / "run"
    run.mkdir()
    torch.save({"model": {}, "model_config": {"name": "x"}, "step": 3, "payload": _RunsCode(marker)},
               run / CHECKPOINT)
    with pytest.raises(RanadError, match="not a ranad training checkpoint") as e:
        load_model(str(run / CHECKPOINT))
    assert "\n" not in str(e.value)
    with pytest.raises(RanadError, match="not a ranad training checkpoint.*Unpickling"):
        resume_step(str(run))
    assert not marker.exists()
    # the CLI verbs that read checkpoints: one line, exit 2, nothing run, nothing written
    from click.testing import CliRunner

    from ranad_cli.main import cli

    for args in (["export", str(run), "-o", str(tmp_path / "m.safetensors")],
                 ["train", str(tmp_path), "-o", str(run), "--steps", "5"]):
        r = CliRunner().invoke(cli, args)
        assert r.exit_code == 2 and "not a ranad training checkpoint" in r.output, (args, r.output)
        assert len(r.output.strip().splitlines()) == 1, r.output
    assert not marker.exists() and not (tmp_path / "m.safetensors").exists()
    # truncated and foreign files: the same one-line error
    (run / CHECKPOINT).write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(RanadError, match="not a ranad training checkpoint"):
        resume_step(str(run))
    torch.save({"weights": torch.zeros(2)}, run / CHECKPOINT)
    with pytest.raises(RanadError, match=r"no model, model_config, step"):
        resume_step(str(run))


def test_training_checkpoints_load_with_weights_only(tmp_path):
    """What save_checkpoint writes (tensors, optimizer state, configs, numpy's rng state) is weights_only-safe."""
    import torch

    from ranad_core.model.config import get_config
    from ranad_core.train.trainer import CHECKPOINT, TrainConfig, build_model, param_groups, resume_step, \
        save_checkpoint

    cfg = TrainConfig(dataset=str(tmp_path), run=str(tmp_path / "run"))
    model = build_model(cfg, get_config(cfg.config))
    opt = torch.optim.AdamW(param_groups(model), lr=1e-3)
    sum(p.sum() for p in model.parameters()).backward()
    opt.step()  # optimizer state with tensors in it
    os.makedirs(cfg.run)
    rng = np.random.default_rng(5)
    rng.random()
    save_checkpoint(os.path.join(cfg.run, CHECKPOINT), model, opt, 7, cfg, rng)
    assert resume_step(cfg.run) == 7
    state = torch.load(os.path.join(cfg.run, CHECKPOINT), weights_only=True)
    assert state["rng"] == rng.bit_generator.state


def test_deep_file_without_z_is_one_line(tmp_path):
    """A deep file whose Z channel is missing (fuzz case 8741 of seed 1 renamed it): `flatten` and `denoise` name
    the file in one line with exit 2; deep.flatten raises ranad's error, not a foreign ValueError."""
    from ranad_core.deep import DeepImage, flatten
    from ranad_core.exr import write_deep

    img = DeepImage(values=np.ones((4, 4), np.float32), offsets=np.arange(5), channels=["A", "B", "G", "R"],
                    data_window=(0, 0, 1, 1))
    path = str(tmp_path / "noz.exr")
    write_deep(path, img)
    with pytest.raises(RanadError, match="no Z channel"):
        flatten(img)
    for args in (["flatten", path, "-o", str(tmp_path / "o.exr")], ["denoise", path, "-o", str(tmp_path / "d.exr")]):
        r = CliRunner().invoke(cli, args)
        lines = r.output.strip().splitlines()
        assert r.exit_code == 2 and len(lines) == 1 and lines[0].startswith(f"ranad: error: {path}: "), r.output
    assert not (tmp_path / "o.exr").exists() and not (tmp_path / "d.exr").exists()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo (POSIX) to make a pipe")
def test_a_pipe_or_device_is_named_as_such(tmp_path):
    """A path that exists but is no regular file (a FIFO, /dev/zero) was reported as 'no such file'; reading it
    would block or never end."""
    fifo = tmp_path / "frame.exr"
    os.mkfifo(fifo)
    for args in (("info", fifo), ("flatten", fifo, "-o", tmp_path / "o.exr"),
                 ("denoise", fifo, "-o", tmp_path / "d.exr")):
        r = CliRunner().invoke(cli, [str(a) for a in args])
        assert r.exit_code == 2 and "not a regular file" in r.output and "no such file" not in r.output, r.output
    r = CliRunner().invoke(cli, ["info", str(tmp_path / "missing.exr")])
    assert r.exit_code == 2 and "no such file" in r.output
    assert not (tmp_path / "o.exr").exists() and not (tmp_path / "d.exr").exists()
