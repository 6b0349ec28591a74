"""Renderer presets (issue 25): a small deep file written with each renderer's channel names (the synth example
frame renamed: split layers as direct + indirect parts, motion in the renderer's units and axes) reads back as
the same canonical layers and motion as the original; --map LAYER=A+B sums layers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core.channels import (ALBEDO, ALPHA, DEPTH, DIFFUSE, EMISSION, NORMAL, SPECULAR, canonical, detect,
                                 mapping_options)
from ranad_core.deep import DeepImage
from ranad_core.errors import RanadError
from ranad_core.exr import read_deep, write_deep
from ranad_core.presets import PRESETS

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"

# Per renderer, the file as that renderer names it: colour layers (one name, or the parts of a sum), the
# normal's layer and components, and the motion layer(s) with how their values relate to canonical pixels.
RENDERERS = {
    "renderman": dict(diffuse=["directDiffuse", "indirectDiffuse"], specular=["directSpecular", "indirectSpecular"],
                      emission="emissive", albedo="albedo", normal=("Nn", "xyz"),
                      motion={"motion_next": ("motionFore", "xy", 1.0, 1.0),
                              "motion_prev": ("motionBack", "xy", 1.0, 1.0)}),
    "arnold": dict(diffuse=["diffuse_direct", "diffuse_indirect"], specular=["specular_direct", "specular_indirect"],
                   emission="emission", albedo="denoise_albedo", normal=("N", "XYZ"),
                   motion={"motion_next": ("motionvector", "XY", 1.0, 1.0)}),
    "karma": dict(diffuse=["directdiffuse", "indirectdiffuse"], specular=["directglossyreflection",
                                                                          "indirectglossyreflection"],
                  emission="emission", albedo="albedo", normal=("N", "xyz"),
                  motion={"motion_next": ("motionvector", "xy", "ndc", "up")}),
    "vray": dict(diffuse=["lighting", "GI"], specular=["reflect", "specular"], emission="selfIllum",
                 albedo="diffuse", normal=("normals", "XYZ"), motion={"motion_next": ("velocity", "RG", 1.0, -1.0)}),
    "redshift": dict(diffuse=["DiffuseLighting", "GI"], specular=["SpecularLighting", "Reflections"],
                     emission="Emission", albedo="DiffuseFilter", normal=("N", "XYZ"),
                     motion={"motion_next": ("MotionVectors", "RG", 1.0, -1.0)}),
}
SHARES = (0.7, 0.3)   # how a canonical layer is split into a renderer's two parts


def renderer_file(img: DeepImage, spec: dict) -> DeepImage:
    """`img` (ranad's channel convention) rewritten with a renderer's channel names and motion conventions."""
    cols, names = [], []

    def put(name, data):
        names.append(name)
        cols.append(np.asarray(data, np.float32))

    for c in ("R", "G", "B", "A", "Z", "ZBack"):
        put(c, img.channel(c))
    for layer in ("diffuse", "specular"):
        parts = spec[layer]
        for part, share in zip(parts, SHARES):
            for c in "RGB":
                put(f"{part}.{c}", img.channel(f"{layer}.{c}") * share)
    for layer, src in (("emission", "emission"), ("albedo", "albedo")):
        for c in "RGB":
            put(f"{spec[layer]}.{c}", img.channel(f"{src}.{c}"))
    nname, comps = spec["normal"]
    for c, k in zip(comps, "XYZ"):
        put(f"{nname}.{c}", img.channel(f"N.{k}"))
    w = img.display_window[2] - img.display_window[0] + 1
    h = img.display_window[3] - img.display_window[1] + 1
    for key, (name, comps, sx, sy) in spec["motion"].items():
        x, y = img.channel(f"{key}.X"), img.channel(f"{key}.Y")
        if sx == "ndc":                                  # fraction of the display window, y up
            x, y = x / w, -y / h
        else:
            x, y = x * sx, y * sy
        put(f"{name}.{comps[0]}", x)
        put(f"{name}.{comps[1]}", y)
    return DeepImage(values=np.stack(cols, 1), offsets=img.offsets, channels=names, ids=img.ids,
                     data_window=img.data_window, display_window=img.display_window,
                     channel_types={**{n: "float" for n in names}, **{k: "uint" for k in img.ids}})


@pytest.fixture(scope="module")
def original():
    """The example frame without `coverage` (a ranad synth channel renderers do not write)."""
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    keep = [c for c in img.channels if c != "coverage"]
    return img.select(keep)


@pytest.mark.parametrize("name", sorted(RENDERERS))
def test_each_preset_reads_its_renderers_file(name, original, tmp_path):
    assert set(RENDERERS) == set(PRESETS)
    spec = RENDERERS[name]
    path = tmp_path / f"{name}.exr"
    write_deep(path, renderer_file(original, spec))
    img = read_deep(path)
    m = detect(img, mapping_options(preset=name), str(path))
    assert m.layers["diffuse"] == tuple(tuple(f"{p}.{c}" for c in "RGB") for p in spec["diffuse"])
    assert m.layers["specular"] == tuple(tuple(f"{p}.{c}" for c in "RGB") for p in spec["specular"])
    assert m.layers["albedo"] == tuple(f"{spec['albedo']}.{c}" for c in "RGB")
    assert m.split and m.guides and m.preset == name
    ref_m = detect(original)
    got, res = canonical(img, m)
    ref, ref_res = canonical(original, ref_m)
    assert got.channels == ref.channels
    np.testing.assert_allclose(got.values, ref.values, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(res, ref_res, rtol=1e-4, atol=1e-4)
    for key in spec["motion"]:                           # the renderer's units and axes back to canonical pixels
        np.testing.assert_allclose(m.motion.vectors(img, key), ref_m.motion.vectors(original, key),
                                   rtol=1e-5, atol=1e-4, err_msg=f"{name} {key}")
    plain = detect(img)                                  # without the preset the split is not found
    assert not plain.split or plain.layers["diffuse"] != m.layers["diffuse"]
    assert not plain.motion.found


def test_vray_diffuse_filter_is_albedo_not_the_diffuse_layer(original):
    img = renderer_file(original, RENDERERS["vray"])
    assert detect(img).layers["diffuse"] == ("diffuse.R", "diffuse.G", "diffuse.B")   # the generic alias's mistake
    m = detect(img, mapping_options(preset="vray"))
    assert m.layers["albedo"] == ("diffuse.R", "diffuse.G", "diffuse.B")
    assert m.layers["diffuse"] == (("lighting.R", "lighting.G", "lighting.B"), ("GI.R", "GI.G", "GI.B"))
    # --map overrides the preset; explicit motion options override the preset's conversion
    m = detect(img, mapping_options(["albedo=lighting"], preset="vray", motion_y="down"))
    assert m.layers["albedo"] == ("lighting.R", "lighting.G", "lighting.B") and not m.motion.y_up


def test_map_sums_layers_and_writes_the_parts_back(original, tmp_path):
    spec = dict(RENDERERS["arnold"], diffuse=["kd_a", "kd_b"], specular=["ks_a", "ks_b"])
    img = renderer_file(original, spec)
    opts = mapping_options(["diffuse=kd_a+kd_b", "specular=ks_a.R,ks_a.G,ks_a.B+ks_b"])
    m = detect(img, opts)
    assert m.layers["diffuse"] == (("kd_a.R", "kd_a.G", "kd_a.B"), ("kd_b.R", "kd_b.G", "kd_b.B")) and m.split
    np.testing.assert_allclose(canonical(img, m)[0].values, canonical(original, detect(original))[0].values,
                               rtol=1e-5, atol=1e-5)
    for bad in (["diffuse=a+"], ["diffuse=a,b+c"], ["motion_prev=a+b"]):
        with pytest.raises(RanadError):
            mapping_options(bad)
    with pytest.raises(RanadError, match="no such channels"):
        detect(img, mapping_options(["diffuse=kd_a+nothing"]))
    # one channel read for two radiance layers: two results would be written into it (and the beauty rebuilt from
    # parts that never summed to it); the guides are only read
    for bad, what in ((["specular=ks_a", "diffuse=ks_a"], "diffuse and specular both read ks_a.R"),
                      (["diffuse=kd_a+kd_a"], "diffuse reads kd_a.R twice"),
                      (["diffuse=R,G,B"], "beauty and diffuse both read R")):
        with pytest.raises(RanadError, match=what):
            detect(img, mapping_options(bad))
    assert detect(img, mapping_options(["diffuse=kd_a+kd_b", "albedo=kd_a"])).layers["albedo"][0] == "kd_a.R"
    with pytest.raises(RanadError, match="unknown renderer"):
        mapping_options(preset="blender")
    # through the CLI: the denoised sum goes back into the parts in their noisy proportions
    from ranad_core.model import RaNAD, ReconConfig, feature_dim
    from ranad_core.model.config import ModelConfig
    from safetensors.torch import save_file

    torch.manual_seed(0)
    rc = ReconConfig(scales=2, heads=2, head_dim=8, radius=1.5, radius_growth=0.5)
    cfg = ModelConfig("tiny", dim=16, unets=1, levels=1, blocks_per_level=1, heads=4, head_dim=8, radius=1.5,
                      radius_growth=0.5, recon={"diffuse": rc, "specular": rc, "alpha": rc, "depth": rc})
    model = RaNAD(cfg, feature_dim()).eval()
    model_path = tmp_path / "tiny.safetensors"
    save_file({k: v.contiguous() for k, v in model.state_dict().items()}, str(model_path),
              metadata={"model_config": json.dumps(model.config.to_dict())})
    write_deep(tmp_path / "in.exr", img)
    r = CliRunner().invoke(cli, ["denoise", str(tmp_path / "in.exr"), "-o", str(tmp_path / "out.exr"), "--model",
                                 str(model_path), "--map", "diffuse=kd_a+kd_b", "--map", "specular=ks_a+ks_b"])
    assert r.exit_code == 0, r.output
    out = read_deep(tmp_path / "out.exr")
    a, b = out.channel("kd_a.R"), out.channel("kd_b.R")
    assert not np.allclose(a, img.channel("kd_a.R"))                 # denoised
    some = np.abs(a + b) > 1e-3
    share = np.divide(a, a + b, out=np.zeros_like(a), where=some)
    big = some & (np.abs(img.channel("kd_a.R")) > 1e-6)
    np.testing.assert_allclose(share[big], SHARES[0], rtol=1e-3)       # the noisy parts' proportions
    zero = some & (img.channel("kd_a.R") == 0)                         # none there: the frame's proportions
    assert zero.any()
    np.testing.assert_allclose(share[zero], SHARES[0], rtol=1e-3)
    rebuilt = sum(out.channel(f"{p}.R") for p in ("kd_a", "kd_b", "ks_a", "ks_b", "emission"))
    assert np.abs(out.channel("R") - rebuilt).max() < 0.05 * max(1.0, np.abs(out.channel("R")).max())


def test_preset_shows_in_info_and_denoise(original, tmp_path):
    path = tmp_path / "karma.exr"
    write_deep(path, renderer_file(original, RENDERERS["karma"]))
    r = CliRunner().invoke(cli, ["info", "--no-stats", "--preset", "karma", str(path)])
    assert r.exit_code == 0, r.output
    assert "diffuse=directdiffuse.R,directdiffuse.G,directdiffuse.B+indirectdiffuse.R" in r.output
    assert "motion channels: motion_next=motionvector.x,motionvector.y (ndc, y up)" in r.output
    r = CliRunner().invoke(cli, ["info", "--no-stats", str(path)])
    assert "motion channels: none (not mapped; may hold motion: motionvector.x, motionvector.y" in r.output


@pytest.mark.parametrize("layers", [("diffuse", "specular", "emission"), ("diffuse", "specular"), ("emission",), ()])
def test_canonical_columns_against_the_definitions(original, layers):
    """canonical gathers the copied columns in one pass and writes the computed ones over placeholders: every
    canonical channel is checked against its definition on the file's own columns (split: the layers as they are
    and residual = beauty - diffuse - specular - emission; no split: diffuse = beauty - emission)."""
    drop = {"diffuse", "specular", "emission"} - set(layers)
    img = original.select([c for c in original.channels if c.split(".")[0] not in drop])
    if "emission" in layers:   # the example's emission is black: give it values, so that leaving it out shows
        values = img.values.copy()
        for c in "RGB":
            values[:, img.channels.index(f"emission.{c}")] = np.random.default_rng(1).uniform(0, 1, img.num_bins)
        img = img.with_values(values)
    m = detect(img)
    got, res = canonical(img, m)
    col = lambda name: img.values[:, img.channels.index(name)].astype(np.float64)   # noqa: E731
    beauty = np.stack([col(c) for c in "RGB"], 1)
    emission = np.stack([col(f"emission.{c}") for c in "RGB"], 1) if "emission" in layers else 0.0
    if m.split:
        assert "diffuse" in layers and "specular" in layers
        expect_res = beauty - sum(np.stack([col(f"{p}.{c}") for c in "RGB"], 1) for p in ("diffuse", "specular"))
        np.testing.assert_allclose(res, expect_res - emission, rtol=1e-5, atol=1e-5)
        for p in ("diffuse", "specular"):
            for canon, c in zip(DIFFUSE if p == "diffuse" else SPECULAR, "RGB"):
                assert np.array_equal(got.channel(canon), img.channel(f"{p}.{c}"))
    else:
        assert res is None
        diffuse = np.stack([got.channel(c) for c in DIFFUSE], 1)
        np.testing.assert_allclose(diffuse, beauty - emission, rtol=1e-6, atol=1e-6)
        assert not set(SPECULAR) & set(got.channels)
    assert set(EMISSION) <= set(got.channels) if "emission" in layers else not set(EMISSION) & set(got.channels)
    for layer, names in (("albedo", ALBEDO), ("normal", NORMAL)):
        for canon, src in zip(names, m.layers[layer]):
            assert np.array_equal(got.channel(canon), img.channel(src))
    assert np.array_equal(got.channel(ALPHA), img.channel(m.alpha))
    assert np.array_equal(got.channel(DEPTH), img.channel(m.depth))


def test_one_motion_option_keeps_the_presets_others():
    """--shutter with --preset karma read Karma's NDC, y-up motion as pixels, y down: any one motion option reset
    the others to the defaults instead of the preset's (the docstring's promise)."""
    conv = lambda **k: mapping_options(**k)["motion"]  # noqa: E731
    assert conv(preset="karma", shutter=0.5) == {"units": "ndc", "fps": None, "shutter": 0.5, "y": "up"}
    assert conv(preset="karma", motion_y="down")["units"] == "ndc"
    assert conv(preset="vray", motion_units="velocity", fps=24.0)["y"] == "up"
    assert conv(shutter=0.5) == {"units": "pixels", "fps": None, "shutter": 0.5, "y": "down"}
    with pytest.raises(RanadError, match="--fps only applies"):
        mapping_options(preset="karma", fps=24.0)
    with pytest.raises(RanadError, match="--fps 0.0: must be a positive number"):   # not "needs --fps"
        mapping_options(motion_units="velocity", fps=0.0)


def test_an_empty_frame_with_a_summed_layer(original, tmp_path):
    """A frame with no bins (an element out of view) whose diffuse is a sum (V-Ray's lighting + GI) was an
    internal error (a reshape of 0 values), alone or as a neighbour; it denoises to an empty frame."""
    from ranad_core.exr import write_deep

    full = renderer_file(original, RENDERERS["vray"])
    empty = DeepImage(np.zeros((0, len(full.channels)), np.float32), np.zeros(full.num_pixels + 1, np.int64),
                      full.channels, data_window=full.data_window, display_window=full.display_window,
                      channel_types=dict(full.channel_types))
    write_deep(tmp_path / "e.exr", empty)
    r = CliRunner().invoke(cli, ["denoise", "--preset", "vray", str(tmp_path / "e.exr"), "-o", str(tmp_path / "o.exr")])
    assert r.exit_code == 0, r.output
    assert read_deep(tmp_path / "o.exr").num_bins == 0
    assert canonical(empty, detect(empty, mapping_options(preset="vray")))[0].num_bins == 0


@pytest.mark.parametrize("preset, layer", [("vray", "normals"), ("karma", "N"), (None, "N")])
def test_normals_with_colour_components_are_the_guide(original, preset, layer):
    """Normals written as .R/.G/.B (V-Ray's normals, Redshift's and Karma's N) were not found: the run went on
    'without guides' with nothing but a missing normal= in the map to say so."""
    vals, names = original.values, list(original.channels)
    for comp, rgb in zip("XYZ", "RGB"):
        names[names.index(f"N.{comp}")] = f"{layer}.{rgb}"
    img = DeepImage(vals, original.offsets, names, data_window=original.data_window)
    m = detect(img, mapping_options(preset=preset) if preset else None)
    assert m.layers["normal"] == (f"{layer}.R", f"{layer}.G", f"{layer}.B") and m.guides
