"""Motion as renderers write it (issue 25): any two channels mapped as motion_prev/motion_next, unit and axis
conversion, one direction carrying both neighbours, and a loud warning when a cross-frame model has no motion."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core.channels import MotionSpec, detect, mapping_options
from ranad_core.deep import DeepImage
from ranad_core.errors import RanadError
from ranad_core.exr import read_deep, write_deep
from ranad_core.motion import compensate, displacement

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"
PREV = ("motion_prev.X", "motion_prev.Y")
NEXT = ("motion_next.X", "motion_next.Y")


def rename(img: DeepImage, names: dict, drop=()) -> DeepImage:
    """`img` with channels renamed (old -> new) and `drop`ped, values, ids and types kept."""
    keep = [c for c in img.channels if c not in drop]
    vals = img.values[:, [img.channels.index(c) for c in keep]]
    new = [names.get(c, c) for c in keep]
    types = {names.get(c, c): t for c, t in img.channel_types.items() if c not in drop}
    return DeepImage(values=vals, offsets=img.offsets, channels=new, ids=img.ids, data_window=img.data_window,
                     display_window=img.display_window, channel_types=types, header=img.header)


def backward_only(img: DeepImage) -> DeepImage:
    """The renderer's file: one backward motion layer `mv.X, mv.Y` (pixels, y down), no forward layer."""
    return rename(img, {"motion_prev.X": "mv.X", "motion_prev.Y": "mv.Y"}, drop=NEXT)


def shot():
    return [read_deep(SHOT / f"noisy_spp16.{i:04d}.exr") for i in range(3)]


# ---------------------------------------------------------------------------------------------- a 5-frame shot
def layered_shot(frames=5, w=24, h=16, seed=0, ids=True):
    """A 5-frame deep shot with known motion: a static background bin in every pixel (z 10) and, where a 5x4
    semi-transparent card covers the pixel, a card bin in front (z 2) moving (+2, +1) pixels per frame. Every
    bin holds `src.X/Y`: where its surface point is in the centre frame (what perfect compensation puts it on).
    Channels: R G B A Z plus canonical motion_prev/motion_next.X/Y (0 at the shot's ends, as ranad synth)."""
    rng = np.random.default_rng(seed)
    chans = ["R", "G", "B", "A", "Z", "src.X", "src.Y", *PREV, *NEXT]
    c = frames // 2
    out = []
    for t in range(frames):
        rows, counts = [], []
        ox, oy = 3 + 2 * t, 4 + 1 * t
        for y in range(h):
            for x in range(w):
                bins = []
                if ox <= x < ox + 5 and oy <= y < oy + 4:
                    mp = (-2.0, -1.0) if t > 0 else (0.0, 0.0)
                    mn = (2.0, 1.0) if t < frames - 1 else (0.0, 0.0)
                    bins.append([*rng.uniform(0, 1, 3), 0.5, 2.0, x + 2 * (c - t), y + (c - t), *mp, *mn, 7])
                bins.append([*rng.uniform(0, 1, 3), 1.0, 10.0, x, y, 0, 0, 0, 0, 3])
                rows += bins
                counts.append(len(bins))
        arr = np.asarray(rows, np.float64)
        offsets = np.concatenate([[0], np.cumsum(counts)])
        out.append(DeepImage(values=arr[:, :-1].astype(np.float32), offsets=offsets, channels=chans,
                             ids={"id": arr[:, -1].astype(np.uint32)} if ids else {},
                             data_window=(0, 0, w - 1, h - 1),
                             channel_types={**{k: "float" for k in chans}, **({"id": "uint"} if ids else {})}))
    return out


def aligned_share(moved: DeepImage, w: int, card_only: bool = False) -> float:
    """Share of a compensated frame's bins (or of its card's bins) that sit on their surface point's
    centre-frame pixel."""
    y, x = np.divmod(moved.pixel_index(), w)
    ok = (moved.channel("src.X") == x) & (moved.channel("src.Y") == y)
    return float(np.mean(ok[moved.channel("Z") == 2.0] if card_only else ok))


