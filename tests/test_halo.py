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
