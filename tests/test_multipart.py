"""Multi-part and stereo files (issue 25): the chosen deep parts are denoised, every other part is copied byte for
byte, `ranad info` lists the parts. A small stereo file the suite makes itself (two deep eyes around a flat part),
and the real Stereo_Trunks.exr when ../shared is beside the checkout."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core.exr import fast, read_deep, read_layout, write_parts
from ranad_core.exr.header import encode_int, encode_string
from real_data import shared
from test_defects import tiny  # noqa: F401  (the fixture)

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def eyes():
    """Two deep eyes cut from the example frame: different data windows, one with every layer and ids, one
    beauty-only in RLE tiles."""
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    left = img.crop((0, 0, 23, 19))
    right = img.select(["R", "G", "B", "A", "Z"]).crop((6, 4, 33, 21))
    left.header["name"], right.header["name"] = encode_string("left"), encode_string("right")
    right.header["view"] = encode_string("right")
    return left, right


def write_stereo(path: Path) -> dict:
    """A three-part file: deep 'left', flat 'matte' (written by OpenEXR itself, PIZ, with its own attribute),
    deep 'right' (RLE, 8x8 tiles). Built with ranad's multi-part writer; OpenImageIO must read every part."""
    left, right = eyes()
    flat_path = path.with_suffix(".flat.exr")
    rgb = np.random.default_rng(1).random((48, 48, 3)).astype(np.float16)   # the eyes' display window
    OpenEXR.File({"compression": OpenEXR.PIZ_COMPRESSION, "type": OpenEXR.scanlineimage, "studio": "matte v3"},
                 {"RGB": rgb}).write(str(flat_path))
    flat_layout, flat_src = read_layout(flat_path)
    with flat_src:
        flat = fast.raw_part(flat_src, flat_layout, 0, str(flat_path), part_number=1)
    flat.attrs.update(name=encode_string("matte"), type=encode_string("scanlineimage"),
                      chunkCount=encode_int(len(flat.chunks)))
    parts = [fast.encode_part(left, fast.PartLayout("zips"), None, 0), flat,
             fast.encode_part(right, fast.PartLayout("rle", (8, 8)), None, 2)]
    with open(path, "wb") as f:
        fast.write_file(f, parts, multipart=True)
    return {"left": left, "right": right, "matte": rgb}


def raw(path, index):
    layout, src = read_layout(path)
    with src:
        return fast.raw_part(src, layout, index, str(path))


def flat_pixels(path, index):
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    assert inp.seek_subimage(index, 0)
    data = inp.read_image(index, 0, 0, inp.spec().nchannels, oiio.HALF)
    inp.close()
    return np.asarray(data)


def test_generated_stereo_file_is_valid_openexr(tmp_path):
    path = tmp_path / "stereo.exr"
    made = write_stereo(path)
    layout, _ = read_layout(path)
    assert layout.multipart and [p.name for p in layout.parts] == ["left", "matte", "right"]
    for name in ("left", "right"):        # OpenEXR itself opens every part; it decodes the RLE tiles here
        got = read_deep(path, part=name, io="oiio" if name == "right" else "fast")
        np.testing.assert_array_equal(got.offsets, made[name].offsets)
        np.testing.assert_array_equal(got.values, made[name].values)
    np.testing.assert_array_equal(flat_pixels(path, 1), made["matte"])


