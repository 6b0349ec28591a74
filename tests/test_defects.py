"""Small defects of issue 25: --kind is checked on every frame, bins carried out of the frame by motion are
reported, an empty shard is "nothing to do" (exit 0), and one NaN/Inf policy holds for every channel."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core.deep import DeepImage, replace_nonfinite
from ranad_core.exr import read_deep, write_deep
from ranad_core.model import RaNAD, ReconConfig, feature_dim
from ranad_core.model.config import ModelConfig

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A small untrained single-frame model as a .safetensors file."""
    from safetensors.torch import save_file

    torch.manual_seed(0)
    rc = ReconConfig(scales=2, heads=2, head_dim=8, radius=1.5, radius_growth=0.5)
    cfg = ModelConfig("tiny", dim=16, unets=1, levels=1, blocks_per_level=1, heads=4, head_dim=8, radius=1.5,
                      radius_growth=0.5, recon={"diffuse": rc, "specular": rc, "alpha": rc, "depth": rc})
    m = RaNAD(cfg, feature_dim()).eval()
    path = tmp_path_factory.mktemp("model") / "tiny.safetensors"
    save_file({k: v.contiguous() for k, v in m.state_dict().items()}, str(path),
              metadata={"model_config": json.dumps(m.config.to_dict())})
    return str(path)


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def without_ids(img: DeepImage) -> DeepImage:
    return DeepImage(values=img.values, offsets=img.offsets, channels=img.channels, data_window=img.data_window,
                     display_window=img.display_window,
                     channel_types={k: v for k, v in img.channel_types.items() if k not in img.ids},
                     header=img.header)


def test_kind_is_checked_on_every_frame(tmp_path, tiny):
    frame = SHOT / "noisy_spp16.0001.exr"                     # deep-OID: every bin of a pixel has its own id
    r = run("denoise", frame, "-o", tmp_path / "a.exr", "--model", tiny, "--kind", "deepoid")
    assert r.exit_code == 0, r.output
    assert "deep-OID input (--kind deepoid, checked on every frame)" in r.output
    r = run("denoise", frame, "-o", tmp_path / "b.exr", "--model", tiny, "--kind", "deepz")
    assert r.exit_code == 2 and not (tmp_path / "b.exr").exists()
    assert r.output.strip().count("\n") == 0 and "noisy_spp16.0001.exr: --kind deepz" in r.output
    plain = tmp_path / "plain.exr"
    write_deep(plain, without_ids(read_deep(frame)))
    r = run("denoise", plain, "-o", tmp_path / "c.exr", "--model", tiny, "--kind", "deepoid")
    assert r.exit_code == 2 and "plain.exr: --kind deepoid: not a deep-OID frame (it has no id channel)" in r.output
    r = run("denoise", plain, "-o", tmp_path / "d.exr", "--model", tiny, "--kind", "deepz")
    assert r.exit_code == 0 and "deep-Z input" in r.output
    # a later frame of the other kind is refused too, naming that frame
    folder = tmp_path / "mixed"
    folder.mkdir()
    for i in range(3):
        img = read_deep(SHOT / f"noisy_spp16.{i:04d}.exr")
        write_deep(folder / f"m.{i:04d}.exr", without_ids(img) if i == 2 else img)
    r = run("denoise", folder / "m.####.exr", "-o", tmp_path / "o.####.exr", "--model", tiny, "--kind", "deepoid")
    assert r.exit_code == 2 and "m.0002.exr: --kind deepoid" in r.output


def test_an_empty_shard_is_nothing_to_do(tmp_path, tiny):
    r = run("denoise", SHOT / "noisy_spp16.####.exr", "-o", tmp_path / "d.####.exr", "--model", tiny,
            "--shard", "4/5")
    assert r.exit_code == 0, r.output
    assert "nothing to do: shard 4/5 has no frames (the shot has 3)" in r.output
    assert not list(tmp_path.glob("d.*"))


def test_bins_carried_out_of_the_frame_are_reported(tmp_path):
    from ranad_core.shot import ShotOptions, denoise_shot
    from ranad_core.exr.sequence import expand_inputs
    from test_motion_map import cross_model

    path = cross_model(tmp_path)
    r = run("denoise", SHOT / "noisy_spp16.####.exr", "-o", tmp_path / "d.####.exr", "--model", path)
    assert r.exit_code == 0, r.output
    found = re.search(r"denoised 3 frame\(s\), \d+ bins, in [\d.]+ s; (\d+) neighbour bin\(s\) carried out of "
                      r"the frame by motion", r.output)
    assert found, r.output
    reported = int(found.group(1))

    from ranad_core.model.store import load_model

    seq = expand_inputs([str(SHOT / "noisy_spp16.####.exr")])
    summary = denoise_shot([(f, str(tmp_path / f"e.{f.frame}.exr")) for f in seq], load_model(path),
                           ShotOptions(window=3))
    assert summary.dropped == reported > 0


