"""Deep EXR I/O: the fast codec against OpenImageIO on real files, round trips, and bad input."""

from __future__ import annotations

import os
import shutil

import numpy as np
import OpenEXR
import pytest

from deep_factory import (assert_same_deep, openexr_deep_channel, random_deep, write_bad_compression,
                          write_corrupt_chunk)
from ranad_core.errors import RanadError
from ranad_core.exr import fast, read_deep, read_layout, write_deep
from ranad_core.exr.header import parse_layout
from real_data import BUNDLED_FILES, DATA, bundled, bundled_deep_files, shared, shared_params, write_small_flat

# every real deep file: the bundled ones always, the larger ../shared ones when that folder is beside the project
REAL_FILES = [pytest.param(p, id=os.path.basename(p)) for p in bundled_deep_files()] + shared_params()


def _deep_parts(path):
    layout, _ = read_layout(path)
    return [i for i in range(len(layout.parts)) if layout.part_is_deep(i)]


def test_real_data_present():
    """The bundled real files are in the checkout, credited in tests/data/README.md, and deep."""
    credits = (DATA / "README.md").read_text()
    for name in BUNDLED_FILES:
        assert f"`{name}`" in credits, f"{name} is not credited in tests/data/README.md"
    for path in bundled_deep_files():
        assert _deep_parts(path) == [0], path


@pytest.mark.parametrize("path", REAL_FILES)
def test_real_files_bit_exact_against_openimageio(path):
    for part in _deep_parts(path):
        ours = read_deep(path, part=part, io="fast")
        theirs = read_deep(path, part=part, io="oiio")
        assert ours.num_bins > 0
        assert_same_deep(ours, theirs)
        assert ours.channel_types == theirs.channel_types
        assert ours.display_window == theirs.display_window


@pytest.mark.parametrize("path", REAL_FILES)
def test_real_files_round_trip(path, tmp_path):
    src = read_deep(path, io="fast")
    out = tmp_path / "rt.exr"
    write_deep(out, src)
    assert_same_deep(read_deep(out, io="fast"), src)
    assert_same_deep(read_deep(out, io="oiio"), src)
    back = read_deep(out)
    assert back.channel_types == src.channel_types
    for name, attr in src.header.items():  # every non-structural attribute passes through byte for byte
        if name not in ("chunkCount", "compression", "lineOrder", "deepImageState"):
            assert back.header[name] == attr, name
    if "deepImageState" in src.header:
        assert back.header["deepImageState"].value() == src.header["deepImageState"].value()


@pytest.mark.parametrize("compression", ["zips", "none"])
def test_synthetic_round_trip_types_windows_ids(tmp_path, compression):
    img = random_deep(width=41, height=23, origin=(-7, 5), ids=("id", "particleid"),
                      channels=("R", "G", "B", "A", "Z", "ZBack", "mv.x"),
                      types={"mv.x": "float"})
    out = tmp_path / "syn.exr"
    write_deep(out, img, compression=compression)
    layout, _ = read_layout(out)
    assert layout.parts[0].compression == {"zips": 2, "none": 0}[compression]
    assert {c.name: c.type for c in layout.parts[0].channels} == img.channel_types
    for io in ("fast", "oiio"):
        back = read_deep(out, io=io)
        assert_same_deep(back, img)
        assert back.display_window == img.display_window


def test_write_through_openimageio_reads_back(tmp_path):
    img = random_deep(width=9, height=5, seed=3)
    write_deep(tmp_path / "o.exr", img, io="oiio")
    assert_same_deep(read_deep(tmp_path / "o.exr", io="fast"), img)


def test_multi_line_zip_chunks(tmp_path):
    # ZIP (16 lines per chunk) cannot be written by OpenEXR 3.5 for deep parts, so this checks our reader's
    # multi-line chunk handling against our writer; tiles (below) check multi-row chunks against OpenImageIO.
    img = random_deep(width=19, height=37, seed=4)
    path = tmp_path / "zip.exr"
    with open(path, "wb") as f:
        fast.write_part(f, img, "zip")
    buf = path.read_bytes()
    layout = parse_layout(buf, str(path))
    assert layout.parts[0].compression == 3 and layout.parts[0].get("chunkCount") == 3
    assert_same_deep(fast.read_part(buf, layout, 0, str(path)), img)