def test_stereo_file_keeps_every_part(tmp_path, tiny):
    src = tmp_path / "stereo.exr"
    made = write_stereo(src)
    r = run("info", src, "--no-stats")
    assert r.exit_code == 0, r.output
    assert "part 0 'left': deepscanline" in r.output and "part 1 'matte': scanlineimage" in r.output
    assert "part 2 'right': deeptile" in r.output

    out = tmp_path / "out.exr"
    r = run("denoise", src, "-o", out, "--model", tiny)
    assert r.exit_code == 0, r.output
    assert "parts: part 0 'left', part 2 'right' (the others copied)" in r.output
    a, b = read_layout(src)[0], read_layout(out)[0]
    assert b.multipart and [(p.name, p.type) for p in b.parts] == [(p.name, p.type) for p in a.parts]
    for i in (0, 2):                        # denoised, stored as the input part was, attributes kept
        assert b.parts[i].compression == a.parts[i].compression and b.parts[i].tiles == a.parts[i].tiles
        assert all(b.parts[i].attrs.get(k) == v for k, v in a.parts[i].attrs.items()), i
        name = a.parts[i].name
        den = read_deep(out, part=name, io="oiio" if name == "right" else "fast")
        np.testing.assert_array_equal(den.offsets, made[name].offsets)
        assert den.data_window == made[name].data_window
        assert not np.array_equal(den.channel("R"), made[name].channel("R"))
        for c in made[name].channels:
            if c.split(".")[0] in ("albedo", "N", "emission", "motion_prev", "motion_next"):
                np.testing.assert_array_equal(den.channel(c), made[name].channel(c))
    np.testing.assert_array_equal(read_deep(out, part="left").ids["id"], made["left"].ids["id"])
    assert raw(out, 1).attrs == raw(src, 1).attrs and raw(out, 1).chunks == raw(src, 1).chunks
    np.testing.assert_array_equal(flat_pixels(out, 1), made["matte"])

    # --part: only that eye; the other deep part is copied byte for byte too
    one = tmp_path / "right_only.exr"
    r = run("denoise", src, "-o", one, "--model", tiny, "--part", "right")
    assert r.exit_code == 0, r.output
    for i in (0, 1):
        assert raw(one, i).attrs == raw(src, i).attrs and raw(one, i).chunks == raw(src, i).chunks
    np.testing.assert_array_equal(read_deep(one, part="right").values, read_deep(out, part="right").values)
    r = run("denoise", src, "-o", tmp_path / "by_index.exr", "--model", tiny, "--part", "2")
    assert r.exit_code == 0 and raw(tmp_path / "by_index.exr", 2).chunks == raw(one, 2).chunks

    for part, problem in (("matte", "part 1 'matte' is not deep"), ("centre", "no part named 'centre'"),
                          ("7", "no part 7")):
        r = run("denoise", src, "-o", tmp_path / "bad.exr", "--model", tiny, "--part", part)
        assert r.exit_code == 2 and problem in r.output and "stereo.exr" in r.output, r.output
        assert r.output.count("\n") == 1 and not (tmp_path / "bad.exr").exists()


def test_write_parts_replaces_only_the_given_parts(tmp_path):
    src = tmp_path / "stereo.exr"
    made = write_stereo(src)
    right = read_deep(src, part="right")
    vals = right.values.copy()
    g = right.channels.index("G")
    vals[:, g] += 1
    write_parts(tmp_path / "o.exr", src, {2: right.with_values(vals)})
    for i in (0, 1):
        assert raw(tmp_path / "o.exr", i).chunks == raw(src, i).chunks
    vals[:, g] = vals[:, g].astype(np.float16)                   # G is a half channel
    np.testing.assert_array_equal(read_deep(tmp_path / "o.exr", part=2, io="oiio").values, vals)
    assert made["right"].num_bins == right.num_bins


def test_real_stereo_file_keeps_both_eyes(tmp_path, tiny, monkeypatch):
    """Stereo_Trunks.exr (Weta, 2 deep parts of 1920x814): the right eye denoised, the left copied byte for byte.
    A full denoise of an eye takes minutes on 2 cores, so the model step is a stand-in that brightens R (the
    tiny model itself runs on the generated stereo file above): this checks the parts, not the model."""
    import ranad_core.shot as shot
    from ranad_core.denoise import FrameResult

    def fast_stand_in(model, images, centre, mapping, *args, **kwargs):
        img = images[centre]
        vals = img.values.copy()
        vals[:, img.channels.index("R")] += 0.5
        return FrameResult(img.with_values(vals), img.num_bins, 0, 1)

    monkeypatch.setattr(shot, "denoise_window", fast_stand_in)
    src = shared("Stereo_Trunks.exr")
    r = run("info", src, "--no-stats")
    assert r.exit_code == 0 and "part 0 'rgba.left'" in r.output and "part 1 'rgba.right'" in r.output
    out = tmp_path / "stereo.exr"
    r = run("denoise", src, "-o", out, "--model", tiny, "--part", "rgba.right")
    assert r.exit_code == 0, r.output
    a, b = read_layout(src)[0], read_layout(out)[0]
    assert [p.name for p in b.parts] == ["rgba.left", "rgba.right"]
    assert raw(out, 0).attrs == raw(src, 0).attrs and raw(out, 0).chunks == raw(src, 0).chunks
    assert b.parts[1].compression == a.parts[1].compression
    assert all(b.parts[1].attrs.get(k) == v for k, v in a.parts[1].attrs.items())
    before, after = read_deep(src, part=1), read_deep(out, part=1)
    assert after.data_window == before.data_window == (0, 266, 1882, 1079)
    np.testing.assert_array_equal(after.offsets, before.offsets)
    r_in, r_out = before.channel("R"), after.channel("R")
    np.testing.assert_allclose(r_out, (r_in + 0.5).astype(np.float16), rtol=0, atol=0)
    for c in ("G", "B", "A", "Z"):
        np.testing.assert_array_equal(after.channel(c), before.channel(c))
    # both eyes by default
    r = run("denoise", src, "-o", tmp_path / "both.exr", "--model", tiny)
    assert r.exit_code == 0 and "parts: part 0 'rgba.left', part 1 'rgba.right'" in r.output, r.output
    for i in (0, 1):
        np.testing.assert_array_equal(read_deep(tmp_path / "both.exr", part=i).channel("R"),
                                      (read_deep(src, part=i).channel("R") + 0.5).astype(np.float16))