@pytest.mark.parametrize("ids", [True, False])
def test_one_backward_layer_carries_both_sides_of_a_five_frame_window(ids):
    frames = layered_shot(ids=ids)
    w = frames[0].width
    both, _ = compensate(frames, 2, motion=MotionSpec.canonical())
    back = [backward_only(f) for f in frames]
    spec = detect(back[2], mapping_options(["motion_prev=mv.X,mv.Y"])).motion
    assert spec.prev == ("mv.X", "mv.Y") and spec.next is None
    only_back, _ = compensate(back, 2, motion=spec)
    still, _ = compensate(back, 2, motion=detect(back[2]).motion)          # nothing mapped: no motion
    for k in (0, 1, 3, 4):
        assert aligned_share(both[k], w) == 1.0
        assert aligned_share(only_back[k], w) == 1.0, k                     # frames before the centre too
        assert aligned_share(still[k], w, card_only=True) == 0.0
    fwd = [rename(f, {"motion_next.X": "fv.X", "motion_next.Y": "fv.Y"}, drop=PREV) for f in frames]
    only_fwd, _ = compensate(fwd, 2, motion=detect(fwd[2], mapping_options(["motion_next=fv"])).motion)
    assert all(aligned_share(only_fwd[k], w) == 1.0 for k in (0, 1, 3, 4))


def test_renamed_channels_compensate_exactly_like_the_canonical_ones():
    """The synth example with its backward layer renamed mv.X/mv.Y (the forward one dropped): with
    --map motion_prev=mv.X,mv.Y the compensated neighbours equal those of the canonical backward channels,
    bit for bit, and land close to where both directions put them."""
    frames = shot()
    canonical_back = [rename(f, {}, drop=NEXT) for f in frames]
    renamed = [backward_only(f) for f in frames]
    mapped = detect(renamed[1], mapping_options(["motion_prev=mv.X,mv.Y"]), "shot").motion
    a, dropped_a = compensate(renamed, 1, motion=mapped)
    b, dropped_b = compensate(canonical_back, 1, motion=detect(canonical_back[1]).motion)
    assert dropped_a == dropped_b
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.offsets, y.offsets)
        np.testing.assert_array_equal(x.values, y.values)           # same bins, same order (motion renamed only)
    full = [displacement(frames, k, 1) for k in (0, 2)]
    one = [displacement(renamed, k, 1, motion=mapped) for k in (0, 2)]
    none = [displacement(renamed, k, 1, motion=detect(renamed[1]).motion) for k in (0, 2)]
    np.testing.assert_array_equal(one[1], full[1])                  # the next frame: its own backward vectors
    err = np.abs(one[0] - full[0]).sum(1)                           # the previous frame: carried with frame 1's
    assert np.median(err) < 0.25 and np.mean(err < 1.0) > 0.9
    assert np.abs(none[0]).max() == 0 and np.abs(full[0]).mean() > 1.0


def test_units_and_axes_convert_to_canonical_pixels():
    frames = shot()
    img = frames[2]
    px = MotionSpec.canonical().vectors(img, "motion_prev")
    w = img.display_window[2] - img.display_window[0] + 1
    h = img.display_window[3] - img.display_window[1] + 1
    cases = {  # the file's values for the same motion, and the options that read them back
        "ndc, y up": (px * [1 / w, -1 / h], dict(motion_units="ndc", motion_y="up")),
        "velocity": (px * 24.0, dict(motion_units="velocity", fps=24.0)),
        "half shutter": (px * 0.5, dict(shutter=0.5)),
    }
    for name, (vals, opts) in cases.items():
        v = np.concatenate([img.values, vals.astype(np.float32)], 1)
        f = img.with_values(v, img.channels + ["vel.x", "vel.y"])
        spec = detect(f, mapping_options(["motion_prev=vel"], **opts)).motion
        np.testing.assert_allclose(spec.vectors(f, "motion_prev"), px, rtol=1e-5, atol=1e-5, err_msg=name)
    for bad in (dict(motion_units="velocity"), dict(fps=24.0), dict(shutter=0.0),
                dict(motion_units="velocity", fps=24.0, shutter=0.5)):
        with pytest.raises(RanadError):
            mapping_options(["motion_prev=vel"], **bad)
    with pytest.raises(RanadError, match="two channels"):
        mapping_options(["motion_prev=a,b,c"])
    with pytest.raises(RanadError, match="no such channels"):
        detect(img, mapping_options(["motion_prev=mv.X,mv.Y"]), "f.exr")


