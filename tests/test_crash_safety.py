"""Crash safety (issue 26): `ranad denoise` killed with SIGKILL in the middle of a shot leaves only complete
frames; a rerun with --skip-existing completes the shot, and every frame equals an uninterrupted run's."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ranad_core.exr import read_deep

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"


def _shot(tmp: Path, frames: int = 6) -> Path:
    """A longer shot made of the example's frames (renumbered), so a kill lands mid-shot."""
    src = tmp / "in"
    src.mkdir()
    for f in range(frames):
        shutil.copy(SHOT / f"noisy_spp16.{f % 3:04d}.exr", src / f"noisy.{f:04d}.exr")
    return src


def _denoise(src: Path, out: Path, *extra) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "ranad_cli", "denoise", str(src / "noisy.####.exr"), "-o", str(out / "o.####.exr"),
           "--model", "cpu-small-p-v1", "--threads", "1", *extra]
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            cwd=Path(__file__).resolve().parents[1])


def test_sigkill_mid_shot_then_skip_existing_equals_an_uninterrupted_run(tmp_path):
    src = _shot(tmp_path)
    full, cut = tmp_path / "full", tmp_path / "cut"
    full.mkdir()
    cut.mkdir()
    assert _denoise(src, full).wait(timeout=600) == 0
    proc = _denoise(src, cut)
    deadline = time.time() + 600
    while time.time() < deadline and not list(cut.glob("o.*.exr")):  # the first frame is written...
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)                                     # ...then the process dies at once
    proc.wait(timeout=60)
    done = sorted(p.name for p in cut.glob("o.*.exr"))
    assert 1 <= len(done) < 6, done                                      # killed in the middle of the shot
    for p in cut.glob("o.*.exr"):                                        # what is there is complete
        read_deep(p)
    for p in cut.iterdir():                                              # (half-written temporaries aside)
        assert p.name.startswith(".") or p.name.startswith("o.")
    assert _denoise(src, cut, "--skip-existing").wait(timeout=600) == 0
    names = sorted(p.name for p in full.glob("o.*.exr"))
    assert names == sorted(p.name for p in cut.glob("o.*.exr")) and len(names) == 6
    for name in names:
        a, b = read_deep(full / name), read_deep(cut / name)
        assert a.channels == b.channels
        np.testing.assert_array_equal(a.offsets, b.offsets)
        np.testing.assert_array_equal(a.values, b.values)
