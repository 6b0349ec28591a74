"""The command line, through click's CliRunner and as a real subprocess (exit codes, one-line errors)."""

from __future__ import annotations

import json
import os
import re
import shutil
import stat
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from deep_factory import random_deep, write_bad_compression, write_corrupt_chunk
from ranad_cli.main import cli
from ranad_core import __version__
from ranad_core.exr import write_deep
from ranad_core.exr.flat import read_flat
from real_data import bundled, bundled_deep_files, shared, write_small_flat

OBJECTID = bundled("objectid.deep.exr")


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
    r = run("info", bundled("openexrid_sample_motionblur_transparency.exr"))
    assert r.exit_code == 0 and "deep-OID" in r.output  # Guerilla's openexrid: one bin per object id


def test_info_json_multipart():
    r = run("info", "--json", shared("Stereo_Trunks.exr"))
    assert r.exit_code == 0
    d = json.loads(r.output)[0]
    assert d["multipart"] and [p["name"] for p in d["parts"]] == ["rgba.left", "rgba.right"]
    left = d["parts"][0]
    assert left["resolution"] == [1920, 814] and left["data_window"] == [0, 266, 1919, 1079]
    assert left["channels"]["Z"] == "float" and left["kind_guess"] == "deep-Z"
    assert left["bins_per_pixel"]["max"] == 2 and 0 < left["empty_pixels"] < 1


def test_info_sequence_and_kind(tmp_path):
    """Frames built to be of a known kind: ids unique within every pixel (deep-OID), the same ids with one
    pixel's two bins sharing an id (deep-Z), no ids (deep-Z); ZBack beyond Z on one bin makes volume samples."""
    img = random_deep(width=8, height=6, ids=(), channels=("R", "G", "B", "A", "Z", "ZBack"))
    zb = img.channels.index("ZBack")
    vals = img.values.copy()
    vals[:, zb] = vals[:, img.channels.index("Z")]                 # point samples
    points = img.with_values(vals)
    oid = points.with_values(points.values)
    oid.ids = {"id": np.arange(img.num_bins, dtype=np.uint32)}     # every bin its own object
    deepz = oid.with_values(oid.values)
    p = int(np.flatnonzero(img.counts >= 2)[0])
    ids = oid.ids["id"].copy()
    ids[img.offsets[p] + 1] = ids[img.offsets[p]]                   # one object owns two depth bins of pixel p
    deepz.ids = {"id": ids}
    vals = vals.copy()
    vals[img.offsets[p], zb] += 0.5
    volume = oid.with_values(vals)
    volume.ids = dict(oid.ids)
    frames = {1001: oid, 1002: deepz, 1003: points, 1004: volume}
    for f, im in frames.items():
        write_deep(tmp_path / f"shot.{f:04d}.exr", im)
    r = run("info", "--json", str(tmp_path / "shot.####.exr"))
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    assert [os.path.basename(x["file"]) for x in d] == [f"shot.{f}.exr" for f in frames]
    got = [(x["parts"][0]["kind_guess"], x["parts"][0]["volume_samples"]) for x in d]
    assert got == [("deep-OID", False), ("deep-Z", False), ("deep-Z", False), ("deep-OID", True)]
    r = run("info", "--json", "--frames", "1001-1003x2", str(tmp_path / "shot.####.exr"))
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    assert [os.path.basename(x["file"]) for x in d] == ["shot.1001.exr", "shot.1003.exr"]
    r = run("info", str(tmp_path / "shot.1002.exr"), str(tmp_path / "shot.1004.exr"))
    assert r.exit_code == 0 and r.output.count("deep-Z (guess)") == 1 and r.output.count("deep-OID (guess)") == 1
    assert r.output.count("volume samples: yes") == 1 and r.output.count("volume samples: no") == 1


def _kind_by_openimageio(path):
    """deep-Z vs deep-OID computed from OpenImageIO's own reading of the file: deep-OID when the object id
    channel ('id'/'Id', else the first uint channel) never repeats within a pixel; no id channel: deep-Z."""
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(path))
    spec, dd = buf.spec(), buf.deepdata()
    names = list(spec.channelnames)
    uints = [n for i, n in enumerate(names) if str(spec.channelformat(i)) == "uint"]
    idc = next((n for n in ("id", "Id") if n in names), uints[0] if uints else None)
    if idc is None:
        return "deep-Z"
    j = names.index(idc)
    for p in range(dd.pixels):
        ids = [dd.deep_value_uint(p, j, s) for s in range(dd.samples(p))]
        if len(set(ids)) < len(ids):
            return "deep-Z"
    return "deep-OID"


