"""The measured tile halo (halo.py): the smallest halo whose tiled output matches the whole frame, stored by
`ranad export --measure-halo` and used as `ranad denoise`'s default."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core.denoise import denoise_frame, halo_for, halo_for_bound
from ranad_core.exr import read_deep
from ranad_core.halo import MAX_TOL, MEAN_TOL, measure_halo
from ranad_core.model.store import load_model
from test_denoise import tiny_model

FRAME = Path(__file__).resolve().parents[1] / "examples" / "synth_shot" / "noisy_spp16.0001.exr"


def wide_model():
    """An untrained model whose receptive-field bound (>= 32 px) is wider than one ALIGN step."""
    return tiny_model(radius=2.5, growth=1.0, heads=2, seed=1, name="wide")


def matches(tiled, whole) -> bool:  # the criterion, computed here independently of halo.mismatch
    d = np.abs(tiled.astype(np.float64) - whole) / (np.abs(whole) + np.maximum(np.abs(whole).mean(0), 1e-6))
    return d.mean() <= MEAN_TOL and d.max() <= MAX_TOL


def test_measured_halo_is_the_smallest_that_matches(tmp_path):
    model = wide_model()
    img = read_deep(FRAME)
    assert halo_for_bound(model) >= 32
    halo, tried = measure_halo(model, [img], tile=16)
    whole = denoise_frame(model, img).image.values.astype(np.float64)
    assert halo <= halo_for_bound(model) and halo % 16 == 0
    assert matches(denoise_frame(model, img, tile=16, halo=halo).image.values, whole)
    if halo > 16:
        assert not matches(denoise_frame(model, img, tile=16, halo=halo - 16).image.values, whole)
    assert [h for h, _, _ in tried] == list(range(16, halo + 1, 16))


def test_export_stores_the_halo_and_denoise_uses_it(tmp_path):
    from safetensors.torch import save_file

    model = wide_model()
    src = tmp_path / "wide.safetensors"
    save_file({k: v.contiguous() for k, v in model.state_dict().items()}, str(src),
              metadata={"model_config": json.dumps(model.config.to_dict())})
    assert not hasattr(load_model(str(src)).model, "measured_halo")
    out = tmp_path / "wide-halo.safetensors"
    r = CliRunner().invoke(cli, ["export", str(src), "-o", str(out), "--measure-halo", str(FRAME)])
    assert r.exit_code == 0, r.output
    loaded = load_model(str(out))
    halo = int(loaded.metadata["halo"])
    assert f"measured halo: {halo} px" in r.output and loaded.model.measured_halo == halo
    assert halo_for(loaded.model) == min(halo, halo_for_bound(loaded.model))
    for name, v in load_model(str(src)).model.state_dict().items():   # the weights are copied unchanged
        assert torch.equal(loaded.model.state_dict()[name], v)
    r = CliRunner().invoke(cli, ["denoise", str(FRAME), "-o", str(tmp_path / "d.exr"), "--model", str(out),
                                 "--tile", "16", "--cache", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    from ranad_core import cache as cache_io

    _, meta = cache_io.read_cache(cache_io.cache_path(str(tmp_path / "c"), str(tmp_path / "d.exr")))
    assert int(meta["halo"]) == halo


def test_export_interpolates_two_models_of_one_config(tmp_path):
    """`ranad export A --interpolate B=T`: every float tensor (1 - T) a + T b, the ends' halos dropped (a halo
    measured with --measure-halo is the result's), the provenance recorded; a model of another configuration, a
    weight outside [0, 1] or a malformed option are refused with exit 2 and no file."""
    from safetensors.torch import save_file

    files = []
    for seed in (1, 2):
        model = tiny_model(seed=seed)
        path = tmp_path / f"m{seed}.safetensors"
        save_file({k: v.contiguous() for k, v in model.state_dict().items()}, str(path),
                  metadata={"model_config": json.dumps(model.config.to_dict()), "halo": "48"})
        files.append(path)
    out = tmp_path / "mix.safetensors"
    r = CliRunner().invoke(cli, ["export", str(files[0]), "-o", str(out), "--interpolate", f"{files[1]}=0.25"])
    assert r.exit_code == 0, r.output
    mixed = load_model(str(out))
    a, b = (load_model(str(f)).model.state_dict() for f in files)
    changed = 0
    for name, v in mixed.model.state_dict().items():
        if v.is_floating_point():
            torch.testing.assert_close(v, 0.75 * a[name] + 0.25 * b[name], rtol=1e-6, atol=1e-7)
            changed += not torch.equal(a[name], b[name])
    assert changed > 0
    assert "halo" not in mixed.metadata and mixed.metadata["interpolated"].startswith("0.25 x m2@")
    r = CliRunner().invoke(cli, ["export", str(files[0]), "-o", str(tmp_path / "h.safetensors"), "--interpolate",
                                 f"{files[1]}=0.5", "--measure-halo", str(FRAME)])
    assert r.exit_code == 0, r.output
    assert "halo" in load_model(str(tmp_path / "h.safetensors")).metadata
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.safetensors", "m1.safetensors", "m2.safetensors",
                                                          "mix.safetensors"]   # no scratch file left
    other = wide_model()
    wide = tmp_path / "wide.safetensors"
    save_file({k: v.contiguous() for k, v in other.state_dict().items()}, str(wide),
              metadata={"model_config": json.dumps(other.config.to_dict())})
    for bad in (f"{wide}=0.5", f"{files[1]}=1.5", f"{files[1]}", "=0.5"):
        r = CliRunner().invoke(cli, ["export", str(files[0]), "-o", str(tmp_path / "bad.safetensors"),
                                     "--interpolate", bad])
        assert r.exit_code == 2, (bad, r.output)
        assert not (tmp_path / "bad.safetensors").exists()
