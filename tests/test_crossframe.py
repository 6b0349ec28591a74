"""Cross-frame denoising: motion compensation moves bins exactly, windows shrink at sequence ends, and the
cross-frame model with one frame is the single-frame model it starts from."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from deep_factory import random_deep
from model_factory import input_keys_config
from ranad_cli.main import cli
from ranad_core import cache as cache_io
from ranad_core.denoise import denoise_window, receptive_field
from ranad_core.exr import read_deep
from ranad_core.exr.sequence import Frame
from ranad_core.model import RaNAD, feature_dim, get_config, prepare
from ranad_core.model.config import ModelConfig
from ranad_core.model.crossframe import CrossFrameRaNAD
from ranad_core.motion import FLOW_CHANNELS, compensate, displacement, rebucket
from ranad_core.shot import window_of

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"
CHANNELS = ("R", "G", "B", "A", "Z") + FLOW_CHANNELS


def moving(dx: float, dy: float, seed=0, w=13, h=9):
    img = random_deep(w, h, max_bins=3, seed=seed, ids=("id",), channels=CHANNELS,
                      types={c: "float" for c in FLOW_CHANNELS})
    vals = img.values.copy()
    for name, (x, y) in {"motion_next": (dx, dy), "motion_prev": (-dx, -dy)}.items():
        vals[:, img.channels.index(f"{name}.X")] = x
        vals[:, img.channels.index(f"{name}.Y")] = y
    return img.with_values(vals)


def test_exact_motion_reproduces_the_shifted_image():
    img = moving(3.2, -1.9)                         # rounds to (3, -2)
    centre = moving(0, 0, seed=1)
    (moved, same), dropped = compensate([img, centre], 1)
    assert same is centre
    w, h = img.width, img.height
    expect_drop = 0
    for y in range(h):
        for x in range(w):
            src = img.values[img.offsets[y * w + x]:img.offsets[y * w + x + 1]]
            tx, ty = x + 3, y - 2
            if 0 <= tx < w and 0 <= ty < h:
                p = ty * w + tx
                np.testing.assert_array_equal(moved.values[moved.offsets[p]:moved.offsets[p + 1]], src)
            else:
                expect_drop += len(src)
    assert dropped == expect_drop > 0
    # the ids travel with their bins
    kept = np.isin(img.ids["id"], moved.ids["id"])
    assert kept.sum() == img.num_bins - dropped


def test_rebucketing_keeps_every_bin_inside_the_frame():
    img = random_deep(16, 12, max_bins=4, seed=3, ids=())
    rng = np.random.default_rng(0)
    y, x = np.divmod(img.pixel_index(), img.width)
    d = rng.uniform(-3, 3, (img.num_bins, 2)).astype(np.float32)
    d[:, 0] = np.clip(x + d[:, 0], 0, img.width - 1) - x     # stays inside
    d[:, 1] = np.clip(y + d[:, 1], 0, img.height - 1) - y
    out, dropped = rebucket(img, d)
    assert dropped == 0 and out.num_bins == img.num_bins
    key = lambda v: np.sort(v.view(np.uint32), axis=0)  # noqa: E731
    np.testing.assert_array_equal(key(out.values), key(img.values))


def test_distant_frames_move_hop_by_hop():
    frames = [moving(1.0, 0.0, seed=s) for s in range(3)]
    d = displacement(frames, 0, 2)
    np.testing.assert_allclose(d, np.tile([2.0, 0.0], (frames[0].num_bins, 1)))
    d = displacement(frames, 2, 0)
    np.testing.assert_allclose(d, np.tile([-2.0, 0.0], (frames[2].num_bins, 1)))
    plain = random_deep(13, 9, seed=5, ids=())              # no motion channels: no motion
    assert not displacement([plain, plain], 0, 1).any()


def test_windows_shrink_at_the_ends_and_stop_at_gaps():
    seq = [Frame(f"f.{n}.exr", n) for n in (1, 2, 3, 4, 5, 7, 8)]
    names = lambda fs: [f.frame for f in fs]  # noqa: E731
    w, c = window_of(seq[0], seq, 3)
    assert names(w) == [1, 2] and c == 0
    w, c = window_of(seq[2], seq, 5)
    assert names(w) == [1, 2, 3, 4, 5] and c == 2
    w, c = window_of(seq[4], seq, 5)
    assert names(w) == [3, 4, 5] and c == 2                  # 6 is missing: the window stops
    w, c = window_of(seq[5], seq, 7)
    assert names(w) == [7, 8] and c == 0
    assert window_of(Frame("single.exr"), seq, 7) == ([Frame("single.exr")], 0)


def small_models():
    torch.manual_seed(0)
    single = RaNAD(get_config("cpu-small"), feature_dim()).eval()
    cross = CrossFrameRaNAD.from_single(single, get_config("cpu-small-xf"), feature_dim()).eval()
    return single, cross


def test_one_frame_window_is_the_single_frame_model():
    single, cross = small_models()
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    a = denoise_window(single, [img], 0).image
    b = denoise_window(cross, [img], 0).image
    np.testing.assert_array_equal(a.values, b.values)
    assert receptive_field(cross) > receptive_field(single)
    frames = [read_deep(SHOT / f"noisy_spp16.{i:04d}.exr") for i in range(3)]
    c = denoise_window(cross, frames, 1).image
    np.testing.assert_array_equal(c.offsets, frames[1].offsets)
    assert not np.array_equal(c.values, b.values)            # the neighbours do change the result


def test_output_mix_starts_from_a_cross_frame_model_and_keeps_the_rules():
    """cpu-small-xfm from a cpu-small-xf model: with its gates shut it is that model; with one frame it is the
    single-frame model; opened, it changes the result, tiles still equal the whole frame (its step is inside the
    halo), and gradients reach it."""
    single, cross = small_models()
    mixed = CrossFrameRaNAD.from_cross(cross, get_config("cpu-small-xfm"), feature_dim()).eval()
    frames = [read_deep(SHOT / f"noisy_spp16.{i:04d}.exr") for i in range(3)]
    for g in mixed.mix_gate.values():
        torch.nn.init.constant_(g.bias, -1e4)
    np.testing.assert_array_equal(denoise_window(mixed, frames, 1).image.values,
                                  denoise_window(cross, frames, 1).image.values)
    np.testing.assert_array_equal(denoise_window(mixed, frames[1:2], 0).image.values,
                                  denoise_window(single, frames[1:2], 0).image.values)
    assert receptive_field(mixed) > receptive_field(cross)
    for g in mixed.mix_gate.values():
        torch.nn.init.constant_(g.bias, 0.0)
    whole = denoise_window(mixed, frames, 1).image.values
    assert np.abs(whole - denoise_window(cross, frames, 1).image.values).max() > 1e-3
    np.testing.assert_allclose(denoise_window(mixed, frames, 1, tile=16).image.values, whole, rtol=1e-4, atol=1e-5)
    mixed.train()
    window = [prepare(f.sorted()[0]) for f in compensate([f.crop((0, 0, 23, 23)) for f in frames], 1)[0]]
    sum(v.square().mean() for v in mixed(window, 1).values()).backward()
    for name in ("mix.diffuse.q.weight", "mix_gate.diffuse.bias", "temporal.diffuse.k.weight"):
        g = dict(mixed.named_parameters())[name].grad
        assert g is not None and g.abs().max() > 0, name
    with pytest.raises(ValueError):                          # a model of another backbone does not fit
        CrossFrameRaNAD.from_cross(single, get_config("cpu-small-xfm"), feature_dim())


def test_input_keys_leave_the_centre_features_alone():
    """A cross-frame model keyed by the bins' inputs (no T-Mix): with one frame, or its temporal gates shut, it
    is the single-frame model; the centre's backbone features do not depend on the neighbours; opened, the
    neighbours change the result, tiles equal the whole frame, the halo bound is the single model's plus the
    temporal step's, and gradients reach the key embedding."""
    single, cross = small_models()
    keyed = CrossFrameRaNAD.from_single(single, input_keys_config(), feature_dim()).eval()
    assert len(keyed.tmix) == 0
    frames = [read_deep(SHOT / f"noisy_spp16.{i:04d}.exr") for i in range(3)]
    one = denoise_window(single, frames[1:2], 0).image.values
    np.testing.assert_array_equal(denoise_window(keyed, frames[1:2], 0).image.values, one)
    for g in keyed.temporal_gate.values():
        torch.nn.init.constant_(g.bias, -1e4)
    np.testing.assert_allclose(denoise_window(keyed, frames, 1).image.values, one, rtol=1e-6, atol=1e-7)
    assert receptive_field(single) < receptive_field(keyed) < receptive_field(cross)
    for g in keyed.temporal_gate.values():
        torch.nn.init.constant_(g.bias, 0.0)
    whole = denoise_window(keyed, frames, 1).image.values
    assert np.abs(whole - one).max() > 1e-3
    np.testing.assert_allclose(denoise_window(keyed, frames, 1, tile=16).image.values, whole, rtol=1e-4, atol=1e-5)
    moved = compensate([f.crop((0, 0, 23, 23)) for f in frames], 1)[0]
    window = [prepare(f.sorted()[0]) for f in moved]
    other = [prepare(f.sorted()[0]) for f in moved]
    other[0].features = other[0].features.flip(0)            # a neighbour with other contents
    with torch.no_grad():
        a, b = keyed.embeddings(window, 1), keyed.embeddings(other, 1)
        dim = keyed.config.dim
        torch.testing.assert_close(a[1][:, :dim], b[1][:, :dim], rtol=0, atol=0)
        assert not torch.equal(a[0], b[0])
        torch.testing.assert_close(a[1][:, :dim], single.embeddings(window[1]), rtol=1e-5, atol=1e-5)
    keyed.train()
    sum(v.square().mean() for v in keyed(window, 1).values()).backward()
    for name in ("temporal_embed.0.weight", "temporal.diffuse.k.weight", "temporal_gate.alpha.bias"):
        g = dict(keyed.named_parameters())[name].grad
        assert g is not None and g.abs().max() > 0, name
    with pytest.raises(ValueError):                          # no per-frame features for an output mix
        CrossFrameRaNAD(ModelConfig(**{**keyed.config.__dict__, "output_mix": True}), feature_dim())