KNOWN_KINDS = {"objectid.deep.exr": "deep-Z", "openexr_test_11.deep.exr": "deep-OID",
               "openexr_test_42.deep.exr": "deep-Z", "LowResLeftView_Trunks.exr": "deep-Z",   # no ids
               "openexrid_sample_motionblur_transparency.exr": "deep-OID"}                  # openexrid: by design


@pytest.mark.parametrize("path", bundled_deep_files(), ids=os.path.basename)
def test_info_kind_of_real_files(path):
    r = run("info", "--json", path)
    assert r.exit_code == 0, r.output
    kind = json.loads(r.output)[0]["parts"][0]["kind_guess"]
    assert kind == KNOWN_KINDS[os.path.basename(path)] == _kind_by_openimageio(path)


def test_info_flat_file_is_described(tmp_path):
    r = run("info", write_small_flat(tmp_path / "flat.exr"))
    assert r.exit_code == 0 and "flat image (not deep)" in r.output and "8x6" in r.output


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


def test_flatten_replaces_nonfinite_values_as_denoise_does(tmp_path):
    """A Z of -inf made NaN pixels (the tidy step's volume split divides by it) with exit 0 and no word; now the
    one NaN/Inf policy (deep.replace_nonfinite) applies, with a warning: the output is finite and equals the
    flattened image with the values replaced."""
    from ranad_core.deep import flatten, replace_nonfinite

    img = random_deep(width=8, height=6, channels=("R", "G", "B", "A", "Z", "ZBack"), ids=())
    vals = img.values.copy()
    vals[::2, img.channels.index("Z")] = -np.inf
    vals[3, img.channels.index("R")] = np.nan
    bad = img.with_values(vals)
    write_deep(tmp_path / "bad.exr", bad)
    r = run("flatten", str(tmp_path / "bad.exr"), "-o", str(tmp_path / "flat.exr"), "--float")
    assert r.exit_code == 0 and "bin(s) with NaN/Inf replaced" in r.output, r.output
    pixels, channels, _, _ = read_flat(tmp_path / "flat.exr")
    assert np.isfinite(pixels).all()
    expected = flatten(replace_nonfinite(bad)[0])
    np.testing.assert_allclose(pixels, expected[..., [bad.channels.index(c) for c in channels]], rtol=1e-6)


def test_flatten_sequence_to_pattern(tmp_path):
    img = random_deep(width=8, height=6)
    for f in (1, 2, 3):
        write_deep(tmp_path / f"in.{f:04d}.exr", img)
    r = run("flatten", str(tmp_path / "in.@@@@.exr"), "-o", str(tmp_path / "out.%04d.exr"))
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in tmp_path.glob("out.*.exr")) == ["out.0001.exr", "out.0002.exr", "out.0003.exr"]


@pytest.mark.parametrize("name, data_window", [
    ("LowResLeftView_Trunks.exr", (0, 141, 1023, 575)),
    pytest.param("LowResLeftView_Balls.exr", (131, 170, 894, 575), id="LowResLeftView_Balls.exr (../shared)")])
def test_flatten_offset_data_window_matches_oiio(tmp_path, name, data_window):
    """OpenImageIO's flatten composites in file order without tidying: equal to ours with --assume-tidy,
    and equal to our default wherever a pixel has no coincident samples (which tidying merges)."""
    import OpenImageIO as oiio

    from ranad_core.exr import read_deep

    src = bundled(name) if name == "LowResLeftView_Trunks.exr" else shared(name)  # data window inside display
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
        assert dw == data_window and disp == (0, 0, 1023, 575)
        for c in ("R", "G", "B", "A"):
            np.testing.assert_allclose(pixels[..., channels.index(c)][mask], theirs[..., names.index(c)][mask],
                                       rtol=1e-5, atol=1e-6)


# ---- errors --------------------------------------------------------------------------------------------
# what each error must say (so a case cannot pass by failing for another reason, e.g. a file that is missing)
BAD_INPUT_PROBLEM = {"missing": "no such file", "not_exr": "not an EXR", "flat": "not a deep image",
                     "truncated": "truncated|cut short", "corrupt": "corrupt", "compression": "compression",
                     "directory": "directory"}


