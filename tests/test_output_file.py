"""Output files (issue 25): created with the umask's mode, and an uncompressed input stays uncompressed."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from ranad_core.exr import read_deep, read_header, write_deep
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
