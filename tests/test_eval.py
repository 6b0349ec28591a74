"""Evaluation: metrics behave (zero on identical inputs, edits do what they say), the baselines keep their
promises (recolour flattens to the flat image it was given), weights round-trip, `ranad eval` makes its table."""

from __future__ import annotations

import csv
import importlib.util
import math
import shutil

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from deep_factory import random_deep
from ranad_cli.main import cli
from ranad_core import metrics
from ranad_core.baselines import recolour
from ranad_core.denoise import denoise_frame
from ranad_core.exr import read_deep
from ranad_core.model import RaNAD, feature_dim, get_config
from ranad_core.model.store import export_weights, load_model
from test_train import SHOT, dataset_from_example

# per test, so that the tests needing neither still run where the eval extras are not installed
needs_oidn = pytest.mark.skipif(importlib.util.find_spec("pyoidn") is None,
                                reason="the OIDN baseline needs pyoidn (pip install 'ranad[eval]')")
needs_flip = pytest.mark.skipif(importlib.util.find_spec("flip_evaluator") is None,
                                reason="HDR-FLIP needs flip-evaluator (pip install 'ranad[eval]')")


def untrained_run(tmp_path):
    torch.manual_seed(0)
    model = RaNAD(get_config("cpu-small"), feature_dim())
    run = tmp_path / "run"
    run.mkdir()
    torch.save({"model": model.state_dict(), "model_config": model.config.to_dict(), "step": 0}, run / "checkpoint.pt")
    return run


def beauty_image(seed=0):
    img = random_deep(24, 20, max_bins=4, seed=seed, ids=(), channels=("R", "G", "B", "A", "Z"))
    vals = img.values.copy()
    vals[:, 3] = np.clip(vals[:, 3] / 4, 0.05, 1)
    vals[:, :3] *= vals[:, 3:4]                      # premultiplied colour
    return img.with_values(vals)


@needs_flip
def test_metrics_are_zero_on_identical_images_and_grow_with_noise():
    img = beauty_image()
    flat = metrics.flat_rgb(img)
    assert metrics.flat_scores(flat, flat) == {"smape": 0.0, "dssim": pytest.approx(0, abs=1e-6), "flip": 0.0}
    deep = metrics.deep_scores(img, img)
    assert all(v == pytest.approx(0, abs=1e-6) for v in deep.values())
    rng = np.random.default_rng(1)
    noisy = img.with_values(img.values * rng.uniform(0.5, 1.5, img.values.shape).astype(np.float32))
    worse = img.with_values(img.values * rng.uniform(0.1, 1.9, img.values.shape).astype(np.float32))
    s1, s2 = metrics.flat_scores(flat, metrics.flat_rgb(noisy)), metrics.flat_scores(flat, metrics.flat_rgb(worse))
    assert 0 < s1["flip"] < s2["flip"] and 0 < s1["smape"] < s2["smape"] and 0 < s1["dssim"] < s2["dssim"]


def test_light_is_the_share_of_the_references_luminance():
    """`light`: a dimmed copy holds its factor of the light, a copy with one pixel's light moved to another the
    same light (spread or gathered light is not lost), a black reference gives NaN."""
    flat = metrics.flat_rgb(beauty_image()).astype(np.float64)
    assert metrics.light(flat, flat) == pytest.approx(1.0)
    assert metrics.light(flat, 0.5 * flat) == pytest.approx(0.5)
    moved = flat.copy()
    ys, xs = np.nonzero(flat.sum(2) > 0)
    moved[ys[1], xs[1]] += moved[ys[0], xs[0]]
    moved[ys[0], xs[0]] = 0
    assert metrics.light(flat, moved) == pytest.approx(1.0)
    assert np.isnan(metrics.light(np.zeros_like(flat), flat))


def _over(bins):
    """Front-to-back 'over' of [(z, (r, g, b), a)] premultiplied point samples at distinct depths (float64)."""
    rgb, acc = np.zeros(3), 0.0
    for _, c, a in sorted(bins, key=lambda b: b[0]):
        rgb += (1 - acc) * np.asarray(c, np.float64)
        acc += (1 - acc) * a
    return rgb


