"""Per-pixel flow from flat EXR sequences (`ranad denoise --flow`, issue 25): a shot whose motion comes from flow
files is compensated (and denoised) exactly like the same shot with the equivalent per-bin vectors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core.channels import CANONICAL_MOTION, MotionSpec
from ranad_core.errors import RanadError
from ranad_core.exr import read_deep, write_deep
from ranad_core.exr.flat import write_flat
from ranad_core.flow import flow_channels, read_flow
from ranad_core.motion import compensate

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"


def field(f: int, direction: str) -> np.ndarray:
    """A smooth per-pixel motion field [48, 48, 2] (pixels, x right, y down), different per frame and direction."""
    y, x = np.mgrid[0:48, 0:48].astype(np.float32)
    sign = -1.0 if direction == "prev" else 1.0
    return np.stack([sign * (1.3 + 0.04 * x + 0.2 * f), sign * (-0.6 + 0.03 * y)], -1).astype(np.float32)


def bare(f: int):
    img = read_deep(SHOT / f"noisy_spp16.{f:04d}.exr")
    return img.select([c for c in img.channels if not c.startswith("motion_")])


def with_vectors(img, fields: dict):
    """`img` with per-bin motion channels holding its pixel's field (float channels, so files keep them)."""
    names, cols = list(img.channels), [img.values]
    for direction, fl in fields.items():
        chans = CANONICAL_MOTION[f"motion_{direction}"]
        cols.append(fl.reshape(-1, 2)[img.pixel_index()])
        names += list(chans)
    out = img.with_values(np.concatenate(cols, 1), names)
    for c in names[len(img.channels):]:
        out.channel_types[c] = "float"
    return out


def flows_of(fields: dict) -> np.ndarray:
    out = np.full((48, 48, 4), np.nan, np.float32)
    for direction, fl in fields.items():
        out[..., (0 if direction == "prev" else 2):][..., :2] = fl
    return out


@pytest.mark.parametrize("directions", [("prev", "next"), ("prev",), ("next",)])
def test_flow_compensates_like_equivalent_per_bin_vectors(directions):
    spec = MotionSpec.canonical()
    fields = [{d: field(f, d) for d in directions} for f in range(3)]
    vec_frames = [with_vectors(bare(f), fields[f]) for f in range(3)]
    flow_frames = [bare(f) for f in range(3)]
    flows = [flows_of(fl) for fl in fields]
    for centre in (0, 1, 2):
        a, da = compensate(vec_frames, centre, motion=spec)
        b, db = compensate(flow_frames, centre, flows=flows, motion=spec)
        assert da == db
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x.offsets, y.offsets)
            np.testing.assert_array_equal(x.select(y.channels).values, y.values)
        unaligned, _ = compensate(flow_frames, centre, motion=spec)
        assert any(not np.array_equal(u.offsets, y.offsets) for u, y in zip(unaligned, b))   # the flow moved bins


def test_read_flow_places_converts_and_picks_channels(tmp_path):
    img = read_deep(SHOT / "noisy_spp16.0001.exr").crop((4, 2, 40, 45))
    fl = field(1, "next")
    path = tmp_path / "flow.exr"
    write_flat(path, fl[:40, :44], ["mv.u", "mv.v"], data_window=(0, 0, 43, 39), display_window=(0, 0, 47, 47),
               dtype="float")
    got = read_flow(str(path), img, "next")
    assert got.shape == (44, 37, 4) and np.isnan(got[..., :2]).all()
    np.testing.assert_array_equal(got[:38, :, 2:], fl[2:40, 4:41])          # display coordinates
    assert np.isnan(got[38:, :, 2:]).all()                                  # rows the flow file does not cover
    up = read_flow(str(path), img, "next", overrides={"motion": {"units": "ndc", "y": "up"}})
    np.testing.assert_allclose(up[:38, :, 2], fl[2:40, 4:41, 0] * 48, rtol=1e-6)
    np.testing.assert_allclose(up[:38, :, 3], -fl[2:40, 4:41, 1] * 48, rtol=1e-6)
    assert flow_channels(["A", "mv.u", "mv.v"], None, "f") == ("mv.u", "mv.v")
    assert flow_channels(["R", "G", "B", "mv.u", "mv.v"], ("mv.u", "mv.v"), "f") == ("mv.u", "mv.v")
    with pytest.raises(RanadError, match="2 candidate x/y channel pairs"):
        flow_channels(["R", "G", "B", "mv.u", "mv.v"], None, "f")


def test_denoise_with_flow_files_equals_denoise_with_per_bin_vectors(tmp_path):
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
    for d in ("vec", "bare", "flow"):
        (tmp_path / d).mkdir()
    for f in range(3):
        fl = field(f, "prev")
        write_deep(tmp_path / "vec" / f"b.{f:04d}.exr", with_vectors(bare(f), {"prev": fl}))
        write_deep(tmp_path / "bare" / f"b.{f:04d}.exr", bare(f))
        write_flat(tmp_path / "flow" / f"mv.{f:04d}.exr", fl, ["X", "Y"], data_window=(0, 0, 47, 47), dtype="float")

    def denoise(src, out, *extra):
        r = CliRunner().invoke(cli, ["denoise", str(tmp_path / src / "b.####.exr"), "-o", str(tmp_path / out),
                                     "--model", str(model), *extra])
        assert r.exit_code == 0, r.output
        return r.output

    denoise("vec", "a/d.####.exr")
    log = denoise("bare", "b/d.####.exr", "--flow", str(tmp_path / "flow" / "mv.####.exr"), "--flow-direction", "prev")
    assert "WITHOUT motion" not in log and "per-pixel flow" in log
    log = denoise("bare", "c/d.####.exr")
    assert "WITHOUT motion" in log
    for f in range(3):
        a, b, c = (read_deep(tmp_path / d / f"d.{f:04d}.exr") for d in "abc")
        np.testing.assert_array_equal(a.select(b.channels).values, b.values)
        if f == 1:
            assert not np.array_equal(b.values, c.values)        # the flow changed what the model saw

    for extra, problem in ((["--flow", str(tmp_path / "flow" / "mv.####.exr")], "needs --flow-direction"),
                           (["--flow", str(tmp_path / "flow" / "nope.####.exr"), "--flow-direction", "next"],
                            "nope.0000.exr: no such file"),
                           (["--flow-direction", "next"], "only apply with --flow")):
        r = CliRunner().invoke(cli, ["denoise", str(tmp_path / "bare" / "b.####.exr"), "-o",
                                     str(tmp_path / "x" / "d.####.exr"), "--model", str(model), *extra])
        assert r.exit_code == 2 and problem in r.output and r.output.count("\n") == 1, r.output