def test_gradients_reach_the_temporal_modules():
    _, cross = small_models()
    cross.train()
    for t in cross.tmix:   # zero-initialised output projections block q/k gradients until the first step
        torch.nn.init.normal_(t.attn.out.weight, std=0.01)
    frames = [read_deep(SHOT / f"noisy_spp16.{i:04d}.exr").crop((0, 0, 23, 23)) for i in range(3)]
    moved, _ = compensate(frames, 1)
    window = [prepare(f.sorted()[0]) for f in moved]
    out = cross(window, 1)
    sum(v.square().mean() for v in out.values()).backward()
    for name in ("tmix.0.attn.out.weight", "tmix.1.attn.q.weight", "single.embed.0.weight", "temporal.diffuse.q.weight",
                 "temporal_gate.alpha.bias"):
        g = dict(cross.named_parameters())[name].grad
        assert g is not None and g.abs().max() > 0, name


def cross_model_file(cross, path, **metadata) -> Path:
    """`cross` saved as a model file `ranad denoise --model` reads (its config, and `metadata` beside it)."""
    from safetensors.torch import save_file

    save_file({k: v.contiguous() for k, v in cross.state_dict().items()}, str(path),
              metadata={"model_config": json.dumps(cross.config.to_dict()), **metadata})
    return path


