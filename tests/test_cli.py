"""The command line, through click's CliRunner and as a real subprocess (exit codes, one-line errors)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from deep_factory import random_deep, write_bad_compression, write_corrupt_chunk
from ranad_cli.main import cli
from ranad_core.exr import read_deep, write_deep
from ranad_core.exr.flat import read_flat

REAL = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "deep-real")
OBJECTID = os.path.join(REAL, "openexr_test_objectid.deep.exr")
STEREO = os.path.join(REAL, "Stereo_Trunks.exr")
FLAT = os.path.join(REAL, "LowResLeftView_composited.exr")


def run(*args):
    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


def run_process(*args, cwd=None):
    exe = [sys.executable, "-m", "ranad_cli"]
    root = os.path.join(os.path.dirname(__file__), "..")
    env = dict(os.environ, PYTHONPATH=os.path.abspath(root))
    return subprocess.run(exe + list(args), capture_output=True, text=True, cwd=cwd, env=env)


# ---- info ---------------------------------------------------------------------------------------------
def test_info_text():
    r = run("info", OBJECTID)
    assert r.exit_code == 0, r.output
    assert "256x256" in r.output and "id channels: id, particleid" in r.output
    assert "deepImageState: tidy" in r.output and "id manifest: yes" in r.output
    assert "deep-Z" in r.output  # some pixels hold several depth bins of one object
    r = run("info", os.path.join(REAL, "openexrid_sample_motionblur_transparency.exr"))
    assert r.exit_code == 0 and "deep-OID" in r.output  # Guerilla's openexrid: one bin per object id


def test_info_json_multipart():
    r = run("info", "--json", STEREO)
    assert r.exit_code == 0
    d = json.loads(r.output)[0]
    assert d["multipart"] and [p["name"] for p in d["parts"]] == ["rgba.left", "rgba.right"]
    left = d["parts"][0]
    assert left["resolution"] == [1920, 814] and left["data_window"] == [0, 266, 1919, 1079]
    assert left["channels"]["Z"] == "float" and left["kind_guess"] == "deep-Z"
    assert left["bins_per_pixel"]["max"] == 2 and 0 < left["empty_pixels"] < 1


def test_info_sequence_and_kind(tmp_path):
    img = random_deep(width=8, height=6, ids=("id",))
    for f in (1001, 1002, 1003):
        write_deep(tmp_path / f"shot.{f:04d}.exr", img)
    r = run("info", "--json", "--frames", "1001-1003x2", str(tmp_path / "shot.####.exr"))
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    assert [os.path.basename(x["file"]) for x in d] == ["shot.1001.exr", "shot.1003.exr"]
    assert d[0]["parts"][0]["volume_samples"] in (True, False)


def test_info_flat_file_is_described():
    r = run("info", FLAT)
    assert r.exit_code == 0 and "flat image (not deep)" in r.output


# ---- flatten -------------------------------------------------------------------------------------------
def test_flatten_exr_and_png(tmp_path):
    out = tmp_path / "flat.exr"
    r = run("flatten", OBJECTID, "-o", str(out))
    assert r.exit_code == 0, r.output
    pixels, channels, dw, _ = read_flat(out)
    assert {"R", "G", "B", "A", "Z"} <= set(channels) and pixels.shape[:2] == (256, 256)
    a = pixels[..., channels.index("A")]
    assert 0.0 <= a.min() and a.max() <= 1.0 + 1e-3 and a.max() > 0.5
    r = run("flatten", OBJECTID, "-o", str(tmp_path / "flat.png"), "--exposure", "1")
    assert r.exit_code == 0 and (tmp_path / "flat.png").stat().st_size > 0


def test_flatten_sequence_to_pattern(tmp_path):
    img = random_deep(width=8, height=6)
    for f in (1, 2, 3):
        write_deep(tmp_path / f"in.{f:04d}.exr", img)
    r = run("flatten", str(tmp_path / "in.@@@@.exr"), "-o", str(tmp_path / "out.%04d.exr"))
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in tmp_path.glob("out.*.exr")) == ["out.0001.exr", "out.0002.exr", "out.0003.exr"]


def test_flatten_offset_data_window_matches_oiio(tmp_path):
    """OpenImageIO's flatten composites in file order without tidying: equal to ours with --assume-tidy,
    and equal to our default wherever a pixel has no coincident samples (which tidying merges)."""
    import OpenImageIO as oiio

    src = os.path.join(REAL, "LowResLeftView_Balls.exr")  # data window inside the display window
    buf = oiio.ImageBufAlgo.flatten(oiio.ImageBuf(src))
    theirs = buf.get_pixels(oiio.FLOAT)
    names = list(buf.spec().channelnames)
    deep = read_deep(src)
    z = deep.channel("Z")
    same = np.zeros(deep.num_bins, dtype=bool)
    same[1:] = (z[1:] == z[:-1]) & (deep.pixel_index()[1:] == deep.pixel_index()[:-1])
    coincident = np.zeros(deep.num_pixels, dtype=bool)
    coincident[deep.pixel_index()[same]] = True
    coincident = coincident.reshape(deep.height, deep.width)
    assert coincident.any() and not coincident.all()
    for flags, mask in ((["--assume-tidy"], np.ones_like(coincident)), ([], ~coincident)):
        r = run("flatten", src, "-o", str(tmp_path / "b.exr"), "--float", *flags)
        assert r.exit_code == 0, r.output
        pixels, channels, dw, disp = read_flat(tmp_path / "b.exr")
        assert dw == (131, 170, 894, 575) and disp == (0, 0, 1023, 575)
        for c in ("R", "G", "B", "A"):
            np.testing.assert_allclose(pixels[..., channels.index(c)][mask], theirs[..., names.index(c)][mask],
                                       rtol=1e-5, atol=1e-6)


# ---- errors --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("case", ["missing", "not_exr", "flat", "truncated", "corrupt", "compression",
                                  "directory"])
def test_bad_input_one_line_exit_2(tmp_path, case):
    if case == "missing":
        path = tmp_path / "nope.exr"
    elif case == "not_exr":
        path = tmp_path / "text.exr"
        path.write_text("not an image")
    elif case == "flat":
        path = FLAT
    elif case == "truncated":
        path = tmp_path / "cut.exr"
        data = open(OBJECTID, "rb").read()
        path.write_bytes(data[: len(data) // 2])
    elif case == "corrupt":
        path = tmp_path / "corrupt.exr"
        write_corrupt_chunk(OBJECTID, path)
    elif case == "compression":
        path = tmp_path / "badcomp.exr"
        write_bad_compression(OBJECTID, path)
    else:
        path = tmp_path
    out = tmp_path / "o.png"
    for result in (CliRunner().invoke(cli, ["flatten", str(path), "-o", str(out)]),):
        assert result.exit_code == 2, result.output
        lines = result.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("ranad: error: ") and str(path) in lines[0]
        assert "Traceback" not in result.output
    assert not out.exists()
    p = run_process("flatten", str(path), "-o", str(out))
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
    assert str(path) in p.stderr and not out.exists()


def test_unwritable_output(tmp_path):
    target = tmp_path / "no" / "such" / "dir" / "o.exr"
    r = CliRunner().invoke(cli, ["flatten", OBJECTID, "-o", str(target)])
    assert r.exit_code == 2 and "output folder does not exist" in r.output
    ro = tmp_path / "ro"
    ro.mkdir()
    (ro / "keep.txt").write_text("x")
    p = run_process("flatten", OBJECTID, "-o", str(tmp_path / "no" / "o.png"))
    assert p.returncode == 2 and "ranad: error:" in p.stderr
    assert sorted(os.listdir(tmp_path)) == ["ro"]


def test_missing_frame_is_named(tmp_path):
    img = random_deep(width=4, height=3)
    for f in (1, 2, 4):
        write_deep(tmp_path / f"s.{f:04d}.exr", img)
    r = CliRunner().invoke(cli, ["info", str(tmp_path / "s.####.exr"), "--frames", "1-4"])
    assert r.exit_code == 2 and "frame 3 is missing" in r.output and "s.0003.exr" in r.output


def test_debug_shows_traceback(tmp_path):
    p = run_process("--debug", "info", str(tmp_path / "nope.exr"))
    assert p.returncode == 2 and "Traceback" in p.stderr


def test_internal_error_exit_1(monkeypatch, tmp_path):
    import ranad_cli.cmd_info as cmd_info

    def boom(*a, **k):
        raise ZeroDivisionError("oops")

    monkeypatch.setattr(cmd_info, "describe", boom)
    r = CliRunner().invoke(cli, ["info", OBJECTID])
    assert r.exit_code == 1 and "internal error" in r.output and "Traceback" not in r.output


def test_io_switch_forces_openimageio(tmp_path, monkeypatch):
    from ranad_core.exr import fast

    def refuse(*a, **k):
        raise AssertionError("fast path used despite --io oiio")

    monkeypatch.setattr(fast, "read_part", refuse)
    r = run("--io", "oiio", "info", "--json", os.path.join(REAL, "openexr_test_11.deep.exr"))
    assert r.exit_code == 0 and json.loads(r.output)[0]["parts"][0]["bins"] == 6056
    from ranad_core import exr

    exr.set_io_mode("auto")


def test_never_overwrites_input(tmp_path):
    src = tmp_path / "in.exr"
    shutil.copy(OBJECTID, src)
    before = src.read_bytes()
    r = CliRunner().invoke(cli, ["flatten", str(src), "-o", str(src)])
    assert r.exit_code == 2 and src.read_bytes() == before


def test_help_texts():
    for cmd in ([], ["info"], ["flatten"]):
        r = run(*cmd, "--help")
        assert r.exit_code == 0 and "Usage:" in r.output
    assert read_deep  # imported for API completeness
