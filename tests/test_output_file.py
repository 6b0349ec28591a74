"""Output files (issue 25): created with the umask's mode; the input's compression (none, RLE, ZIPS), tiling, line
order and attributes are kept, and the untouched channels come back bit-exact."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest

from ranad_core.exr import read_deep, read_header, write_deep
from ranad_core.exr.header import Attribute
from ranad_core.fileutil import atomic_output, new_file_mode
from ranad_core.shot import output_compression
from test_defects import tiny  # noqa: F401  (the fixture)

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"


@pytest.mark.parametrize("umask", [0o022, 0o002, 0o077])
def test_outputs_get_the_umask_mode(tmp_path, umask):
    old = os.umask(umask)
    try:
        assert new_file_mode() == 0o666 & ~umask
        with atomic_output(tmp_path / "f.bin") as tmp:
            Path(tmp).write_bytes(b"x")
        write_deep(tmp_path / "d.exr", read_deep(SHOT / "noisy_spp16.0001.exr"))
    finally:
        os.umask(old)
    for name in ("f.bin", "d.exr"):
        assert stat.S_IMODE(os.stat(tmp_path / name).st_mode) == 0o666 & ~umask, name


def test_uncompressed_input_gives_uncompressed_output(tmp_path):
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    assert output_compression(img) == "zips"
    write_deep(tmp_path / "none.exr", img, compression="none")
    plain = read_deep(tmp_path / "none.exr")
    assert output_compression(plain) == "none"
    assert read_header(tmp_path / "none.exr").parts[0].compression == 0


def test_denoise_keeps_an_uncompressed_input_uncompressed(tmp_path, tiny):
    from click.testing import CliRunner

    from ranad_cli.main import cli

    write_deep(tmp_path / "none.exr", read_deep(SHOT / "noisy_spp16.0001.exr"), compression="none")
    for name, src in (("a.exr", tmp_path / "none.exr"), ("b.exr", SHOT / "noisy_spp16.0001.exr")):
        r = CliRunner().invoke(cli, ["denoise", str(src), "-o", str(tmp_path / name), "--model", tiny])
        assert r.exit_code == 0, r.output
    assert read_header(tmp_path / "a.exr").parts[0].compression == 0          # none stays none
    assert read_header(tmp_path / "b.exr").parts[0].compression == 2          # zips stays zips


@pytest.mark.parametrize("compression,tiles,line_order", [
    ("rle", None, 0), ("rle", None, 1), ("zips", (16, 8), 0), ("none", (8, 16), 2), ("rle", (16, 16), 1),
    ("zips", None, 1)])
def test_denoise_keeps_compression_tiling_line_order_and_attributes(tmp_path, tiny, compression, tiles, line_order):
    from click.testing import CliRunner

    from ranad_cli.main import cli

    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    img.header["studio:shot"] = Attribute("string", b"sq010_sh020")
    img.header["owner"] = Attribute("string", "Weta Digital".encode())
    img.header["screenWindowWidth"] = Attribute("float", np.float32(1.5).tobytes())
    src = tmp_path / "in.exr"
    write_deep(src, img, compression=compression, tiles=tiles, line_order=line_order)
    part = read_header(src).parts[0]
    assert part.compression == {"none": 0, "rle": 1, "zips": 2}[compression]
    assert (part.tiles[:2] if tiles else None) == tiles and part.get("lineOrder") == line_order
    read_deep(src, io="oiio")                     # OpenEXR itself reads what the input writer made
    out = tmp_path / "out.exr"
    r = CliRunner().invoke(cli, ["denoise", str(src), "-o", str(out), "--model", tiny])
    assert r.exit_code == 0, r.output
    got = read_header(out).parts[0]
    assert got.compression == part.compression and got.type == part.type
    assert got.tiles == part.tiles and got.get("lineOrder") == line_order
    same = {k for k in part.attrs if k not in ("deepImageState", "maxSamplesPerPixel")}
    assert same <= set(got.attrs) and all(got.attrs[k] == part.attrs[k] for k in same), \
        [k for k in same if got.attrs.get(k) != part.attrs[k]]
    a, b = read_deep(src), read_deep(out, io="oiio")   # OpenEXR decodes the output
    np.testing.assert_array_equal(a.offsets, b.offsets)
    for name in a.ids:
        np.testing.assert_array_equal(a.ids[name], b.ids[name])
    untouched = [c for c in a.channels if c.split(".")[0] in ("albedo", "N", "emission", "motion_prev", "motion_next")]
    assert untouched
    for c in untouched:
        assert np.array_equal(a.channel(c).view(np.uint32), b.channel(c).view(np.uint32)), c
    assert not np.array_equal(a.channel("R"), b.channel("R"))


# ---- a farm's conditions: full disks, protected targets, SIGTERM, long and odd paths ----------------------------
def test_a_write_the_machine_refuses_is_one_line_naming_the_output(tmp_path):
    """A full disk (or a read-only file system, a protected target) was an internal error from whichever library
    wrote (OSError, safetensors' SafetensorError, torch's RuntimeError), or named the temporary file: now one
    RanadError naming the output, and no temporary left."""
    import errno

    from ranad_core.errors import RanadError

    class LibraryError(Exception):   # how safetensors reports it: the system's message inside its own
        pass

    for exc in (OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)),
                LibraryError(f"Error while serializing: I/O error: {os.strerror(errno.ENOSPC)} (os error 28)")):
        with pytest.raises(RanadError) as e:
            with atomic_output(tmp_path / "out.exr") as tmp:
                Path(tmp).write_bytes(b"partial")
                raise exc
        assert e.value.path == str(tmp_path / "out.exr") and e.value.problem == "cannot write (No space left on " \
                                                                                  "device)"
        assert os.listdir(tmp_path) == []
    with pytest.raises(ZeroDivisionError):   # anything else is no writing trouble and passes unchanged
        with atomic_output(tmp_path / "out.exr"):
            raise ZeroDivisionError


def test_sigterm_leaves_no_temporary(tmp_path):
    """SIGTERM (a farm stopping a job) ended the process on the spot, leaving `.name.XXXX.tmp` files beside the
    outputs; ranad's handler raises fileutil.Terminated, so every atomic_output on the way out cleans up, and the
    CLI says 'terminated' with exit 143."""
    import signal
    import subprocess
    import sys

    script = (
        "import os, signal, sys\n"
        "from pathlib import Path\n"
        "from ranad_cli.main import _terminate\n"
        "from ranad_core.fileutil import atomic_output, Terminated\n"
        "signal.signal(signal.SIGTERM, _terminate)\n"
        "try:\n"
        f"    with atomic_output({str(tmp_path / 'out.exr')!r}) as tmp:\n"
        "        Path(tmp).write_bytes(b'half')\n"
        "        os.kill(os.getpid(), signal.SIGTERM)\n"
        "        signal.pause()\n"
        "except Terminated:\n"
        "    sys.exit(7)\n")
    root = str(Path(__file__).resolve().parents[1])
    r = subprocess.run([sys.executable, "-c", script], env=dict(os.environ, PYTHONPATH=root), timeout=120)
    assert r.returncode == 7 and os.listdir(tmp_path) == []
    from click.testing import CliRunner

    import ranad_cli.cmd_info as cmd_info
    from ranad_cli.main import cli
    from ranad_core.fileutil import Terminated

    def stopped(*a, **k):
        raise Terminated()

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cmd_info, "describe", stopped)
        res = CliRunner().invoke(cli, ["info", str(SHOT / "noisy_spp16.0001.exr")])
    assert res.exit_code == 128 + signal.SIGTERM and res.output.strip() == "ranad: terminated"


def test_long_names_and_dotdot_paths(tmp_path):
    """A 250-byte output name (legal) was refused after the work (the temporary's name is longer); a name over
    the folder's limit is refused before any work; 'missing/../x.exr' was an internal error at the rename."""
    from ranad_core.errors import RanadError
    from ranad_core.fileutil import check_writable_target

    long = tmp_path / ("n" * 246 + ".exr")
    with atomic_output(long) as tmp:
        Path(tmp).write_bytes(b"x")
    assert long.read_bytes() == b"x"
    with pytest.raises(RanadError, match="file name longer than the 255 bytes"):
        check_writable_target(tmp_path / ("n" * 256 + ".exr"))
    with atomic_output(str(tmp_path / "missing" / ".." / "x.exr")) as tmp:
        Path(tmp).write_bytes(b"y")
    assert (tmp_path / "x.exr").read_bytes() == b"y"


def test_a_preview_is_not_written_to_a_full_disk(tmp_path, monkeypatch):
    """OIIO's PNG writer reported nothing on a full disk (a truncated PNG, exit 0) and libjpeg ended the process
    (exit 1, its temporary left): the folder's free space is checked first."""
    from ranad_core.errors import RanadError
    from ranad_core.exr.flat import write_flat

    class Full:
        f_bavail, f_frsize = 1, 4096

    monkeypatch.setattr(os, "statvfs", lambda p: Full())
    for ext in ("png", "jpg"):
        with pytest.raises(RanadError, match="no space left on device"):
            write_flat(tmp_path / f"p.{ext}", np.ones((64, 64, 3), np.float32), ["R", "G", "B"], (0, 0, 63, 63))
    assert os.listdir(tmp_path) == []