def test_the_profile_tells_the_halo_from_the_windows_other_frames(tmp_path):
    """--profile on a cross-frame shot: the halo overlap is the centre frame's (whole-frame tiles: 1.00x), and the
    neighbours' bins a tile also holds are named apart (they were counted as halo overlap: 2-3x)."""
    _, cross = small_models()
    model = cross_model_file(cross, tmp_path / "xf.safetensors")
    r = CliRunner().invoke(cli, ["denoise", str(SHOT / "noisy_spp16.####.exr"), "-o", str(tmp_path / "d.####.exr"),
                                 "--model", str(model), "--profile", "--bin-merge", "0"])   # the files' own bins
    assert r.exit_code == 0, r.output
    m = re.search(r"3 tile\(s\): (\d+)-(\d+) bins with the halo, ([\d.]+)x the frame's bins computed \(halo "
                  r"overlap\), (\d+)-(\d+) with the window's other frames;", r.output)
    assert m, r.output
    b = [read_deep(SHOT / f"noisy_spp16.000{i}.exr").num_bins for i in range(3)]
    assert (int(m.group(1)), int(m.group(2))) == (min(b), max(b)) and float(m.group(3)) == 1.0
    # every window holds a neighbour's bins besides its own, at most the three frames' (motion carries some out)
    assert max(b) < int(m.group(4)) <= int(m.group(5)) <= sum(b)


