"""`ranad aov`: light groups that sum to the beauty stay summing to it after denoising (single- and cross-frame
models, through the cache and in one step), and stale or mismatched caches are refused."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from model_factory import demodulating, input_keys_config, matching_config
from ranad_cli.main import cli
from ranad_core.aov import aov_layers, denoise_aovs, kernel_rule, partial_layers
from ranad_core.channels import detect
from ranad_core.denoise import denoise_window, is_cross_frame
from ranad_core.exr import read_deep, write_deep
from ranad_core.model import RaNAD, feature_dim, get_config
from ranad_core.model.crossframe import CrossFrameRaNAD

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"
GROUPS = ("lg_key", "lg_fill", "lg_rim")


def exact_groups(img):
    """The frame with float channels and lg_rim set so that the light groups sum exactly to R, G, B."""
    ch = img.channels
    vals = img.values.astype(np.float32).copy()
    for c in "RGB":
        vals[:, ch.index(f"lg_rim.{c}")] = (vals[:, ch.index(c)] - vals[:, ch.index(f"lg_key.{c}")]
                                            - vals[:, ch.index(f"lg_fill.{c}")])
    out = img.with_values(vals)
    out.channel_types = {c: ("uint" if c in img.ids else "float") for c in list(ch) + list(img.ids)}
    return out


def sums(img, prefix=""):
    ch = img.channels
    lg = sum(img.values[:, [ch.index(f"{g}.{c}") for c in "RGB"]].astype(np.float64) for g in GROUPS)
    return lg, img.values[:, [ch.index(c) for c in "RGB"]].astype(np.float64)


def models():
    torch.manual_seed(0)
    single = RaNAD(get_config("cpu-small"), feature_dim()).eval()
    cross = CrossFrameRaNAD.from_single(single, get_config("cpu-small-xf"), feature_dim()).eval()
    for g in cross.temporal_gate.values():     # open the temporal step, so the test covers it
        torch.nn.init.constant_(g.bias, 0.0)
    mixed = CrossFrameRaNAD.from_cross(cross, get_config("cpu-small-xfm"), feature_dim()).eval()
    for g in mixed.mix_gate.values():          # and the output mix
        torch.nn.init.constant_(g.bias, 0.0)
    keyed = CrossFrameRaNAD.from_single(single, input_keys_config(), feature_dim()).eval()
    for g in keyed.temporal_gate.values():
        torch.nn.init.constant_(g.bias, 0.0)
    demod = RaNAD(demodulating(get_config("cpu-small")), feature_dim()).eval()
    demod.load_state_dict(single.state_dict())
    demod_keyed = CrossFrameRaNAD(demodulating(input_keys_config()), feature_dim()).eval()
    demod_keyed.load_state_dict(keyed.state_dict())
    guarded = CrossFrameRaNAD.from_single(demod, demodulating(matching_config(guard=True)), feature_dim()).eval()
    for t in guarded.temporal.values():         # spread the matching step's weights over the candidates
        torch.nn.init.constant_(t.self_bonus, 0.0)
    ranged = RaNAD(get_config("cpu-small-pdr"), feature_dim("prior")).eval()
    for name, p in ranged.named_parameters():   # the prior-range term switched on, so the test covers it
        if name.endswith(".range"):
            torch.nn.init.constant_(p, 1.0)
    return {"single": single, "cross": cross, "output-mix": mixed, "input-keys": keyed, "demodulated": demod,
            "demodulated-input-keys": demod_keyed, "guarded-matching": guarded, "prior-range": ranged}


def test_layers_and_rules():
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    assert list(aov_layers(img.channels, "lg_*")) == sorted(GROUPS)
    assert aov_layers(img.channels, "nothing*") == {}
    assert kernel_rule("diffuse_key") == "diffuse" and kernel_rule("spec_rim") == "specular"
    assert kernel_rule("lg_key") == "colour"


@pytest.mark.parametrize("kind", ["single", "cross", "output-mix", "input-keys", "demodulated",
                                  "demodulated-input-keys", "guarded-matching", "prior-range"])
def test_light_groups_sum_to_the_denoised_beauty(kind):
    model = models()[kind]
    frames = [exact_groups(read_deep(SHOT / f"noisy_spp16.{i:04d}.exr")) for i in range(3)]
    lg, rgb = sums(frames[1])
    assert np.abs(lg - rgb).max() < 1e-6
    images, centre = (frames, 1) if is_cross_frame(model) else ([frames[1]], 0)
    res = denoise_window(model, images, centre, want_embeddings=True, tile=16)   # tiles: the primary pass
    layers = aov_layers(frames[1].channels, "lg_*")
    out = denoise_aovs(model, images, centre, detect(frames[1]), layers, res.embeddings, res.perms, res.offsets,
                       None, res.merge_gap, res.merges, res.split, res.dark_radius, res.gain)
    lg_d = sum(out[g].astype(np.float64) for g in GROUPS)
    _, rgb_d = sums(res.image)
    scale = np.abs(rgb_d).max()
    assert np.abs(lg_d - rgb_d).max() < 1e-5 * scale
    assert np.abs(lg_d - lg).max() > 1e-2 * scale          # the groups were denoised, not copied


def denoise_then_aov(net, tmp_path):
    """`net` saved as a .safetensors model; the bundled shot with exact light groups denoised with `--cache`, then
    `ranad aov` from the cache. Checks that every frame's groups keep the beauty's bins and sum to the denoised
    beauty; returns (CLI runner, source folder, model path) for further steps."""
    from safetensors.torch import save_file

    model = tmp_path / "m.safetensors"
    save_file({k: v.contiguous() for k, v in net.state_dict().items()}, str(model),
              metadata={"model_config": json.dumps(net.config.to_dict())})
    src = tmp_path / "in"
    src.mkdir()
    for f in range(3):
        write_deep(src / f"b.{f:04d}.exr", exact_groups(read_deep(SHOT / f"noisy_spp16.{f:04d}.exr")))
    run = lambda *a: CliRunner().invoke(cli, [str(x) for x in a])  # noqa: E731
    r = run("denoise", src / "b.####.exr", "-o", tmp_path / "d" / "b.####.exr", "--model", model, "--cache",
            tmp_path / "cache")
    assert r.exit_code == 0, r.output
    r = run("aov", tmp_path / "cache", "--layers", "lg_*", "-o", tmp_path / "a" / "lg.####.exr")
    assert r.exit_code == 0, r.output
    for f in range(3):
        a, d = read_deep(tmp_path / "a" / f"lg.{f:04d}.exr"), read_deep(tmp_path / "d" / f"b.{f:04d}.exr")
        np.testing.assert_array_equal(a.offsets, d.offsets)
        lg, _ = sums(a)
        _, rgb = sums(d)
        assert np.abs(lg - rgb).max() < 1e-5 * np.abs(rgb).max()
    return run, src, model


def test_aov_command_through_the_cache_of_an_input_keyed_model(tmp_path):
    """The sequence default's kind of model (input keys: the centre's cache entry holds its backbone features and
    its keys) through `ranad denoise --cache` and `ranad aov`: the light groups sum to the denoised beauty."""
    denoise_then_aov(models()["input-keys"], tmp_path)


def test_aov_command_through_the_cache_of_a_demodulating_model(tmp_path):
    """A model that divides the diffuse layer by the albedo: `ranad aov` rebuilds the same modulation from the
    files, so the light groups still sum to the denoised beauty."""
    denoise_then_aov(models()["demodulated-input-keys"], tmp_path)


def test_aov_command_through_the_cache_of_a_guarded_matching_model(tmp_path):
    """The matching step with its guard: the guides travel in the cached embeddings, so `ranad aov` rebuilds the
    same allowed pairs and the light groups still sum to the denoised beauty."""
    denoise_then_aov(models()["guarded-matching"], tmp_path)


@pytest.mark.parametrize("cross", [False, True])
def test_aov_command_through_the_cache_of_a_colour_gated_model(tmp_path, cross):
    """A model whose colour kernels are layer-gated (reconstruction.layer_gate) reads the bins' depths in `ranad
    aov` as in the primary pass, single-frame and cross-frame: the light groups still sum to the denoised beauty."""
    import dataclasses

    torch.manual_seed(1)
    gated = ("diffuse", "specular", "alpha", "depth")
    if cross:
        cfg = dataclasses.replace(demodulating(input_keys_config()), name="gated-keys", layer_gate=gated)
        net = CrossFrameRaNAD(cfg, feature_dim()).eval()
        for g in net.temporal_gate.values():
            torch.nn.init.constant_(g.bias, 0.0)
    else:
        net = RaNAD(get_config("cpu-small-pdl-gall"), feature_dim("prior")).eval()
    assert net.config.layer_gate == gated
    denoise_then_aov(net, tmp_path)


def test_aov_command_through_the_cache_of_a_prior_range_model(tmp_path):
    """The prior-range reconstruction: the prior guides travel in the cached embeddings, so `ranad aov` gives the
    kernels the same range term and the light groups still sum to the denoised beauty."""
    denoise_then_aov(models()["prior-range"], tmp_path)


def test_aov_command_through_the_cache_and_refusals(tmp_path):
    run, src, model = denoise_then_aov(models()["single"], tmp_path)
    # one step: ranad denoise --aovs writes the same light groups
    r = run("denoise", src / "b.####.exr", "-o", tmp_path / "one" / "b.####.exr", "--model", model, "--aovs", "lg_*")
    assert r.exit_code == 0, r.output
    one, two = read_deep(tmp_path / "one" / "b.0001.exr"), read_deep(tmp_path / "a" / "lg.0001.exr")
    np.testing.assert_allclose(one.channel("lg_key.G"), two.channel("lg_key.G"), rtol=1e-5, atol=1e-6)
    # a stale cache: the beauty was re-rendered (other depths) after the cache was made
    img = read_deep(src / "b.0001.exr")
    vals = img.values.copy()
    vals[:, img.channels.index("Z")] *= 1.01
    write_deep(src / "b.0001.exr", img.with_values(vals))
    r = run("aov", tmp_path / "cache", "--layers", "lg_*", "-o", str(tmp_path / "a2") + "/")
    assert r.exit_code == 2 and "does not match this file's bin layout" in r.output
    # AOV files of another layout
    other = tmp_path / "other"
    other.mkdir()
    for f in range(3):
        shutil.copy(SHOT / f"noisy_spp16.{(f + 1) % 3:04d}.exr", other / f"x.{f:04d}.exr")
    shutil.copy(tmp_path / "cache" / "b.0000.ranadcache", tmp_path / "only0.ranadcache")
    r = run("aov", tmp_path / "only0.ranadcache", "--layers", "lg_*", "--input", other / "x.####.exr",
            "-o", tmp_path / "a3.exr")
    assert r.exit_code == 2 and "bin layout differs" in r.output
    r = run("aov", tmp_path / "only0.ranadcache", "--layers", "nope_*", "-o", tmp_path / "a4.exr")
    assert r.exit_code == 2 and "no AOV layers match" in r.output
    (tmp_path / "junk.ranadcache").write_bytes(b"junk" * 10)
    r = run("aov", tmp_path / "junk.ranadcache", "--layers", "lg_*", "-o", tmp_path / "a5.exr")
    assert r.exit_code == 2 and "not a ranad cache" in r.output
    # one bit flipped in the tensors' bytes (a disk or copy error; safetensors checks only the sizes)
    data = bytearray((tmp_path / "only0.ranadcache").read_bytes())
    data[-3] ^= 0x10
    (tmp_path / "flipped.ranadcache").write_bytes(bytes(data))
    r = run("aov", tmp_path / "flipped.ranadcache", "--layers", "lg_*", "--input", src / "b.0000.exr",
            "-o", tmp_path / "a6.exr")
    assert r.exit_code == 2 and "corrupt cache" in r.output and not (tmp_path / "a6.exr").exists()


def test_a_matching_layer_without_its_blue_is_named(tmp_path):
    """A light group with .R and .G but no .B matched the pattern and was left noisy without a word (the groups
    then no longer sum to the denoised beauty): `--aovs` and `ranad aov` name it."""
    chans = ["R", "G", "B", "lg_key.R", "lg_key.G", "lg_fill.R", "lg_fill.G", "lg_fill.B", "other.R"]
    assert list(aov_layers(chans, "lg_*")) == ["lg_fill"] and partial_layers(chans, "lg_*") == ["lg_key"]
    assert partial_layers(chans, "*") == ["lg_key", "other"]
    lower = ["LPE_rim.r", "LPE_rim.g", "LPE_rim.b", "LPE_key.R", "LPE_key.g"]   # Karma writes .r/.g/.b
    assert aov_layers(lower, "LPE_*") == {"LPE_rim": ("LPE_rim.r", "LPE_rim.g", "LPE_rim.b")}
    assert partial_layers(lower, "LPE_*") == ["LPE_key"]
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    write_deep(tmp_path / "nob.exr", img.select([c for c in img.channels if c != "lg_key.B"]))
    r = CliRunner().invoke(cli, ["denoise", str(tmp_path / "nob.exr"), "-o", str(tmp_path / "d.exr"), "--aovs", "lg_*",
                                 "--cache", str(tmp_path / "c")])
    assert r.exit_code == 0 and "AOV layer(s) lg_key match 'lg_*' but lack .R, .G or .B: left noisy" in r.output
    r = CliRunner().invoke(cli, ["aov", str(tmp_path / "c"), "--layers", "lg_*", "-o", str(tmp_path / "a.exr")])
    assert r.exit_code == 0 and "AOV layer(s) lg_key match 'lg_*'" in r.output, r.output