# ------------------------------------------------------------------------------------------------------- the CLI
def cross_model(tmp_path) -> str:
    from safetensors.torch import save_file

    from ranad_core.model import RaNAD, feature_dim, get_config
    from ranad_core.model.crossframe import CrossFrameRaNAD

    torch.manual_seed(0)
    single = RaNAD(get_config("cpu-small"), feature_dim()).eval()
    cross = CrossFrameRaNAD.from_single(single, get_config("cpu-small-xf"), feature_dim()).eval()
    path = tmp_path / "xf.safetensors"
    save_file({k: v.contiguous() for k, v in cross.state_dict().items()}, str(path),
              metadata={"model_config": json.dumps(cross.config.to_dict())})
    return str(path)


def test_denoise_warns_once_without_motion_and_uses_the_mapping(tmp_path):
    folder = tmp_path / "shot"
    folder.mkdir()
    for i, f in enumerate(shot()):
        write_deep(folder / f"beauty.{i:04d}.exr", backward_only(f))
    model = cross_model(tmp_path)
    pattern = str(folder / "beauty.####.exr")
    r = CliRunner().invoke(cli, ["denoise", pattern, "-o", str(tmp_path / "a.####.exr"), "--model", model])
    assert r.exit_code == 0, r.output
    assert r.output.count("WITHOUT motion compensation") == 2         # the warning (once), and the summary
    assert "mv.X, mv.Y" in r.output and "--map motion_prev" in r.output
    r = CliRunner().invoke(cli, ["denoise", pattern, "-o", str(tmp_path / "b.####.exr"), "--model", model,
                                 "--map", "motion_prev=mv.X,mv.Y"])
    assert r.exit_code == 0, r.output
    assert "WITHOUT motion" not in r.output and "motion: motion_prev=mv.X,mv.Y (pixels, y down)" in r.output
    a, b = (read_deep(tmp_path / f"{n}.0001.exr") for n in "ab")
    assert not np.array_equal(a.values, b.values)                   # the mapping changed the neighbours
    r = CliRunner().invoke(cli, ["denoise", pattern, "-o", str(tmp_path / "c.####.exr"), "--model", model,
                                 "--window", "1"])
    assert r.exit_code == 0 and "WITHOUT motion" not in r.output    # frames denoised alone need no motion
    r = CliRunner().invoke(cli, ["info", "--no-stats", str(folder / "beauty.0001.exr")])
    assert "motion channels: none (not mapped; may hold motion: mv.X, mv.Y" in r.output
    r = CliRunner().invoke(cli, ["info", "--no-stats", "--map", "motion_prev=mv", str(folder / "beauty.0001.exr")])
    assert "motion channels: motion_prev=mv.X,mv.Y (pixels, y down)" in r.output
    r = CliRunner().invoke(cli, ["denoise", pattern, "-o", str(tmp_path / "d.####.exr"), "--model", model,
                                 "--map", "motion_prev=vx,vy"])
    assert r.exit_code == 2 and "beauty.0000.exr" in r.output and "motion_prev=vx,vy: no such channels" in r.output


def test_motion_far_beyond_the_frame_lands_outside_it():
    """A motion of 3e38 px cast to int64 with a numpy 'invalid value' warning (and an undefined target); such a bin
    is carried out of the frame, like any motion past its edge, without a warning."""
    import warnings

    from ranad_core.motion import _targets

    img = DeepImage(np.zeros((4, 5), np.float32), [0, 1, 2, 3, 4], ["R", "G", "B", "A", "Z"],
                    data_window=(0, 0, 1, 1))
    dxy = np.array([[3e38, 0], [-3e38, 0], [0, 1e30], [1, 0]], np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        target, inside = _targets(img, dxy)
    assert inside.tolist() == [False, False, False, False] and target.tolist() == [-1, -1, -1, -1]
    target, inside = _targets(img, np.array([[0, 0], [-1, 0], [0, 0], [0, -1]], np.float32))
    assert inside.all() and target.tolist() == [0, 0, 2, 1]