def test_denoise_with_a_window_caches_every_frame(tmp_path):
    _, cross = small_models()
    model = cross_model_file(cross, tmp_path / "xf.safetensors")
    r = CliRunner().invoke(cli, ["denoise", str(SHOT / "noisy_spp16.####.exr"), "-o", str(tmp_path / "d.####.exr"),
                                 "--model", str(model), "--cache", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    t, meta = cache_io.read_cache(cache_io.cache_path(str(tmp_path / "c"), str(tmp_path / "d.0001.exr")))
    assert len(json.loads(meta["window"])) == 3 and meta["centre"] == "1" and "embeddings.2" in t
    t, meta = cache_io.read_cache(cache_io.cache_path(str(tmp_path / "c"), str(tmp_path / "d.0000.exr")))
    assert len(json.loads(meta["window"])) == 2 and meta["centre"] == "0"
    r = CliRunner().invoke(cli, ["denoise", str(SHOT / "noisy_spp16.####.exr"), "-o", str(tmp_path / "e.####.exr"),
                                 "--model", str(model), "--window", "1", "--cache", str(tmp_path / "c1")])
    assert r.exit_code == 0, r.output
    t, meta = cache_io.read_cache(cache_io.cache_path(str(tmp_path / "c1"), str(tmp_path / "e.0001.exr")))
    assert len(json.loads(meta["window"])) == 1


def shot_stripped_in_frame_1(tmp_path, prefixes: tuple) -> tuple:
    """(a small cross-frame model file, a folder s.0000-0002.exr): the bundled shot's first three frames with frame
    1's channels starting with `prefixes` left out (a frame that lacks what its neighbours have)."""
    from ranad_core.exr import read_deep, write_deep

    _, cross = small_models()
    model = cross_model_file(cross, tmp_path / "xf.safetensors")
    shot = tmp_path / "shot"
    shot.mkdir()
    for n in range(3):
        img = read_deep(SHOT / f"noisy_spp16.{n:04d}.exr")
        if n == 1:
            img = img.select([c for c in img.channels if not c.startswith(prefixes)])
        write_deep(shot / f"s.{n:04d}.exr", img)
    return model, shot


def test_a_neighbour_without_the_centres_channels_is_named(tmp_path):
    """The centre frame's channel map reads every frame of its window: a neighbour without the diffuse/specular
    split was a KeyError (internal error, exit 1); now a one-line error naming that frame, nothing written."""
    model, shot = shot_stripped_in_frame_1(tmp_path, ("diffuse.", "specular."))
    r = CliRunner().invoke(cli, ["denoise", str(shot / "s.####.exr"), "-o", str(tmp_path / "out" / "d.####.exr"),
                                 "--model", str(model)])
    assert r.exit_code == 2 and "s.0001.exr: lacks channel(s) diffuse.R" in r.output, r.output
    assert "that s.0000.exr has" in r.output and not list((tmp_path / "out").glob("*.exr"))


def test_a_centre_frame_without_motion_reads_its_neighbours(tmp_path):
    """Frames 0 and 2 carry motion, frame 1 not: the map detected on frame 1 had no motion, so its window ran
    unaligned and the run warned that no motion channels were mapped. The neighbours' motion now carries them
    (one direction is enough), without that warning."""
    from ranad_core.exr import read_deep

    for n in range(3):
        assert "motion_next.X" in read_deep(SHOT / f"noisy_spp16.{n:04d}.exr").channels
    model, shot = shot_stripped_in_frame_1(tmp_path, ("motion_prev", "motion_next"))
    r = CliRunner().invoke(cli, ["denoise", str(shot / "s.####.exr"), "-o", str(tmp_path / "out" / "d.####.exr"),
                                 "--model", str(model)])
    assert r.exit_code == 0 and "WITHOUT motion compensation" not in r.output, r.output


def test_default_window_is_the_training_window(tmp_path):
    """Without --window a cross-frame model runs with the window its train_config records (offsets it never
    saw in training stay unused); files without that record get 3."""
    from ranad_core.model.store import LoadedModel, training_window

    _, cross = small_models()
    meta = lambda tc: LoadedModel(cross, "m", {"train_config": tc})  # noqa: E731
    assert training_window(meta(json.dumps({"window": 5}))) == 5
    assert training_window(meta(json.dumps({"window": 9}))) == cross.config.window   # capped by the architecture
    assert training_window(meta(json.dumps({}))) == 3
    assert training_window(LoadedModel(cross, "m", {})) == 3
    assert training_window(meta("not json")) == 3
    model = cross_model_file(cross, tmp_path / "xf1.safetensors", train_config=json.dumps({"window": 1}))
    r = CliRunner().invoke(cli, ["denoise", str(SHOT / "noisy_spp16.####.exr"), "-o", str(tmp_path / "d.####.exr"),
                                 "--model", str(model), "--cache", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    _, m = cache_io.read_cache(cache_io.cache_path(str(tmp_path / "c"), str(tmp_path / "d.0001.exr")))
    assert len(json.loads(m["window"])) == 1


def _flat(img):
    """Composited R, G, B (bins in depth order, 'over')."""
    names = [c for c in ("R", "G", "B", "A", "Z", "ZBack") if c in img.channels]
    b = img.with_values(img.values[:, [img.channels.index(c) for c in names]], names)
    b.ids = {}
    return b.flatten()[..., :3].astype(np.float64)


def _tonemap(x):
    x = np.maximum(x, 0)
    return x / (1 + x)


def _temporal_error(outs, refs):
    """Mean over consecutive frames of mean |(T(o[t+1]) - T(o[t])) - (T(r[t+1]) - T(r[t]))|, T = x / (1 + x)."""
    return float(np.mean([np.mean(np.abs((_tonemap(outs[t + 1]) - _tonemap(outs[t]))
                                         - (_tonemap(refs[t + 1]) - _tonemap(refs[t]))))
                          for t in range(len(outs) - 1)]))


def test_reference_noise_floor_is_what_a_perfect_denoiser_scores():
    """The floor `ranad eval --temporal` prints, estimated from the noisy input's temporal error, against a
    simulation: a static scene, noisy frames at spp and references at ref_spp with independent noise of spread
    1/sqrt(samples); a perfect denoiser (the true image) scores the references' own flicker."""
    from ranad_core.evaluate import reference_noise_floor

    rng = np.random.default_rng(0)
    truth = rng.uniform(0.05, 0.3, (64, 64, 3))
    rows = []
    perfect = []
    for spp, ref_spp in ((4, 64), (16, 1024), (64, 256)):
        render = lambda n: truth + 0.05 * rng.standard_normal(truth.shape) / np.sqrt(n)  # noqa: E731
        noisy, refs = [render(spp) for _ in range(5)], [render(ref_spp) for _ in range(5)]
        rows.append({"spp": spp, "ref_spp": ref_spp, "method": "noisy", "temporal": _temporal_error(noisy, refs)})
        perfect.append(_temporal_error([truth] * 5, refs))
    floors = reference_noise_floor(rows)
    assert list(floors) == [4, 16, 64]
    for (spp, floor), want in zip(floors.items(), perfect):
        assert floor == pytest.approx(want, rel=0.03), spp


def test_temporal_eval_compares_single_and_cross_frame(tmp_path):
    """A shot whose frames 0 and 2 use the noisy frame itself as reference (plumbing; frame 1 has a real one)."""
    import shutil

    import pytest

    pytest.importorskip("pyoidn", reason="the OIDN baseline needs pyoidn (pip install 'ranad[eval]')")
    pytest.importorskip("flip_evaluator", reason="HDR-FLIP needs flip-evaluator (pip install 'ranad[eval]')")
    from safetensors.torch import save_file

    scene = tmp_path / "ds" / "scene_0000"
    (scene / "deepoid").mkdir(parents=True)
    for f in range(3):
        shutil.copy(SHOT / f"noisy_spp16.{f:04d}.exr", scene / "deepoid" / f"noisy_spp16.{f:04d}.exr")
        src = SHOT / (f"reference_spp16.{f:04d}.exr" if f == 1 else f"noisy_spp16.{f:04d}.exr")
        shutil.copy(src, scene / "deepoid" / f"reference_spp16.{f:04d}.exr")
    m = json.loads((SHOT / "manifest.json").read_text())
    m["reference_frames"] = [0, 1, 2]
    (scene / "manifest.json").write_text(json.dumps(m))
    single, cross = small_models()
    paths = {}
    for name, model in (("single", single), ("cross", cross)):
        paths[name] = str(tmp_path / f"{name}.safetensors")
        save_file({k: v.contiguous() for k, v in model.state_dict().items()}, paths[name],
                  metadata={"model_config": json.dumps(model.config.to_dict())})
    out = tmp_path / "ev"
    r = CliRunner().invoke(cli, ["eval", str(tmp_path / "ds"), "-o", str(out), "--temporal", "--model",
                                 paths["single"], "--cross-model", paths["cross"]])
    assert r.exit_code == 0, r.output
    import csv

    rows = {row["method"]: row for row in csv.DictReader(open(out / "temporal.csv"))}
    assert set(rows) == {"noisy", "oidn", "ranad", "ranad-xf"}
    assert float(rows["ranad-xf"]["seconds"]) > 0 and "| 16 | ranad-xf | 1 |" in r.output
    # the temporal errors recomputed here: references n0, r1, n2 (n: noisy frames, r1: frame 1's reference);
    # the noisy input's error then reduces to mean |T(n1) - T(r1)|
    noisy = [read_deep(SHOT / f"noisy_spp16.{f:04d}.exr") for f in range(3)]
    refs = [_flat(noisy[0]), _flat(read_deep(SHOT / "reference_spp16.0001.exr")), _flat(noisy[2])]
    want_noisy = float(np.mean(np.abs(_tonemap(_flat(noisy[1])) - _tonemap(refs[1]))))
    assert float(rows["noisy"]["temporal"]) == pytest.approx(want_noisy, rel=1e-4)
    assert _temporal_error([_flat(n) for n in noisy], refs) == pytest.approx(want_noisy, rel=1e-6)
    single_outs = [_flat(denoise_window(single, [n], 0).image) for n in noisy]
    windows = [([0, 1], 0), ([0, 1, 2], 1), ([1, 2], 1)]            # up to 3 frames, shorter at the ends
    cross_outs = [_flat(denoise_window(cross, [noisy[i] for i in w], c).image) for w, c in windows]
    for method, outs in (("ranad", single_outs), ("ranad-xf", cross_outs)):   # the CSV keeps 6 digits
        assert float(rows[method]["temporal"]) == pytest.approx(_temporal_error(outs, refs), rel=1e-5), method
    # (the untrained cross-frame model barely uses its neighbours: one-frame windows, i.e. the single-frame
    # model, would be off by more than 10x this tolerance)
    assert abs(_temporal_error(cross_outs, refs) / _temporal_error(single_outs, refs) - 1) > 1e-4
    from ranad_core.metrics import flip                               # FLIP: 0 on frames 0 and 2 (ref = input)
    assert float(rows["noisy"]["flip"]) == pytest.approx(flip(refs[1], _flat(noisy[1])) / 3, rel=1e-4)
    floor = float(re.search(r"([\d.]+) at 16 spp", r.output).group(1))
    assert 0 < floor < want_noisy
    r = CliRunner().invoke(cli, ["eval", str(SHOT.parent), "-o", str(out), "--temporal", "--model", paths["single"],
                                 "--cross-model", paths["cross"]])
    assert r.exit_code == 2


def test_default_model_follows_the_shot():
    """Without --model: the cross-frame model when some frames are consecutive (and --window is not 1), else the
    single-frame one (one frame, frames without numbers, or numbers with gaps only)."""
    from ranad_core.model.store import DEFAULT_CROSS_MODEL, DEFAULT_MODEL, default_model_for

    assert default_model_for([1, 2, 3], None) == DEFAULT_CROSS_MODEL
    assert default_model_for([10, 12, 13], 5) == DEFAULT_CROSS_MODEL
    assert default_model_for([1, 2, 3], 1) == DEFAULT_MODEL
    assert default_model_for([1, 3, 5], None) == DEFAULT_MODEL
    assert default_model_for([None], None) == DEFAULT_MODEL
    assert default_model_for([7], None) == DEFAULT_MODEL


def test_default_pair_shares_its_spatial_weights():
    """A shot's frames get the spatial model a single frame gets: the default cross-frame model's single-frame part
    holds the default single-frame model's weights bit for bit (trained with --freeze-spatial from them), so `ranad
    denoise` of a sequence and of one of its frames alone differ only by what the neighbours bring."""
    from ranad_core.model.store import DEFAULT_CROSS_MODEL, DEFAULT_MODEL, load_model

    single = load_model(DEFAULT_MODEL).model.state_dict()
    cross = load_model(DEFAULT_CROSS_MODEL).model.state_dict()
    inner = {k[len("single."):]: v for k, v in cross.items() if k.startswith("single.")}
    assert inner.keys() == single.keys()
    w, n = inner["embed.0.weight"], single["embed.0.weight"].shape[1]
    assert not w[:, n:].any()   # the frame one-hot columns (CrossFrameRaNAD.from_single), zero and frozen
    inner["embed.0.weight"] = w[:, :n]
    differ = [k for k, v in single.items() if not torch.equal(v, inner[k])]
    assert not differ, f"{DEFAULT_CROSS_MODEL} was not trained on {DEFAULT_MODEL}: {differ[:3]}"


def test_the_windows_copies_are_freed_before_its_tiles(monkeypatch):
    """denoise_window's copies of a window's frames with the flat prior's channels attached, and the neighbours
    compensated onto the centre (every channel of the files, 1.5 GB of a 2-frame 1080p window), are not read once
    the model's frames are made: no array of theirs may still be alive when the tiles run (held through them, a
    2-frame 1080p window at --max-memory 4G went over the ceiling)."""
    import weakref

    from ranad_core import denoise as denoise_mod
    from ranad_core import motion
    from ranad_core.model.store import DEFAULT_CROSS_MODEL, load_model

    copies = []
    compensate = motion.compensate

    def spy_compensate(sources, centre, **kwargs):
        moved, dropped = compensate(sources, centre, **kwargs)
        copies.extend(weakref.ref(im.values) for im in (*sources, *moved))
        return moved, dropped

    alive = []
    tile_inputs = denoise_mod._tile_inputs

    def spy_tile_inputs(fr, win, width):
        alive.append(sum(ref() is not None for ref in copies))
        return tile_inputs(fr, win, width)

    monkeypatch.setattr(motion, "compensate", spy_compensate)
    monkeypatch.setattr(denoise_mod, "_tile_inputs", spy_tile_inputs)
    frames = [read_deep(SHOT / f"noisy_spp16.{i:04d}.exr") for i in range(3)]
    denoise_window(load_model(DEFAULT_CROSS_MODEL).model, frames, 1)
    assert len(copies) == 6 and alive and max(alive) == 0