@pytest.mark.parametrize("case", list(BAD_INPUT_PROBLEM))
def test_bad_input_one_line_exit_2(tmp_path, case):
    if case == "missing":
        path = tmp_path / "nope.exr"
    elif case == "not_exr":
        path = tmp_path / "text.exr"
        path.write_text("not an image")
    elif case == "flat":
        path = write_small_flat(tmp_path / "flat.exr")
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
    assert (case == "missing") != os.path.exists(path)
    out = tmp_path / "o.png"
    for result in (CliRunner().invoke(cli, ["flatten", str(path), "-o", str(out)]),):
        assert result.exit_code == 2, result.output
        lines = result.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("ranad: error: ") and str(path) in lines[0]
        assert re.search(BAD_INPUT_PROBLEM[case], lines[0]), lines[0]
        assert "Traceback" not in result.output
    assert not out.exists()
    p = run_process("flatten", str(path), "-o", str(out))
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
    assert str(path) in p.stderr and re.search(BAD_INPUT_PROBLEM[case], p.stderr) and not out.exists()


def _assert_refused(result, target, problem):
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"ranad: error: {target}") and re.search(problem, lines[0])
    assert not os.path.exists(target)


def test_unwritable_output(tmp_path):
    target = tmp_path / "no" / "such" / "dir" / "o.exr"
    _assert_refused(CliRunner().invoke(cli, ["flatten", OBJECTID, "-o", str(target)]), target,
                    "output folder does not exist")
    p = run_process("flatten", OBJECTID, "-o", str(tmp_path / "no" / "o.png"))
    assert p.returncode == 2 and p.stderr.startswith("ranad: error:") and p.stderr.count("\n") == 1
    # a folder that is a regular file (refused for every user, root included)
    (tmp_path / "afile").write_text("x")
    target = tmp_path / "afile" / "o.png"
    _assert_refused(CliRunner().invoke(cli, ["flatten", OBJECTID, "-o", str(target)]), target, "output folder")
    assert sorted(os.listdir(tmp_path)) == ["afile"] and (tmp_path / "afile").read_text() == "x"


def test_read_only_output_folder(tmp_path):
    """A read-only folder is refused before any work and left as it was. Root ignores permission bits, so for
    root the folder is one no user can write in: sysfs or procfs, checked to refuse a file first."""
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        (ro / "keep.txt").write_text("x")
        ro.chmod(stat.S_IRUSR | stat.S_IXUSR)
        try:
            target = ro / "o.png"
            _assert_refused(CliRunner().invoke(cli, ["flatten", OBJECTID, "-o", str(target)]), target,
                            "not writable|cannot write")
            assert os.listdir(ro) == ["keep.txt"]
        finally:
            ro.chmod(stat.S_IRWXU)
        return
    for folder in ("/sys", "/proc"):
        try:
            with open(os.path.join(folder, "ranad-probe.png"), "wb"):
                pass
        except OSError:
            break
        os.remove(os.path.join(folder, "ranad-probe.png"))
    else:
        pytest.skip("running as root, and neither /sys nor /proc refuses new files here")
    target = os.path.join(folder, "o.png")
    _assert_refused(CliRunner().invoke(cli, ["flatten", OBJECTID, "-o", target]), target,
                    "not writable|cannot write")
    p = run_process("flatten", OBJECTID, "-o", target)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr


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


def test_out_of_memory_is_one_line_exit_2(monkeypatch):
    """A frame larger than the process may hold (a ulimit, a farm's cap) said 'internal error' (exit 1); it is a
    one-line error, exit 2, like other input the machine cannot take."""
    import ranad_cli.cmd_info as cmd_info

    def too_big(*a, **k):
        raise MemoryError("Unable to allocate 128. MiB for an array")

    monkeypatch.setattr(cmd_info, "describe", too_big)
    r = CliRunner().invoke(cli, ["info", OBJECTID])
    assert r.exit_code == 2 and r.output.startswith("ranad: error: out of memory (Unable to allocate 128. MiB")
    assert r.output.count("\n") == 1 and "Traceback" not in r.output


def test_io_switch_forces_openimageio(tmp_path, monkeypatch):
    from ranad_core.exr import fast

    def refuse(*a, **k):
        raise AssertionError("fast path used despite --io oiio")

    monkeypatch.setattr(fast, "read_part", refuse)
    r = run("--io", "oiio", "info", "--json", bundled("openexr_test_11.deep.exr"))
    assert r.exit_code == 0 and json.loads(r.output)[0]["parts"][0]["bins"] == 6056
    from ranad_core import exr

    exr.set_io_mode("auto")


def test_a_command_through_openimageio_ends_without_noise(tmp_path):
    """A real process that read through OpenImageIO prints its result and nothing at shutdown: the interpreter's
    last collection must reach OpenImageIO's binding objects, else nanobind lists them as 'leaked' on stderr (some
    60 lines, seen when the script froze the collector at exit to save 0.3 s)."""
    p = run_process("--io", "oiio", "flatten", bundled("openexr_test_11.deep.exr"), "-o", str(tmp_path / "f.exr"))
    assert p.returncode == 0, p.stderr
    assert "leaked" not in p.stderr and "nanobind" not in p.stderr, p.stderr[-2000:]
    assert (tmp_path / "f.exr").exists()