def _object_arrays(img):
    out = {}
    for name in list(img.channels) + list(img.ids):
        arr = np.empty((img.height, img.width), dtype=object)
        col = img.channel(name)
        for p in range(img.num_pixels):
            y, x = divmod(p, img.width)
            v = col[img.offsets[p]:img.offsets[p + 1]]
            if img.counts[p]:
                arr[y, x] = v.astype(np.float16) if img.channel_types[name] == "half" else v.copy()
        out[name] = arr
    return out


def test_rle_written_by_openexr(tmp_path):
    img = random_deep(width=17, height=11, seed=5)
    path = str(tmp_path / "rle.exr")
    OpenEXR.File({"compression": OpenEXR.RLE_COMPRESSION, "type": OpenEXR.deepscanline},
                 _object_arrays(img)).write(path)
    assert read_layout(path)[0].parts[0].compression == 1
    assert_same_deep(read_deep(path, io="fast"), img)
    assert_same_deep(read_deep(path, io="oiio"), img)


@pytest.mark.parametrize("tile", [(16, 8), (5, 7)])
def test_deep_tiles_written_by_openimageio(tmp_path, tile):
    import OpenImageIO as oiio

    img = random_deep(width=37, height=21, origin=(3, 5), seed=6)
    names = img.channels + list(img.ids)
    spec = oiio.ImageSpec(img.width, img.height, len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    spec.channelformats = tuple(oiio.TypeDesc(img.channel_types[n]) for n in names)
    spec.x, spec.y = 3, 5
    spec.deep = True
    spec.tile_width, spec.tile_height = tile
    spec.attribute("compression", "zips")
    path = str(tmp_path / "tiled.exr")
    out = oiio.ImageOutput.create(path)
    assert out.open(path, spec), out.geterror()
    dd = oiio.DeepData()
    dd.init(img.num_pixels, len(names), spec.channelformats, spec.channelnames)
    for p in range(img.num_pixels):
        dd.set_samples(p, int(img.counts[p]))
    for p in range(img.num_pixels):
        for s in range(img.counts[p]):
            for j in range(len(img.channels)):
                dd.set_deep_value(p, j, s, float(img.values[img.offsets[p] + s, j]))
            dd.set_deep_value_uint(p, len(img.channels), s, int(img.ids["id"][img.offsets[p] + s]))
    assert out.write_deep_image(dd), out.geterror()
    out.close()
    layout, _ = read_layout(path)
    assert layout.part_is_tiled(0) and layout.parts[0].tiles[:2] == tile
    assert_same_deep(read_deep(path, io="fast"), img)
    assert_same_deep(read_deep(path, io="oiio"), img)


def test_multipart_written_by_openimageio(tmp_path):
    """A two-part deep file written by OpenImageIO (different data windows, ids in one part only): each part
    reads back by index and by name, through both I/O paths; part 0 is the default."""
    import OpenImageIO as oiio

    imgs = {"left": random_deep(width=9, height=5, seed=1, ids=()),
            "right": random_deep(width=7, height=4, seed=2, origin=(2, 3), ids=("id",))}
    specs = []
    for name, img in imgs.items():
        names = img.channels + list(img.ids)
        spec = oiio.ImageSpec(img.width, img.height, len(names), oiio.FLOAT)
        spec.channelnames = tuple(names)
        spec.channelformats = tuple(oiio.TypeDesc(img.channel_types[n]) for n in names)
        spec.x, spec.y = img.data_window[:2]
        spec.full_x, spec.full_y, spec.full_width, spec.full_height = 0, 0, 16, 10   # one display window
        spec.deep = True
        spec.attribute("compression", "zips")
        spec.attribute("name", name)
        specs.append(spec)
    path = str(tmp_path / "two_parts.exr")
    out = oiio.ImageOutput.create(path)
    assert out.open(path, specs), out.geterror()
    for k, (spec, img) in enumerate(zip(specs, imgs.values())):
        if k:
            assert out.open(path, spec, "AppendSubimage"), out.geterror()
        dd = oiio.DeepData()
        dd.init(img.num_pixels, len(spec.channelnames), spec.channelformats, spec.channelnames)
        for p in range(img.num_pixels):
            dd.set_samples(p, int(img.counts[p]))
        for p in range(img.num_pixels):
            for s in range(img.counts[p]):
                b = img.offsets[p] + s
                for j in range(len(img.channels)):
                    dd.set_deep_value(p, j, s, float(img.values[b, j]))
                for j, idn in enumerate(img.ids):
                    dd.set_deep_value_uint(p, len(img.channels) + j, s, int(img.ids[idn][b]))
        assert out.write_deep_image(dd), out.geterror()
    out.close()
    for k, (name, img) in enumerate(imgs.items()):
        for io in ("fast", "oiio"):
            assert_same_deep(read_deep(path, part=k, io=io), img)
        by_name = read_deep(path, part=name)
        assert_same_deep(by_name, img)
        assert by_name.header["name"].value() == name and by_name.display_window == (0, 0, 15, 9)
    assert read_deep(path).header["name"].value() == "left"
    with pytest.raises(RanadError, match="no part named 'centre'"):
        read_deep(path, part="centre")
    with pytest.raises(RanadError, match="no part 2"):
        read_deep(path, part=2)


def test_multipart_by_index_and_name():
    path = shared("Stereo_Trunks.exr")
    right = read_deep(path, part="rgba.right")
    assert right.data_window == read_deep(path, part=1).data_window == (0, 266, 1882, 1079)
    assert read_deep(path).header["name"].value() == "rgba.left"
    with pytest.raises(RanadError, match="no part named 'centre'"):
        read_deep(path, part="centre")
    with pytest.raises(RanadError, match="no part 5"):
        read_deep(path, part=5)


def test_channel_subset():
    path = bundled("openexr_test_42.deep.exr")
    full = read_deep(path)
    sub = read_deep(path, channels=["R", "Z", "modelid"])
    assert sub.channels == ["R", "Z"] and list(sub.ids) == ["modelid"]
    assert np.array_equal(sub.channel("Z"), full.channel("Z"))
    assert np.array_equal(sub.ids["modelid"], full.ids["modelid"])
    with pytest.raises(RanadError, match="missing channel"):
        read_deep(path, channels=["R", "diffuse.R"])


def test_deep_image_state_reflects_what_is_written(tmp_path):
    src = read_deep(bundled("openexr_test_42.deep.exr"))
    assert src.header["deepImageState"].value() == 3
    # reverse every pixel's bins: no longer sorted, so the state written must say so
    perm = np.concatenate([np.arange(src.offsets[p + 1] - 1, src.offsets[p] - 1, -1)
                           for p in range(src.num_pixels)]).astype(np.int64)
    messy = src.with_values(src.values[perm])
    messy.ids = {k: v[perm] for k, v in src.ids.items()}
    write_deep(tmp_path / "m.exr", messy)
    state = read_deep(tmp_path / "m.exr").header["deepImageState"].value()
    assert state in (0, 2)  # not sorted
    write_deep(tmp_path / "t.exr", messy, state="tidy")
    assert read_deep(tmp_path / "t.exr").header["deepImageState"].value() == 3


# ---- bad input ----------------------------------------------------------------------------------------
def test_not_an_exr(tmp_path):
    p = tmp_path / "x.exr"
    p.write_text("hello, I am not an image")
    with pytest.raises(RanadError, match="not an EXR file") as e:
        read_deep(p)
    assert str(p) in str(e.value)


def test_flat_exr_is_refused(tmp_path):
    flat = write_small_flat(tmp_path / "flat.exr")
    with pytest.raises(RanadError, match="not a deep image") as e:
        read_deep(flat)
    assert str(flat) in str(e.value)


def test_flat_exr_from_openexr_images_is_refused():
    with pytest.raises(RanadError, match="not a deep image"):
        read_deep(shared("LowResLeftView_composited.exr"))


def test_missing_file(tmp_path):
    with pytest.raises(RanadError, match="no such file"):
        read_deep(tmp_path / "nope.exr")


@pytest.mark.parametrize("keep", [0.3, 0.9, 0.999])
def test_truncated_file(tmp_path, keep):
    src = bundled("openexr_test_11.deep.exr")
    data = open(src, "rb").read()
    p = tmp_path / "cut.exr"
    p.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(RanadError, match="truncated|cannot be opened|corrupt"):
        read_deep(p, io="fast")


def test_corrupt_chunk(tmp_path):
    p = tmp_path / "corrupt.exr"
    write_corrupt_chunk(bundled("openexr_test_42.deep.exr"), p, line=128)
    with pytest.raises(RanadError, match=r"corrupt chunk \(scan line 128"):
        read_deep(p, io="fast")


def test_unknown_compression_is_refused(tmp_path):
    p = tmp_path / "badcomp.exr"
    write_bad_compression(bundled("openexr_test_11.deep.exr"), p)
    with pytest.raises(RanadError, match="compression"):
        read_deep(p)


def test_unwritable_output_leaves_nothing(tmp_path):
    img = random_deep(width=4, height=3)
    with pytest.raises(RanadError, match="output folder does not exist"):
        write_deep(tmp_path / "missing" / "o.exr", img)
    assert os.listdir(tmp_path) == []


def test_failed_write_leaves_no_partial_file(tmp_path, monkeypatch):
    img = random_deep(width=4, height=3)

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(fast, "write_part", boom)
    with pytest.raises(RuntimeError):
        write_deep(tmp_path / "o.exr", img)
    assert os.listdir(tmp_path) == []


def test_write_refuses_unknown_compression(tmp_path):
    with pytest.raises(RanadError, match="cannot write deep compression 'piz'"):
        write_deep(tmp_path / "o.exr", random_deep(width=4, height=3), compression="piz")


def test_copy_of_real_file_with_unicode_name(tmp_path):
    p = tmp_path / "plan_é.exr"
    shutil.copy(bundled("openexr_test_11.deep.exr"), p)
    assert read_deep(p).num_bins == 6056


@pytest.mark.parametrize("tile", [(7, 3), (100, 200)])
def test_uncompressed_deep_tiles_at_the_edges_written_by_openexr(tmp_path, tile):
    """OpenEXR writes an uncompressed deep tile's sample-count table at the full tile's size, also where the tile
    is cut by the window's edge (its rows x cols counts first): ranad refused such files as corrupt ("uncompressed
    block has 84 bytes, expected 12"). Read, they equal OpenImageIO's reading of the same file."""
    h, w = 37, 29
    rng = np.random.default_rng(0)
    counts = rng.integers(0, 4, (h, w))

    chan = lambda dtype, make: openexr_deep_channel(counts, dtype, make)  # noqa: E731

    z = chan("f", lambda n: np.sort(rng.uniform(1, 10, n)))
    r, a = chan("e", lambda n: rng.uniform(0, 1, n)), chan("e", lambda n: rng.uniform(0, 1, n))
    desc = OpenEXR.TileDescription()
    desc.xSize, desc.ySize, desc.mode = tile[0], tile[1], OpenEXR.LevelMode.ONE_LEVEL
    path = str(tmp_path / "tiles.exr")
    OpenEXR.File({"type": OpenEXR.deeptile, "compression": OpenEXR.NO_COMPRESSION, "tiles": desc,
                  "dataWindow": ((3, -5), (3 + w - 1, -5 + h - 1)), "displayWindow": ((0, -10), (40, 40))},
                 {"R": r, "G": r, "B": r, "A": a, "Z": z}).write(path)
    fast_img, oiio_img = read_deep(path, io="fast"), read_deep(path, io="oiio")
    assert fast_img.counts.reshape(h, w).tolist() == counts.tolist()
    np.testing.assert_array_equal(fast_img.offsets, oiio_img.offsets)
    np.testing.assert_array_equal(fast_img.values, oiio_img.values)


def _predictor_oracle(raw: bytes) -> bytes:
    """OpenEXR's ZIP/RLE pre-pass written byte by byte (ImfZip.cpp): the even bytes, then the odd ones, each
    byte stored as its difference from the previous one plus 128, modulo 256."""
    t = raw[0::2] + raw[1::2]
    return bytes([t[0]] + [(t[i] - t[i - 1] + 128) % 256 for i in range(1, len(t))]) if t else b""


@pytest.mark.parametrize("size", [1, 2, 3, 1001, 1 << 16, (1 << 16) + 1, 300_001])
@pytest.mark.parametrize("with_torch", [True, False])
def test_predictor_and_its_undo_match_openexr_byte_for_byte(monkeypatch, size, with_torch):
    """The codec's pre-pass and its undo, on blocks above and below the size from which torch's prefix sum takes
    over (and with torch unavailable), against a byte-by-byte oracle: a slip in either path corrupts every
    compressed file that path reads or writes."""
    import torch

    from ranad_core.exr import compression

    monkeypatch.setattr(compression, "_torch", (lambda: torch) if with_torch else (lambda: None))
    raw = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8).tobytes()
    packed = compression._interleave_predict(raw)
    assert packed == _predictor_oracle(raw)
    assert compression._unpredict_deinterleave(np.frombuffer(packed, np.uint8)) == raw
    assert compression.decompress(compression.ZIPS, compression.compress(compression.ZIPS, raw), size) == raw