def poisoned(tmp_path) -> tuple[Path, DeepImage, np.ndarray]:
    """The example frame with NaN/+Inf/-Inf in model channels (diffuse, Z) and in others (P, lg_key, motion)."""
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    vals = img.values.copy()
    rng = np.random.default_rng(3)
    rows = rng.choice(img.num_bins, 40, replace=False)
    for k, (c, v) in enumerate([("P.X", np.inf), ("lg_key.R", np.nan), ("lg_fill.G", np.inf),
                                ("motion_next.X", -np.inf), ("diffuse.R", np.nan), ("Z", np.inf),
                                ("lg_rim.B", np.nan), ("coverage", np.nan)]):
        vals[rows[5 * k:5 * k + 5], img.channels.index(c)] = v
    path = tmp_path / "poisoned.exr"
    bad = img.with_values(vals)
    write_deep(path, bad)
    return path, bad, rows


def test_one_nan_inf_policy_for_every_channel(tmp_path, tiny):
    path, bad, rows = poisoned(tmp_path)
    fixed, n = replace_nonfinite(bad, ("Z", "ZBack"))
    assert n == 40 and np.isfinite(fixed.values).all()
    z = bad.channel("Z")
    assert fixed.channel("Z")[rows[25:30]].tolist() == [z[np.isfinite(z)].max()] * 5
    assert (fixed.channel("P.X")[rows[:5]] == 0).all() and (fixed.channel("lg_fill.G")[rows[10:15]] == 0).all()
    r = run("denoise", path, "-o", tmp_path / "out.exr", "--model", tiny, "--aovs", "lg_*")
    assert r.exit_code == 0, r.output
    assert "poisoned.exr: 40 bin(s) with NaN/Inf values (replaced in every channel" in r.output
    assert "40 bin(s) with NaN/Inf replaced" in r.output
    out = read_deep(tmp_path / "out.exr")
    assert np.isfinite(out.values).all()                       # AOVs, P, motion and the model's channels alike
    for c in ("P.X", "motion_next.X", "coverage"):             # channels the denoiser does not touch: the policy
        np.testing.assert_array_equal(out.channel(c), fixed.channel(c))
    r = run("denoise", path, "-o", tmp_path / "strict.exr", "--model", tiny, "--strict")
    assert r.exit_code == 2 and "poisoned.exr: 40 bin(s) with NaN/Inf values" in r.output
    assert not (tmp_path / "strict.exr").exists()


def test_nan_only_outside_the_model_channels_is_still_counted(tmp_path, tiny):
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    vals = img.values.copy()
    vals[:7, img.channels.index("P.Y")] = np.nan
    write_deep(tmp_path / "p.exr", img.with_values(vals))
    r = run("denoise", tmp_path / "p.exr", "-o", tmp_path / "o.exr", "--model", tiny)
    assert r.exit_code == 0 and "p.exr: 7 bin(s) with NaN/Inf values" in r.output
    assert np.isfinite(read_deep(tmp_path / "o.exr").values).all()
    r = run("denoise", tmp_path / "p.exr", "-o", tmp_path / "s.exr", "--model", tiny, "--strict")
    assert r.exit_code == 2 and "7 bin(s) with NaN/Inf" in r.output


def test_a_model_that_outputs_nan_writes_nothing(tmp_path, tiny):
    """Weights that overflow (or are NaN) gave NaN frames with exit 0 and no word: the inputs are made finite
    first, so a non-finite output is the model's, refused with one line and no output."""
    from safetensors.torch import load_file, save_file
    from safetensors import safe_open

    with safe_open(tiny, "pt") as f:
        meta = f.metadata()
    state = {k: v * float("nan") if v.is_floating_point() else v for k, v in load_file(tiny).items()}
    bad = tmp_path / "nan.safetensors"
    save_file(state, str(bad), metadata=meta)
    r = run("denoise", SHOT / "noisy_spp16.0001.exr", "-o", tmp_path / "d.exr", "--model", bad)
    assert r.exit_code == 2 and "the model's output has NaN/Inf" in r.output, r.output
    assert r.output.strip().splitlines()[-1].startswith("ranad: error: ") and not (tmp_path / "d.exr").exists()
    r = run("denoise", SHOT / "noisy_spp16.0001.exr", "-o", tmp_path / "ok.exr", "--model", tiny)
    assert r.exit_code == 0 and (tmp_path / "ok.exr").exists()