def test_edits_recolour_the_front_and_insert_a_layer():
    """The compositing edit and the depth slices against a pixel-by-pixel composite written out here: bins in
    front of the split recoloured by the protocol's gain (1.6, 0.8, 0.5), a layer of premultiplied colour
    (0.08, 0.25, 0.6) and alpha 0.5 inserted at the split depth."""
    gain, layer = np.array([1.6, 0.8, 0.5]), ((0.08, 0.25, 0.6), 0.5)
    img = beauty_image()
    rgb, a, z = img.values[:, :3].astype(np.float64), img.values[:, 3].astype(np.float64), img.channel("Z")
    assert len(np.unique(z)) == img.num_bins                      # distinct depths: no coincident samples
    assert metrics.split_depth(img) == pytest.approx(float(np.median(z)))
    split = float(np.sort(z)[img.num_bins // 2 - 1] + np.sort(z)[img.num_bins // 2]) / 2   # between two bins
    edit = metrics.composite_edit(img, split).reshape(-1, 3)
    front, back = (s.reshape(-1, 3) for s in metrics.depth_slices(img, split))
    kinds = set()
    for p in range(img.num_pixels):
        b = range(img.offsets[p], img.offsets[p + 1])
        fg = [i for i in b if z[i] < split]
        bg = [i for i in b if z[i] >= split]
        kinds.add((bool(fg), bool(bg)))
        want = _over([(z[i], rgb[i] * (gain if z[i] < split else 1), a[i]) for i in b] + [(split, *layer)])
        np.testing.assert_allclose(edit[p], want, rtol=1e-5, atol=1e-6, err_msg=f"pixel {p}")
        np.testing.assert_allclose(front[p], _over([(z[i], rgb[i], a[i]) for i in fg]), rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(back[p], _over([(z[i], rgb[i], a[i]) for i in bg]), rtol=1e-5, atol=1e-6)
    assert {(False, False), (True, False), (False, True), (True, True)} <= kinds   # every case was checked
    # a pixel with no bins shows only the inserted layer
    empty = int(np.flatnonzero(img.counts == 0)[0])
    np.testing.assert_allclose(edit[empty], layer[0], rtol=1e-6)


def test_recolour_flattens_to_the_given_image_and_keeps_the_layout():
    img = beauty_image(3)
    target = metrics.flat_rgb(img) * np.float32(0.5) + np.float32(0.01)
    out = recolour(img, target)
    np.testing.assert_array_equal(out.offsets, img.offsets)
    covered = (img.counts > 0).reshape(img.height, img.width)
    np.testing.assert_allclose(metrics.flat_rgb(out)[covered], target[covered], rtol=2e-4, atol=1e-5)


def test_model_id_names_the_content_not_the_file_bytes(tmp_path):
    """Exporting one checkpoint twice (safetensors orders metadata keys differently per write) gives one id, the
    checkpoint's own; another tensor value or another note gives another."""
    import torch
    from ranad_core.model.store import content_digest

    run = untrained_run(tmp_path)
    a = export_weights(run, tmp_path / "a.safetensors")
    b = export_weights(run, tmp_path / "b.safetensors")
    ids = {load_model(str(p)).model_id.split("@")[1] for p in (run, a, b)}
    assert len(ids) == 1
    assert load_model(str(export_weights(run, tmp_path / "c.safetensors", {"data": "x"}))).model_id.split("@")[1] \
        not in ids
    state = {"w": torch.zeros(3), "b": torch.ones(2, dtype=torch.bfloat16)}
    d = content_digest(state, {"k": "1", "j": "2"})
    assert d == content_digest(dict(reversed(list(state.items()))), {"j": "2", "k": "1"})
    assert d != content_digest({**state, "w": torch.tensor([0.0, 0.0, 1e-30])}, {"k": "1", "j": "2"})
    assert d != content_digest(state, {"k": "1", "j": "3"})


def test_weights_round_trip_and_denoise_keeps_the_layout(tmp_path):
    run = untrained_run(tmp_path)
    path = export_weights(run, tmp_path / "m.safetensors", {"data": "test"})
    a, b = load_model(str(run)), load_model(str(path))
    assert b.metadata["data"] == "test" and b.model_id.startswith("m@")
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    out_a, out_b = denoise_frame(a.model, img).image, denoise_frame(b.model, img).image
    np.testing.assert_array_equal(out_a.values, out_b.values)
    np.testing.assert_array_equal(out_a.offsets, img.offsets)
    np.testing.assert_array_equal(out_a.ids["id"], img.ids["id"])
    assert out_a.channels == img.channels and out_a.header == img.header
    alpha = out_a.channel("A")
    assert alpha.min() >= 0 and alpha.max() <= 1 and np.isfinite(out_a.values).all()
    ch = img.channels
    def layers_sum(im):
        return sum(im.values[:, [ch.index(f"{l}.{c}") for c in "RGB"]] for l in ("diffuse", "specular", "emission"))

    # the beauty is rebuilt from its layers plus the denoised residual (a convex mix of the noisy residuals)
    residual = np.abs(img.values[:, [ch.index(c) for c in "RGB"]] - layers_sum(img)).max()
    np.testing.assert_allclose(out_a.values[:, [ch.index(c) for c in "RGB"]], layers_sum(out_a), rtol=0,
                               atol=residual * 1.001 + 1e-6)
    untouched = [c for c in ch if c.split(".")[0] in ("albedo", "N", "emission", "lg_key", "coverage")]
    np.testing.assert_array_equal(out_a.select(untouched).values, img.select(untouched).values)


def test_bad_model_files_are_refused(tmp_path):
    from ranad_core.errors import RanadError

    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(b"not weights")
    with pytest.raises(RanadError, match="not a ranad model"):
        load_model(str(bad))
    with pytest.raises(RanadError, match="no such model"):
        load_model("no-such-model")


@needs_oidn
@needs_flip
def test_eval_command_writes_table_csv_and_grid(tmp_path):
    ds = dataset_from_example(tmp_path / "ds")
    run = untrained_run(tmp_path)
    out = tmp_path / "ev"
    r = CliRunner().invoke(cli, ["eval", str(ds), "-o", str(out), "--model", str(run), "--grid", "1"])
    assert r.exit_code == 0, r.output
    assert "| 16 | ranad | 1 |" in r.output and "| 16 | oidn | 1 |" in r.output
    rows = list(csv.DictReader(open(out / "eval.csv")))
    # the example has albedo and normal: OIDN with its guides prefiltered, and the recolour from it, are scored too
    assert [row["method"] for row in rows] == ["noisy", "oidn", "oidn-clean", "recolour", "recolour-clean", "ranad"]
    noisy, oidn, clean = rows[0], rows[1], rows[2]
    assert float(oidn["flip"]) < float(noisy["flip"])          # OIDN really denoised
    assert float(clean["flip"]) < float(noisy["flip"]) and clean["flip"] != oidn["flip"]
    table = (out / "eval.md").read_text()
    assert "| 16 | oidn-clean | 1 |" in table and "| 16 | recolour-clean | 1 |" in table
    assert 0.5 < float(noisy["light"]) < 2 and "| light |" in (out / "eval.md").read_text()
    assert math.isnan(float(oidn["comp_flip"])) and float(noisy["comp_flip"]) > 0
    assert (out / "grid.png").stat().st_size > 1000 and (out / "eval.md").is_file()
    r = CliRunner().invoke(cli, ["eval", str(ds), "-o", str(out), "--model", str(run), "--spp", "7"])
    assert r.exit_code == 2 and "no pairs match" in r.output


@needs_oidn
def test_oidn_with_prefiltered_guides_denoises_the_guides_first():
    """oidn_flat(clean_aux=True): OIDN's own filters really denoise a noisy albedo (closer to the clean one than the
    noisy guide was), the beauty is then denoised from the cleaned guides (not the plain result), and a frame
    without guides gets plain OIDN."""
    import pyoidn

    from ranad_core.baselines import oidn_flat, prefiltered

    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[0:64, 0:64] / 64.0
    albedo = np.stack([0.2 + 0.6 * (xx > 0.5), 0.3 + 0.4 * yy, np.full_like(xx, 0.5)], -1).astype(np.float32)
    noisy_albedo = np.clip(albedo + rng.normal(0, 0.15, albedo.shape), 0, 1).astype(np.float32)
    cleaned = prefiltered(pyoidn, "albedo", noisy_albedo)
    assert np.abs(cleaned - albedo).mean() < 0.5 * np.abs(noisy_albedo - albedo).mean()

    img = random_deep(32, 24, max_bins=3, seed=5, ids=(), channels=("R", "G", "B", "A", "Z", "albedo.R", "albedo.G",
                                                                    "albedo.B", "N.X", "N.Y", "N.Z"))
    plain, clean = oidn_flat(img), oidn_flat(img, clean_aux=True)
    assert plain.shape == clean.shape == (24, 32, 3) and np.isfinite(clean).all()
    assert not np.array_equal(plain, clean)
    bare = random_deep(32, 24, max_bins=3, seed=5, ids=(), channels=("R", "G", "B", "A", "Z"))
    assert np.array_equal(oidn_flat(bare), oidn_flat(bare, clean_aux=True))


def test_eval_names_what_it_cannot_score(tmp_path):
    """A noisy file without its reference was dropped without a word (or 'no pairs match' with nothing else);
    a manifest.json that is no JSON was an internal error in eval and train."""
    ds = dataset_from_example(tmp_path / "ds")
    shutil.copytree(ds / "scene_0000", ds / "scene_0001")
    ref = next((ds / "scene_0000" / "deepoid").glob("reference_spp16.*.exr"))
    ref.unlink()
    run = untrained_run(tmp_path)
    r = CliRunner().invoke(cli, ["eval", str(ds), "-o", str(tmp_path / "ev"), "--model", str(run), "--grid", "0"])
    assert r.exit_code == 0 and f"1 noisy file(s) without their reference are not scored, e.g. {ref}" in r.output
    shutil.rmtree(ds / "scene_0001")
    r = CliRunner().invoke(cli, ["eval", str(ds), "-o", str(tmp_path / "ev"), "--model", str(run)])
    assert r.exit_code == 2 and "no complete scenes" in r.output and f"have no reference, e.g. {ref}" in r.output
    (ds / "scene_0000" / "manifest.json").write_text("{not json")
    for args in (["eval", str(ds), "-o", str(tmp_path / "ev2"), "--model", str(run)],
                 ["train", str(ds), "-o", str(tmp_path / "tr"), "--steps", "1"]):
        r = CliRunner().invoke(cli, args)
        assert r.exit_code == 2 and "manifest.json: not a scene manifest" in r.output, r.output


def test_shipped_default_model_denoises_the_example():
    """The shipped weights load by name and bring the example's frame closer to its reference."""
    from ranad_core import metrics
    from ranad_core.model.store import DEFAULT_MODEL, shipped_models

    assert DEFAULT_MODEL in shipped_models()
    loaded = load_model(None)
    assert loaded.model_id.startswith(DEFAULT_MODEL + "@")
    noisy, ref = read_deep(SHOT / "noisy_spp16.0001.exr"), read_deep(SHOT / "reference_spp16.0001.exr")
    flat_ref = metrics.flat_rgb(ref)
    before = metrics.smape(flat_ref, metrics.flat_rgb(noisy))
    after = metrics.smape(flat_ref, metrics.flat_rgb(denoise_frame(loaded.model, noisy).image))
    assert after < 0.7 * before, (before, after)


def test_equivalent_spp_interpolates_the_single_frame_curve_in_log_log():
    """Where the cross-frame model's error falls on the single-frame model's error-vs-spp curve: exact at measured
    points, log-log linear between them, and a bound rather than an extrapolation outside them."""
    from ranad_core.evaluate import equivalent_spp, temporal_markdown

    curve = {4: 0.004, 16: 0.002, 64: 0.001}                 # error halves per 4x spp: error ~ spp^-0.5
    assert equivalent_spp(curve, 0.002) == (16.0, "")
    eq, _ = equivalent_spp(curve, 0.002 / np.sqrt(2))          # half a step in log: sqrt(16 * 64)
    assert abs(eq - 32.0) < 1e-9
    assert equivalent_spp(curve, 0.0005) == (None, ">")
    assert equivalent_spp(curve, 0.005) == (None, "<")
    rows = [{"scene": "s", "kind": "deepoid", "spp": spp, "ref_spp": 1024, "method": m, "flip": f, "temporal": t,
             "seconds": 0.1}
            for spp, e in curve.items()
            for m, f, t in (("noisy", 0.5, 0.02), ("ranad", 50 * e, e), ("ranad-xf", 50 * e / np.sqrt(2), e / 2))]
    table = temporal_markdown(rows)
    assert "| 4 | 8 spp (2.00x) | 16 spp (4.00x) |" in table
    assert "| 64 | > 64 spp (> 1x) | > 64 spp (> 1x) |" in table
    assert "single-frame at" not in temporal_markdown([r for r in rows if r["spp"] == 4])