def garble_offsets(src: Path, part: int) -> None:
    """Every entry of part `part`'s chunk offset table in file `src` pointed far past the file's end."""
    from ranad_core.exr.header import offset_table_span, parse_layout

    data = bytearray(src.read_bytes())
    pos, count, _ = offset_table_span(parse_layout(bytes(data), str(src)), part, str(src))
    data[pos:pos + 8 * count] = np.full(count, 1 << 62, "<u8").tobytes()
    src.write_bytes(bytes(data))


def test_a_corrupt_part_that_is_copied_fails_before_the_work(tmp_path, tiny, monkeypatch):
    """The parts a run copies as they are (here the flat 'matte') are checked before any denoising: a garbage
    offset table there used to surface only at the write, after every eye was denoised."""
    from ranad_core import shot

    src = tmp_path / "stereo.exr"
    write_stereo(src)
    garble_offsets(src, 1)
    calls = []
    real = shot._denoise_part
    monkeypatch.setattr(shot, "_denoise_part", lambda *a, **k: calls.append(1) or real(*a, **k))
    r = run("denoise", src, "-o", tmp_path / "out.exr", "--model", tiny)
    assert r.exit_code == 2 and "part 1, chunk 0 is missing" in r.output, r.output
    assert not calls and not (tmp_path / "out.exr").exists()


def test_a_corrupt_part_that_is_denoised_is_named(tmp_path, tiny):
    """A read error in one deep part of a multi-part file names that part (the file's others may be fine)."""
    src = tmp_path / "stereo.exr"
    write_stereo(src)
    garble_offsets(src, 2)
    r = run("denoise", src, "-o", tmp_path / "out.exr", "--model", tiny)
    assert r.exit_code == 2 and "part 2 'right': truncated file" in r.output, r.output
    assert not (tmp_path / "out.exr").exists()


def test_aov_of_a_multi_part_file_keeps_every_part(tmp_path, tiny):
    """`ranad aov` on the caches of a stereo file's two eyes (one cache a part) writes one multi-part output with
    both eyes' light groups denoised, each equal to that part's reconstruction alone; it wrote each part as a
    single-part file to the same path, the last eye replacing the first. An eye without the layers fails the
    run with no output."""
    from ranad_core import cache as cache_io
    from ranad_core.aov import denoise_cached_frame
    from ranad_core.model.store import load_model

    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    left, right = img.crop((0, 0, 23, 19)), img.crop((6, 4, 33, 21))
    left.header["name"], right.header["name"] = encode_string("left"), encode_string("right")
    src = tmp_path / "stereo.exr"
    with open(src, "wb") as f:
        fast.write_file(f, [fast.encode_part(left, fast.PartLayout("zips"), None, 0),
                            fast.encode_part(right, fast.PartLayout("zips"), None, 1)], multipart=True)
    r = run("denoise", src, "-o", tmp_path / "beauty.exr", "--model", tiny, "--cache", tmp_path / "cache")
    assert r.exit_code == 0, r.output
    r = run("aov", tmp_path / "cache", "--layers", "lg_*", "-o", str(tmp_path / "aov") + "/")
    assert r.exit_code == 0, r.output
    out = tmp_path / "aov" / "stereo.exr"
    assert [p.name for p in read_layout(out)[0].parts] == ["left", "right"]
    loaded = load_model(tiny)
    for name, noisy in (("left", left), ("right", right)):
        cache = tmp_path / "cache" / f"beauty.{name}.ranadcache"
        tensors, meta = cache_io.read_cache(str(cache))
        want = denoise_cached_frame(loaded, str(cache), tensors, meta, "lg_*", [str(src)])
        got = read_deep(out, part=name)
        for c in ("lg_key.R", "lg_fill.G"):
            np.testing.assert_array_equal(got.channel(c), want.channel(c).astype(np.float16).astype(np.float32))
        assert not np.array_equal(got.channel("lg_key.R"), noisy.channel("lg_key.R"))
    bare = right.select(["R", "G", "B", "A", "Z"])
    bare.header["name"] = encode_string("right")
    with open(src, "wb") as f:
        fast.write_file(f, [fast.encode_part(left, fast.PartLayout("zips"), None, 0),
                            fast.encode_part(bare, fast.PartLayout("zips"), None, 1)], multipart=True)
    r = run("denoise", src, "-o", tmp_path / "b2.exr", "--model", tiny, "--cache", tmp_path / "cache2")
    assert r.exit_code == 0, r.output
    r = run("aov", tmp_path / "cache2", "--layers", "lg_*", "-o", str(tmp_path / "aov2") + "/")
    assert r.exit_code == 2 and "no AOV layers match" in r.output and not list((tmp_path / "aov2").iterdir())