def test_never_overwrites_input(tmp_path):
    src = tmp_path / "in.exr"
    shutil.copy(OBJECTID, src)
    before = src.read_bytes()
    r = CliRunner().invoke(cli, ["flatten", str(src), "-o", str(src)])
    assert r.exit_code == 2 and src.read_bytes() == before


HELP_MUST_SAY = {
    (): ["--io [auto|oiio|fast]", "--debug", "--version"],
    ("info",): ["INPUTS...", "--frames", "--json", "--no-stats", "deep-Z vs deep-", "bins per pixel"],
    ("flatten",): ["INPUTS...", "-o, --output", "[required]", "--frames", "--part", "--exposure", "--float", ".png"],
    ("denoise",): ["INPUTS...", "-o, --output", "[required]", "--frames", "--model", "--device [auto|cpu|cuda]",
                   "--threads", "--kind [auto|deepz|deepoid]", "--map LAYER=CHANNELS", "--keep-noisy", "--tile",
                   "--halo", "--max-memory", "[default: 8G]", "--cache", "--skip-existing", "--shard I/N",
                   "--strict", "--window", "--aovs", "--reference PATTERN"],
    ("aov",): ["CACHE", "--layers", "-o, --output"],
    ("eval",): ["DATASET", "-o, --out", "--model", "--spp", "--temporal", "--cross-model"],
    ("train",): ["DATASETS...", "-o, --run", "--config", "--steps", "--processes"],
    ("synth",): ["-o, --out", "--scenes", "--size", "--spp", "--ref-spp"],
    ("export",): ["RUN", "-o, --out", "--note KEY=VALUE"],
}


def test_help_texts():
    """Every command's help runs and names its options; the top level lists every command and the version."""
    def run(*args):
        return CliRunner().invoke(cli, list(args), prog_name="ranad", catch_exceptions=False)

    top = run("--help")
    assert top.exit_code == 0 and top.output.startswith("Usage: ranad [OPTIONS] COMMAND")
    listed = top.output.split("\nCommands:\n")[-1]
    assert sorted(line.split()[0] for line in listed.strip().splitlines()) == sorted(
        cmd[0] for cmd in HELP_MUST_SAY if cmd)
    for cmd, phrases in HELP_MUST_SAY.items():
        r = run(*cmd, "--help")
        assert r.exit_code == 0 and r.output.startswith(f"Usage: {' '.join(('ranad',) + cmd)} "), r.output
        text = " ".join(r.output.split())      # click wraps lines
        missing = [p for p in phrases if p not in text]
        assert not missing, (cmd, missing)
    r = run("--version")
    assert r.exit_code == 0 and r.output.strip() == f"ranad, version {__version__}"
    r = run("no-such-command")
    assert r.exit_code == 2 and "No such command" in r.output


@pytest.mark.parametrize("args", [
    ("denoise", "--max-memory", "."), ("denoise", "--max-memory", "1.2.3"), ("denoise", "--threads", "99999"),
    ("denoise", "--bin-merge", "nan"), ("denoise", "--window", "2"), ("flatten", "--exposure", "nan"),
    ("flatten", "--exposure", "1e308")], ids=lambda a: " ".join(a))
def test_bad_option_values_are_usage_errors(tmp_path, args):
    """Values that crashed (internal error: float('.'), a thread per 99999, 2^1e308) or were taken silently (NaN
    through click's FloatRange, an even window that ran as the odd one below it): usage errors, exit 2."""
    cmd, *opt = args
    out = tmp_path / ("o.png" if cmd == "flatten" else "o.exr")
    r = run(cmd, str(OBJECTID), "-o", str(out), *opt)
    assert r.exit_code == 2 and "Invalid value" in r.output and "internal error" not in r.output, r.output
    assert not out.exists()


def test_a_closed_pipe_is_no_internal_error():
    """`ranad info F | head -2`: the reader goes away before ranad writes; that was 'internal error:
    BrokenPipeError' on stderr. Now quiet (exit 1, as a cut-off command), with no traceback at exit either."""
    root = os.path.join(os.path.dirname(__file__), "..")
    env = dict(os.environ, PYTHONPATH=os.path.abspath(root))
    p = subprocess.Popen([sys.executable, "-m", "ranad_cli", "info", str(OBJECTID)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, env=env)
    p.stdout.close()   # before the first write: every write meets a closed pipe
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 1 and "internal error" not in err and "Traceback" not in err, err
