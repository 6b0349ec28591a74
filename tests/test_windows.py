"""Sequences whose data windows differ from frame to frame (auto-cropped deep renders, issue 25): each frame is
denoised and written at its own window, and motion compensation works in display coordinates."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core.channels import MotionSpec
from ranad_core.exr import read_deep, write_deep
from ranad_core.motion import compensate

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"
#: per frame of the example shot (48x48 display window): auto-crop-like data windows, all different
WINDOWS = [(2, 1, 40, 44), (5, 3, 47, 47), (0, 0, 38, 40)]


def cropped_shot():
    return [read_deep(SHOT / f"noisy_spp16.{f:04d}.exr").crop(w) for f, w in enumerate(WINDOWS)]


def same(a, b):
    assert a.data_window == b.data_window
    np.testing.assert_array_equal(a.offsets, b.offsets)
    np.testing.assert_array_equal(a.values, b.values)
    for k in a.ids:
        np.testing.assert_array_equal(a.ids[k], b.ids[k])


def test_compensation_with_shifted_windows_equals_compensation_padded_to_a_common_window():
    frames = cropped_shot()
    spec = MotionSpec.canonical()
    for centre in (0, 1, 2):
        moved, dropped = compensate(frames, centre, motion=spec)
        common = (-4, -4, 51, 51)
        padded, _ = compensate([f.crop(common) for f in frames], centre, motion=spec)
        target = WINDOWS[centre]
        for k, (m, p) in enumerate(zip(moved, padded)):
            assert m.data_window == target
            same(m, p.crop(target))
        assert dropped > 0                                        # neighbours' bins outside the centre's window
    # placed by their offsets, not by their first pixels: treating every window as starting at (0, 0) differs
    naive = [f.crop((f.data_window[0], f.data_window[1], f.data_window[0] + 35, f.data_window[1] + 37))
             for f in frames]
    for f in naive:
        f.data_window = (0, 0, 35, 37)
    a, _ = compensate(naive, 1, motion=spec)
    b, _ = compensate(frames, 1, motion=spec)
    assert not np.array_equal(a[0].crop((0, 0, 35, 37)).offsets, b[0].crop((5, 3, 40, 40)).offsets)


def test_shot_with_per_frame_windows_denoises_each_frame_at_its_window(tmp_path):
    import torch
    from safetensors.torch import save_file

    from ranad_core.model import RaNAD, feature_dim
    from ranad_core.model.config import get_config
    from ranad_core.model.crossframe import CrossFrameRaNAD

    torch.manual_seed(0)
    single = RaNAD(get_config("cpu-small"), feature_dim()).eval()
    cross = CrossFrameRaNAD.from_single(single, get_config("cpu-small-xf"), feature_dim()).eval()
    model = tmp_path / "xf.safetensors"
    save_file({k: v.contiguous() for k, v in cross.state_dict().items()}, str(model),
              metadata={"model_config": json.dumps(cross.config.to_dict())})
    src = tmp_path / "in"
    src.mkdir()
    frames = cropped_shot()
    for f, img in enumerate(frames):
        write_deep(src / f"b.{f:04d}.exr", img)
    r = CliRunner().invoke(cli, ["denoise", str(src / "b.####.exr"), "-o", str(tmp_path / "d.####.exr"),
                                 "--model", str(model)])
    assert r.exit_code == 0, r.output
    assert "denoised 3 frame(s)" in r.output and "WITHOUT motion" not in r.output
    for f, img in enumerate(frames):
        out = read_deep(tmp_path / f"d.{f:04d}.exr")
        assert out.data_window == img.data_window and out.display_window == img.display_window
        np.testing.assert_array_equal(out.offsets, img.offsets)
    # the neighbours were used: the centre frame differs from the one denoised alone
    r = CliRunner().invoke(cli, ["denoise", str(src / "b.0001.exr"), "-o", str(tmp_path / "alone.exr"),
                                 "--model", str(model), "--window", "1"])
    assert r.exit_code == 0, r.output
    assert not np.array_equal(read_deep(tmp_path / "alone.exr").values, read_deep(tmp_path / "d.0001.exr").values)


def test_display_windows_must_match(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    for f, img in enumerate(cropped_shot()):
        if f == 2:
            img.display_window = (0, 0, 63, 47)
        write_deep(src / f"b.{f:04d}.exr", img)
    r = CliRunner().invoke(cli, ["denoise", str(src / "b.####.exr"), "-o", str(tmp_path / "d.####.exr"),
                                 "--model", "cpu-small-v1"])
    assert r.exit_code == 2 and "display window (0, 0, 63, 47) differs from (0, 0, 47, 47)" in r.output
    assert "b.0002.exr" in r.output and r.output.count("\n") == 1
