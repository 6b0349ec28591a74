"""Training: augmentation keeps noisy and reference layouts identical; the loop trains, checkpoints and resumes."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core.errors import RanadError
from ranad_core.exr import read_deep
from ranad_core.train.data import find_frame_pairs, find_pairs, sample, sample_consecutive, transform
from ranad_core.train.losses import temporal_loss

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"


def dataset_from_example(root: Path) -> Path:
    scene = root / "scene_0000" / "deepoid"
    scene.mkdir(parents=True)
    for f in SHOT.glob("*.exr"):
        shutil.copy(f, scene / f.name)
    shutil.copy(SHOT / "manifest.json", root / "scene_0000" / "manifest.json")
    return root


def test_transforms_move_bins_with_their_pixels():
    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    rgba = ["R", "G", "B", "A", "Z", "ZBack"]
    flat = img.select(rgba).flatten()
    for fx, fy, tr in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)]:
        t = transform(img, bool(fx), bool(fy), bool(tr))
        expect = flat[:, ::-1] if fx else flat
        expect = expect[::-1] if fy else expect
        expect = expect.transpose(1, 0, 2) if tr else expect
        np.testing.assert_allclose(t.select(rgba).flatten(), expect, rtol=1e-6, atol=1e-6)
        if fx and not tr:  # screen-space motion follows the flip
            i = img.channels.index("motion_next.X")
            np.testing.assert_array_equal(np.sort(t.values[:, i]), np.sort(-img.values[:, i]))
    back = transform(transform(img, False, False, True), False, False, True)
    np.testing.assert_array_equal(back.values, img.values)


def test_samples_keep_identical_layouts(tmp_path):
    pairs = find_pairs(dataset_from_example(tmp_path / "ds"))
    rng = np.random.default_rng(0)
    for _ in range(5):
        n, r = sample(pairs[0], rng, 24)
        assert n.width == 24 and n.height == 24
        np.testing.assert_array_equal(n.offsets, r.offsets)
        np.testing.assert_array_equal(n.ids["id"], r.ids["id"])


def test_train_checkpoints_and_resumes(tmp_path):
    ds = dataset_from_example(tmp_path / "ds")
    run = tmp_path / "run"
    args = ["train", str(ds), "-o", str(run), "--steps", "4", "--crop", "24", "--checkpoint-every", "2"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    state = torch.load(run / "checkpoint.pt", weights_only=False)
    assert state["step"] == 4 and state["model_config"]["name"] == "cpu-small"
    r = CliRunner().invoke(cli, args[:4] + ["--steps", "6", "--crop", "24"])
    assert r.exit_code == 0, r.output
    assert torch.load(run / "checkpoint.pt", weights_only=False)["step"] == 6
    assert "step 6 loss" in (run / "train.log").read_text()
    r = CliRunner().invoke(cli, args[:4] + ["--steps", "6"])
    assert r.exit_code == 0 and "already at step 6" in r.output


def test_train_in_chunks_keeps_the_schedule(tmp_path):
    """--until stops at a step of a longer schedule; resuming to the end gives the run trained in one go."""
    ds = dataset_from_example(tmp_path / "ds")
    base = ["train", str(ds), "--steps", "4", "--crop", "16", "--checkpoint-every", "100"]
    for run, chunks in (("whole", [None]), ("chunks", [2, None])):
        for until in chunks:
            r = CliRunner().invoke(cli, base + ["-o", str(tmp_path / run)] + (["--until", str(until)] if until else []))
            assert r.exit_code == 0, r.output
            if until:
                assert torch.load(tmp_path / run / "checkpoint.pt", weights_only=False)["step"] == until
    whole, chunks = (torch.load(tmp_path / r / "checkpoint.pt", weights_only=False) for r in ("whole", "chunks"))
    assert whole["step"] == chunks["step"] == 4
    for k, v in whole["model"].items():
        torch.testing.assert_close(chunks["model"][k], v)


def test_optimizer_state_follows_parameters_into_new_groups():
    """A checkpoint's optimizer state from before the learning-rate groups (one group, parameter order) lands on
    the same parameters in the grouped optimizer; the temporal gate's group runs at 10x the rate."""
    from ranad_core.model import feature_dim, get_config
    from ranad_core.model.crossframe import CrossFrameRaNAD
    from ranad_core.train.trainer import load_optimizer, param_groups

    model = CrossFrameRaNAD(get_config("cpu-small-xf"), feature_dim())
    old = torch.optim.AdamW(model.parameters(), lr=1e-3)
    for i, p in enumerate(model.parameters()):
        p.grad = torch.full_like(p, float(i + 1))
    old.step()
    groups = param_groups(model)
    assert {g["lr_scale"] for g in groups} == {1.0, 3.0, 10.0}
    assert all(n.startswith("temporal_gate.") for g in groups if g["lr_scale"] == 10.0 for n in g["names"])
    new = torch.optim.AdamW(groups, lr=1e-3)
    load_optimizer(new, old.state_dict(), model)
    by_param = {id(p): new.state[p]["exp_avg"] for g in new.param_groups for p in g["params"]}
    for i, (name, p) in enumerate(model.named_parameters()):
        assert torch.allclose(by_param[id(p)], torch.full_like(p, 0.1 * (i + 1))), name
    again = torch.optim.AdamW(param_groups(model), lr=1e-3)
    load_optimizer(again, new.state_dict(), model)   # same groups: loaded as they are
    assert [g["lr_scale"] for g in again.param_groups] == [g["lr_scale"] for g in groups]


def test_train_errors(tmp_path):
    r = CliRunner().invoke(cli, ["train", str(tmp_path / "none"), "-o", str(tmp_path / "run")])
    assert r.exit_code == 2 and "dataset folder not found" in r.output
    r = CliRunner().invoke(cli, ["train", str(tmp_path), "-o", str(tmp_path / "run"), "--config", "huge"])
    assert r.exit_code == 2 and "unknown model config" in r.output
    (tmp_path / "empty").mkdir()
    r = CliRunner().invoke(cli, ["train", str(tmp_path / "empty"), "-o", str(tmp_path / "run")])
    assert r.exit_code == 2 and "no complete scenes" in r.output
    assert json.loads((SHOT / "manifest.json").read_text())["centre_frame"] == 1


def test_ssim_loss_sees_structure_smape_misses():
    """Two images with the same SMAPE against the reference (every pixel off by a factor 1.2 or 1/1.2, which SMAPE
    scores alike): a global brightness change keeps the structure, per-pixel factors destroy it; only SSIM tells
    them apart. SMAPE is computed twice: by the training loss and as written out here."""
    from ranad_core.train.losses import smape, ssim

    g = torch.Generator().manual_seed(0)
    ref = torch.nn.functional.avg_pool2d((0.5 + 0.5 * torch.rand(3, 32, 32, generator=g))[None], 3, 1, 1,
                                         count_include_pad=False)[0]
    assert abs(ssim(ref, ref).item() - 1) < 1e-5 and smape(ref, ref).item() == 0
    brighter = ref * 1.2
    blotchy = ref * torch.where(torch.rand(1, 32, 32, generator=g) < 0.5, 1.2, 1 / 1.2)

    def smape_here(test, r, eps=1e-2):
        t, r = test.double().numpy(), r.double().numpy()
        return float(np.mean(np.abs(t - r) / (np.abs(t) + np.abs(r) + eps)))

    for img in (brighter, blotchy):
        assert smape(img, ref).item() == pytest.approx(smape_here(img, ref), rel=1e-5)
        assert smape_here(img, ref) == pytest.approx(0.2 / 2.2, rel=0.02)   # |k - 1| / (k + 1) for k = 1.2, 1/1.2
    assert smape(brighter, ref).item() == pytest.approx(smape(blotchy, ref).item(), rel=0.01)
    assert ssim(ref, brighter).item() > 0.95 and ssim(ref, blotchy).item() < 0.5
    # noise and blur lower SSIM too
    noisy = (ref + 0.2 * torch.randn(3, 32, 32, generator=g)).clamp(0, 1)
    blurred = torch.nn.functional.avg_pool2d(ref[None], 5, 1, 2, count_include_pad=False)[0]
    assert ssim(ref, noisy) < 0.9 and ssim(ref, blurred) < ssim(ref, brighter)


def test_data_parallel_training_averages_over_processes(tmp_path):
    """Two gloo processes, one step: the gradient DDP applied (AdamW's first moment in rank 0's checkpoint is
    0.1 x the gradient; no clipping) equals the average of the two ranks' gradients computed here in one
    process on the crops each rank draws (its own stream, seeded [seed, rank]); not their sum, not rank 0's."""
    from ranad_core.model import get_config
    from ranad_core.train.trainer import TrainConfig, build_model, pair_loss, spawn_local

    ds = dataset_from_example(tmp_path / "ds")
    cfg = TrainConfig(dataset=str(ds), run=str(tmp_path / "ddp"), steps=1, crop=16, checkpoint_every=1,
                      log_every=1, clip=1e9)
    spawn_local(cfg, 2, show_progress=False)
    state = torch.load(tmp_path / "ddp" / "checkpoint.pt", weights_only=False)
    assert state["step"] == 1 and (tmp_path / "ddp" / "train.log").read_text().count("step 1 loss") == 1
    opt = state["optimizer"]
    exp_avg = {n: opt["state"][i]["exp_avg"] for g in opt["param_groups"] for n, i in zip(g["names"], g["params"])
               if i in opt["state"]}

    torch.manual_seed(cfg.seed)
    model = build_model(cfg, get_config(cfg.config))
    after_init = torch.get_rng_state()
    names, params = zip(*model.named_parameters())
    pairs = find_pairs(str(ds))
    grads = []
    for rank in (0, 1):
        torch.set_rng_state(after_init)                       # each process's torch stream after building
        rng = np.random.default_rng([cfg.seed, rank])
        loss, _ = pair_loss(model, pairs[int(rng.integers(0, len(pairs)))], rng, cfg, False)
        g = torch.autograd.grad(loss, params, allow_unused=True)
        grads.append([torch.zeros_like(p) if x is None else x for p, x in zip(params, g)])
    mean = {n: (a + b) / 2 for n, a, b in zip(names, *grads)}
    scale = max(v.abs().max().item() for v in mean.values())
    for n in names:
        np.testing.assert_allclose(exp_avg[n].numpy(), 0.1 * mean[n].numpy(), rtol=1e-3, atol=1e-6 * scale,
                                   err_msg=n)
    rank0 = dict(zip(names, grads[0]))
    assert max((0.1 * rank0[n] - exp_avg[n]).abs().max().item() for n in names) > 0.01 * scale   # rank 1 counted


def test_reduced_modes_keep_the_radiance():
    from ranad_core.model import prepare
    from ranad_core.train.data import reduce_inputs


    noisy = read_deep(SHOT / "noisy_spp16.0001.exr")
    ref = read_deep(SHOT / "reference_spp16.0001.exr")
    n2, r2 = reduce_inputs(noisy, ref, np.random.default_rng(0), 1.0, 1.0)
    assert not any(c.startswith(("albedo.", "N.", "specular.")) for c in n2.channels)
    assert not any(c.startswith("specular.") for c in r2.channels)
    full, red = prepare(noisy.sorted()[0]), prepare(n2.sorted()[0])
    np.testing.assert_allclose(red.layers["diffuse"], full.layers["diffuse"] + full.layers["specular"], rtol=1e-6)
    assert float(red.layers["specular"].abs().max()) == 0
    n3, r3 = reduce_inputs(noisy, ref, np.random.default_rng(0), 0.0, 0.0)
    assert n3 is noisy and r3 is ref


def sequence_dataset(root: Path) -> Path:
    """The example shot with a reference on every frame (frames 0 and 2 use their noisy image as reference: the
    same bin layout, which is all the temporal loss's plumbing needs)."""
    ds = dataset_from_example(root)
    scene = ds / "scene_0000"
    for t in (0, 2):
        shutil.copy(scene / "deepoid" / f"noisy_spp16.{t:04d}.exr", scene / "deepoid" / f"reference_spp16.{t:04d}.exr")
    m = json.loads((scene / "manifest.json").read_text())
    m["reference_frames"] = [0, 1, 2]
    (scene / "manifest.json").write_text(json.dumps(m))
    return ds


def test_consecutive_frames_share_one_crop(tmp_path):
    ds = sequence_dataset(tmp_path / "ds")
    found = find_frame_pairs(ds)
    assert [(a.noisy.name, b.noisy.name) for a, b in found] == [
        ("noisy_spp16.0000.exr", "noisy_spp16.0001.exr"), ("noisy_spp16.0001.exr", "noisy_spp16.0002.exr")]
    assert find_frame_pairs(dataset_from_example(tmp_path / "centre_only")) == []
    (f0, r0, c0, _), (f1, r1, c1, _) = sample_consecutive(found[0], np.random.default_rng(3), 24, 3)
    assert (len(f0), c0, len(f1), c1) == (2, 0, 3, 1)  # frame 0 sits at the sequence's start
    for frames, ref, c in ((f0, r0, c0), (f1, r1, c1)):
        assert all((f.width, f.height) == (24, 24) for f in frames)
        np.testing.assert_array_equal(frames[c].offsets, ref.offsets)


def test_temporal_loss_counts_flicker_not_static_error():
    offsets = torch.tensor([0, 1, 2])  # two pixels, one bin each
    ref = {"diffuse": torch.tensor([[0.2, 0.3, 0.4], [1.0, 0.5, 0.1]]), "specular": torch.zeros(2, 3),
           "alpha": torch.ones(2, 1)}
    scaled = {**ref, "diffuse": ref["diffuse"] * 1.2}
    assert temporal_loss([scaled, scaled], [ref, ref], [offsets, offsets]).item() == 0
    assert temporal_loss([ref, scaled], [ref, ref], [offsets, offsets]).item() > 0.01


def test_train_with_the_temporal_loss(tmp_path):
    ds = sequence_dataset(tmp_path / "ds")
    run = tmp_path / "run"
    args = ["train", str(ds), "-o", str(run), "--config", "cpu-small-xf", "--steps", "2", "--crop", "16",
            "--temporal-weight", "2"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    assert "temporal" in r.output and torch.load(run / "checkpoint.pt", weights_only=False)["step"] == 2
    r = CliRunner().invoke(cli, ["train", str(dataset_from_example(tmp_path / "c")), "-o", str(tmp_path / "r2"),
                                 "--config", "cpu-small-xf", "--temporal-weight", "2"])
    assert r.exit_code == 2 and "--ref-frames all" in r.output
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(tmp_path / "r3"), "--temporal-weight", "2"])
    assert r.exit_code == 2 and "cross-frame config" in r.output


def test_output_mix_config_starts_from_a_cross_frame_run(tmp_path):
    """--init with a cross-frame run starts cpu-small-xfm from its weights (the output mix added, nearly shut);
    a config without the output mix refuses such an --init."""
    from ranad_core.model.store import load_model

    ds = sequence_dataset(tmp_path / "ds")
    base = tmp_path / "xf"
    args = ["--steps", "1", "--crop", "16", "--temporal-weight", "2"]
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(base), "--config", "cpu-small-xf", *args])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(tmp_path / "xfm"), "--config", "cpu-small-xfm",
                                 "--init", str(base), "--lr", "0", *args])
    assert r.exit_code == 0, r.output
    before, after = load_model(str(base)).model.state_dict(), load_model(str(tmp_path / "xfm")).model.state_dict()
    assert set(after) - set(before) and all(k.startswith(("mix.", "mix_gate.")) for k in set(after) - set(before))
    assert all(torch.equal(before[k], after[k]) for k in before)        # lr 0: the copied weights, untouched
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(tmp_path / "bad"), "--config", "cpu-small-xf",
                                 "--init", str(base), *args])
    assert r.exit_code == 2 and "output mix" in r.output


def test_training_pools_several_datasets(tmp_path):
    """`ranad train A B`: the scenes of both datasets (same scene names in each) are pooled, not merged by name."""
    a, b = sequence_dataset(tmp_path / "a"), sequence_dataset(tmp_path / "b")
    assert len(find_pairs([a, b])) == 2 * len(find_pairs(a))
    assert len(find_frame_pairs((a, b))) == 2 * len(find_frame_pairs(a))
    assert {p.noisy.parents[2] for p in find_pairs([a, b])} == {a, b}
    run = tmp_path / "run"
    r = CliRunner().invoke(cli, ["train", str(a), str(b), "-o", str(run), "--config", "cpu-small-xf", "--steps", "1",
                                 "--crop", "16", "--temporal-weight", "1"])
    assert r.exit_code == 0, r.output
    assert torch.load(run / "checkpoint.pt", weights_only=False)["train_config"]["dataset"] == (str(a), str(b))
    r = CliRunner().invoke(cli, ["train", str(a), str(tmp_path / "none"), "-o", str(tmp_path / "r2")])
    assert r.exit_code == 2 and "dataset folder not found" in r.output and "none" in r.output


def test_freeze_spatial_trains_only_the_temporal_parts(tmp_path):
    """--freeze-spatial: after training steps the single-frame part (embedding, U-Nets, spatial reconstruction)
    is bit for bit the --init model's, while the temporal parts moved; without --init or with a single-frame
    config it is refused."""
    from ranad_core.model.store import load_model

    ds = sequence_dataset(tmp_path / "ds")
    single = tmp_path / "single"
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(single), "--steps", "1", "--crop", "16"])
    assert r.exit_code == 0, r.output
    run = tmp_path / "xf"
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(run), "--config", "cpu-small-xf", "--init", str(single),
                                 "--steps", "3", "--crop", "24", "--lr", "1e-2", "--freeze-spatial"])
    assert r.exit_code == 0, r.output
    start = load_model(str(single)).model.state_dict()
    trained = load_model(str(run)).model.state_dict()
    for k, v in start.items():
        if k == "embed.0.weight":   # the frame one-hot columns are appended at zero and stay there
            w = trained["single." + k]
            assert torch.equal(w[:, :v.shape[1]], v) and not w[:, v.shape[1]:].any()
        else:
            assert torch.equal(trained["single." + k], v), k
    moved = [k for k, v in trained.items() if not k.startswith("single.") and "gate" in k]
    assert moved and any(not torch.equal(trained[k], torch.full_like(trained[k], -4.0)) for k in moved
                         if k.endswith("bias"))
    for extra, msg in ((["--config", "cpu-small-xf"], "needs --init"), (["--init", str(single)], "cross-frame")):
        r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(tmp_path / "bad"), "--steps", "1", "--crop", "16",
                                     "--freeze-spatial", *extra])
        assert r.exit_code == 2 and msg in r.output, r.output
        assert not (tmp_path / "bad").exists()


def test_separation_loss_sees_colour_moved_between_depth_layers():
    """One pixel, a transparent front bin (alpha 0) and an opaque back bin: moving the colour from one bin to the
    other leaves the flattened colour as it was (the composite loss sees nothing) but puts it on the wrong side of
    a holdout, which the separation term measures. Written out here: the front composite is the front bin's
    colour, the back composite the back bin's, each against the reference's."""
    from ranad_core.train.losses import composite, depth_slices, separation, smape, total_loss

    offsets = torch.tensor([0, 2])
    ref = {"diffuse": torch.tensor([[0.0, 0.0, 0.0], [0.6, 0.4, 0.2]]), "specular": torch.zeros(2, 3),
           "alpha": torch.tensor([[0.0], [1.0]]), "depth": torch.tensor([[1.0], [3.0]])}
    moved = {**ref, "diffuse": ref["diffuse"].flip(0)}
    assert torch.allclose(composite(moved, offsets), composite(ref, offsets))
    assert separation(depth_slices(ref, ref, offsets)).item() == 0
    zero, colour = torch.zeros(1, 3), ref["diffuse"][1:]
    expected = (smape(colour, zero) + smape(zero, colour)) / 2
    assert expected > 0.5
    assert separation(depth_slices(moved, ref, offsets)).item() == pytest.approx(expected.item(), rel=1e-6)
    _, off = total_loss(moved, ref, offsets, (1, 1))
    _, on = total_loss(moved, ref, offsets, (1, 1), weights={"separation": 1.0})
    assert "separation" not in off and on["separation"] == pytest.approx(expected.item(), rel=1e-6)
    assert on["composite"] == off["composite"] == pytest.approx(0, abs=1e-7)


def _random_layers(seed: int, pixels: int = 40):
    """A ragged stack of sorted, semi-transparent premultiplied bins, as a loss dict and as a DeepImage (R G B A Z),
    with an even number of bins and distinct depths (so the median depth is no bin's: the front/back split is
    unambiguous)."""
    from ranad_core.deep import DeepImage

    rng = np.random.default_rng(seed)
    counts = rng.integers(0, 5, size=pixels)
    counts[-1] += counts.sum() % 2
    offsets = np.concatenate([[0], np.cumsum(counts)])
    n = int(offsets[-1])
    alpha = rng.uniform(0.05, 0.95, n)
    rgb = rng.uniform(0, 3, (n, 3)) * alpha[:, None]
    z = rng.permutation(np.linspace(1, 9, n))
    for p in range(pixels):
        z[offsets[p]:offsets[p + 1]].sort()
    values = np.concatenate([rgb, alpha[:, None], z[:, None]], axis=1)
    img = DeepImage(values=values.astype(np.float64), offsets=offsets, channels=["R", "G", "B", "A", "Z"],
                    data_window=(0, 0, pixels - 1, 0), display_window=(0, 0, pixels - 1, 0),
                    channel_types={c: "float" for c in "RGBAZ"})
    t = torch.from_numpy
    layers = {"diffuse": t(rgb), "specular": torch.zeros(n, 3, dtype=torch.float64), "alpha": t(alpha[:, None]),
              "depth": t(z[:, None])}
    return layers, img, torch.from_numpy(offsets)


def test_edit_loss_image_is_the_edit_eval_scores():
    """The loss's compositing edit (front recoloured, the layer inserted at the median depth, flattened) equals
    metrics.composite_edit, the edit `ranad eval` scores, on random ragged stacks; at exposure scale s it is the
    edit of the image divided by s."""
    from ranad_core.metrics import composite_edit, split_depth
    from ranad_core.train.losses import depth_slices, edit_image

    for seed in range(3):
        layers, img, offsets = _random_layers(seed)
        (front, _), (back, _) = depth_slices(layers, layers, offsets)
        oracle = composite_edit(img, split_depth(img)).reshape(-1, 3)
        # metrics flattens in float32
        assert np.allclose(edit_image(front, back).numpy(), oracle, rtol=1e-5, atol=1e-6)
        scaled = img.with_values(img.values * np.array([4, 4, 4, 1, 1]))
        big = {**layers, "diffuse": layers["diffuse"] * 4}
        (front4, _), (back4, _) = depth_slices(big, big, offsets)
        assert np.allclose(edit_image(front4, back4, 4.0).numpy(), oracle, rtol=1e-5, atol=1e-6)
        assert not np.allclose(composite_edit(scaled, split_depth(img)).reshape(-1, 3), 4 * oracle)


def test_edit_loss_sees_front_alpha_the_composite_hides_less():
    """Halving the front bins' alpha and colour (premultiplied: the front layer made more transparent) changes the
    edit; the edit terms are zero for the reference itself, positive for the change, and computed only when
    weighted."""
    from ranad_core.train.losses import total_loss

    layers, _, offsets = _random_layers(7, pixels=64)
    z = layers["depth"][:, 0]
    front = (z < torch.quantile(z, 0.5)).to(z.dtype)[:, None]
    thin = {**layers, "diffuse": layers["diffuse"] * (1 - front / 2), "alpha": layers["alpha"] * (1 - front / 2)}
    weights = {"edit": 1.0, "edit_ssim": 1.0}
    _, same = total_loss(layers, layers, offsets, (8, 8), weights=weights)
    _, off = total_loss(thin, layers, offsets, (8, 8))
    _, on = total_loss(thin, layers, offsets, (8, 8), weights=weights)
    assert same["edit"] == pytest.approx(0, abs=1e-9) and same["edit_ssim"] == pytest.approx(0, abs=1e-6)
    assert "edit" not in off and "edit_ssim" not in off
    assert on["edit"] > 0.02 and on["edit_ssim"] > 0


def test_composite_grad_charges_blur_more_than_fine_noise():
    """The gradient term, on a sharp-edged reference: SMAPE prefers a blur of the edge to a fine noise (the trade
    section 4 of runs/generalization-s24 found the training making), the gradient term the noise; it is zero for the
    reference itself, computed only when weighted, and its gradient reaches the prediction."""
    from ranad_core.train.losses import gradient_l1, smape

    g = torch.Generator().manual_seed(2)
    ref = torch.zeros(3, 16, 16)
    ref[:, :, 8:] = 0.8                                                    # a vertical edge
    blur = torch.nn.functional.avg_pool2d(ref[None], 5, 1, 2, count_include_pad=False)[0]
    noise = ref + 0.02 * torch.randn(3, 16, 16, generator=g)
    assert gradient_l1(ref, ref).item() == 0
    assert smape(blur, ref).item() < smape(noise, ref).item()
    assert gradient_l1(blur, ref).item() > gradient_l1(noise, ref).item() * 1.5

    _check_optional_term("composite_grad", lambda d: d * (1 + 0.3 * torch.rand(d.shape, generator=g)))


def _check_optional_term(term: str, spoil) -> None:
    """An off-by-default loss term on random layers: zero for the reference itself, absent unless weighted, above
    zero for a prediction whose diffuse layer is spoil(diffuse), and its gradient reaches that prediction."""
    from ranad_core.train.losses import total_loss

    layers, _, offsets = _random_layers(7, pixels=64)
    pred = {k: v.clone().requires_grad_(k == "diffuse") for k, v in layers.items()}
    spoilt = {**pred, "diffuse": spoil(pred["diffuse"])}
    _, same = total_loss(layers, layers, offsets, (8, 8), weights={term: 1.0})
    _, off = total_loss(spoilt, layers, offsets, (8, 8))
    loss, on = total_loss(spoilt, layers, offsets, (8, 8), weights={term: 1.0})
    assert same[term] == 0 and term not in off and on[term] > 0
    loss.backward()
    assert pred["diffuse"].grad is not None and pred["diffuse"].grad.abs().sum() > 0


def test_separation_ssim_sees_structure_moved_between_depth_layers():
    """8x8 pixels, each a transparent front bin (alpha 0) over an opaque back bin; the reference's front layer holds
    a checker. Moving the front colour into the back bin on the checker's dark squares leaves every composite
    colour as it was (composite terms zero) but changes both layers' structure: the separation_ssim term is
    positive, zero for the reference itself, and computed only when weighted."""
    from ranad_core.train.losses import total_loss

    h = w = 8
    offsets = torch.arange(0, 2 * h * w + 1, 2)
    checker = ((torch.arange(h)[:, None] + torch.arange(w)[None, :]) % 2).reshape(-1).float()
    diffuse = torch.zeros(2 * h * w, 3)
    diffuse[0::2] = 0.5 + 0.4 * checker[:, None]        # front: a checker
    diffuse[1::2] = 0.3                                 # back: flat
    ref = {"diffuse": diffuse, "specular": torch.zeros_like(diffuse),
           "alpha": torch.tensor([0.0, 1.0]).repeat(h * w)[:, None],
           "depth": torch.tensor([1.0, 3.0]).repeat(h * w)[:, None]}
    moved_diffuse = diffuse.clone()
    dark = checker == 0
    front, back = moved_diffuse[0::2], moved_diffuse[1::2]
    back[dark] += front[dark]
    front[dark] = 0
    moved_diffuse[0::2], moved_diffuse[1::2] = front, back
    moved = {**ref, "diffuse": moved_diffuse}
    weights = {"separation_ssim": 1.0}
    _, same = total_loss(ref, ref, offsets, (h, w), weights=weights)
    _, off = total_loss(moved, ref, offsets, (h, w))
    _, on = total_loss(moved, ref, offsets, (h, w), weights=weights)
    assert same["separation_ssim"] == pytest.approx(0, abs=1e-5)
    assert "separation_ssim" not in off and on["separation_ssim"] > 0.05
    assert on["composite"] == pytest.approx(0, abs=1e-6) and on["composite_ssim"] == pytest.approx(0, abs=1e-5)


def test_loss_weights_from_the_command_line(tmp_path):
    """--loss-weight reaches the loss (the log shows the term) and is kept in the checkpoint's train_config;
    an unknown term or a negative weight is a usage error."""
    ds = dataset_from_example(tmp_path / "ds")
    run = tmp_path / "run"
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(run), "--steps", "2", "--crop", "16",
                                 "--loss-weight", "separation=1", "--loss-weight", "alpha=2"])
    assert r.exit_code == 0, r.output
    state = torch.load(run / "checkpoint.pt", weights_only=False)
    assert dict(state["train_config"]["loss_weights"]) == {"separation": 1.0, "alpha": 2.0}
    for bad in ("smoothness=1", "alpha=-1", "alpha"):
        r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(tmp_path / "r2"), "--loss-weight", bad])
        assert r.exit_code == 2 and "--loss-weight" in r.output and "TERM=W" in r.output


def test_misaligned_windows_move_only_the_neighbours():
    """--p-misalign: the centre frame and the reference are cut as without it; each neighbour holds its own
    content from a window shifted by 2 .. crop/4 pixels, relabelled to the centre's window; at 0 no random numbers
    are drawn, so earlier runs keep their crops."""
    from dataclasses import replace

    from deep_factory import random_deep
    from ranad_core.train.data import cropped, misalignment, random_window, transform

    frames = [random_deep(40, 40, seed=s) for s in (1, 2, 3)]
    ref = random_deep(40, 40, seed=4)
    windows = [(frames, ref, 1, None)]
    r0, r1 = np.random.default_rng(7), np.random.default_rng(7)
    plain = cropped(windows, r0, 16)[0]
    off = cropped(windows, r1, 16, p_misalign=0.0)[0]
    assert r0.random() == r1.random()                       # the same draws with the option at 0
    for a, b in zip(plain[0] + [plain[1]], off[0] + [off[1]]):
        assert np.array_equal(a.values, b.values) and np.array_equal(a.offsets, b.offsets)
    moved = cropped(windows, np.random.default_rng(7), 16, p_misalign=1.0)[0]
    assert np.array_equal(moved[0][1].values, plain[0][1].values)        # the centre
    assert np.array_equal(moved[1].values, plain[1].values)              # the reference
    # the neighbours: the same draws replayed give each one's shift
    rng = np.random.default_rng(7)
    win = random_window(ref, rng, 16)
    fx, fy, tr = (bool(b) for b in rng.integers(0, 2, 3))
    rng.random()
    shifts = [misalignment(rng, 16) for _ in frames]
    for k in (0, 2):
        dx, dy = shifts[k]
        assert 2 <= max(abs(dx), abs(dy)) <= 4
        want = transform(replace(frames[k].crop((win[0] + dx, win[1] + dy, win[2] + dx, win[3] + dy)),
                                 data_window=win), fx, fy, tr)
        got = moved[0][k]
        assert got.data_window == plain[0][k].data_window
        assert np.array_equal(got.offsets, want.offsets) and np.array_equal(got.values, want.values)
        assert not (np.array_equal(got.offsets, plain[0][k].offsets)
                    and np.array_equal(got.values, plain[0][k].values))
    assert all(2 <= max(abs(v) for v in misalignment(np.random.default_rng(s), 16)) <= 4 for s in range(200))


def test_p_misalign_needs_a_cross_frame_config(tmp_path):
    r = CliRunner().invoke(cli, ["train", str(dataset_from_example(tmp_path / "ds")), "-o", str(tmp_path / "run"),
                                 "--p-misalign", "0.3", "--steps", "1"])
    assert r.exit_code == 2 and "--p-misalign needs a cross-frame config" in r.output


def test_a_reconstruction_grown_by_a_scale_starts_from_the_init():
    """cpu-small-pd3a (three alpha scales) from cpu-small-pd weights: every init weight is kept, the other layers
    denoise exactly as the init does, the new scale starts with about NEW_SCALE_LOGIT's share of alpha's mix; a
    config of another shape refuses the init."""
    from ranad_core.model import RaNAD, feature_dim, get_config
    from ranad_core.model.store import load_model
    from ranad_core.train.trainer import NEW_SCALE_LOGIT, grown_reconstruction, init_single

    torch.manual_seed(0)
    model = RaNAD(get_config("cpu-small-pd3a"), feature_dim("prior")).eval()
    init_single(model, "cpu-small-pd-v1")
    init = load_model("cpu-small-pd-v1").model
    old, new = init.state_dict(), model.state_dict()
    for k, v in old.items():
        assert torch.equal(new[k][:len(v)], v), k
    assert set(new) - set(old) and all(k.startswith("recon.alpha.") for k in set(new) - set(old))
    assert torch.all(new["recon.alpha.mixer.bias"][2] == NEW_SCALE_LOGIT)
    assert torch.all(new["recon.alpha.mixer.weight"][2] == 0)
    img = read_deep(Path(__file__).resolve().parents[1] / "examples" / "synth_shot" / "noisy_spp16.0001.exr")
    from ranad_core.denoise import denoise_window

    # the models' own outputs: light matching composites with the denoised alpha, so it would move the colour too
    a, b = (denoise_window(m, [img], 0, light_match=False).image for m in (init, model))
    ch = a.channels
    same = [ch.index(c) for c in ("R", "G", "B", "Z")]
    assert np.allclose(a.values[:, same], b.values[:, same], rtol=1e-4, atol=1e-6)   # only alpha changed
    alpha = ch.index("A")
    assert 0 < np.abs(a.values[:, alpha] - b.values[:, alpha]).max() < 0.05
    with pytest.raises(RanadError, match="shape"):
        grown_reconstruction(old, {**old, "recon.alpha.mixer.bias": torch.zeros(1)}, "x")
    with pytest.raises(RanadError, match="lacks"):
        grown_reconstruction({k: v for k, v in old.items() if k != "embed.0.bias"}, old, "x")


def test_a_one_unet_config_starts_from_a_two_unet_models_first_unet(tmp_path):
    """cpu-small-pdl-gza-u1 from the two-U-Net default: it denoises exactly as the default does with its second
    U-Net skipped (the oracle: the loaded default with its backbone cut to the first U-Net), and a two-U-Net
    config refuses a one-U-Net init."""
    import copy

    from safetensors.torch import save_file

    from ranad_core.denoise import denoise_frame
    from ranad_core.model import RaNAD, feature_dim, get_config
    from ranad_core.model.store import DEFAULT_MODEL, load_model
    from ranad_core.train.trainer import init_single

    model = RaNAD(get_config("cpu-small-pdl-gza-u1"), feature_dim("prior")).eval()
    init_single(model, DEFAULT_MODEL)
    cut = copy.deepcopy(load_model(DEFAULT_MODEL).model)
    assert cut.config.unets == 2
    cut.backbone.unets = cut.backbone.unets[:1]
    img = read_deep(Path(__file__).resolve().parents[1] / "examples" / "synth_shot" / "noisy_spp16.0001.exr")
    a, b = denoise_frame(cut, img).image, denoise_frame(model, img).image
    assert np.allclose(a.values, b.values, rtol=1e-5, atol=1e-6)
    full = denoise_frame(load_model(DEFAULT_MODEL).model, img).image
    assert not np.allclose(full.values, b.values, rtol=1e-3, atol=1e-4)   # the second U-Net did matter
    path = tmp_path / "u1.safetensors"
    save_file({k: v.contiguous() for k, v in model.state_dict().items()}, str(path),
              metadata={"model_config": json.dumps(model.config.to_dict())})
    two = RaNAD(get_config("cpu-small-pdl-gza"), feature_dim("prior"))
    with pytest.raises(RanadError, match="does not match"):
        init_single(two, str(path))


def test_cross_frame_init_must_share_the_spatial_models_dropout(tmp_path):
    """A sequence config on the lattice bin dropout refuses a spatial init trained without it (the weights would
    load, the U-Nets would see other bins than they were trained on), and one with the layer gate an init without
    it: exit 2, no run folder."""
    ds = dataset_from_example(tmp_path / "ds")
    run = tmp_path / "run"
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(run), "--steps", "1", "--crop", "16", "--config",
                                 "cpu-small-pdl-xg", "--init", "cpu-small-pd-v2", "--freeze-spatial"])
    assert r.exit_code == 2 and "dropout_lattice=False" in r.output, r.output
    assert not run.exists()
    # nor a spatial init without the layer gate the sequence config's spatial model has
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(run), "--steps", "1", "--crop", "16", "--config",
                                 "cpu-small-pdl-gza-xg", "--init", "cpu-small-pdl-v1", "--freeze-spatial"])
    assert r.exit_code == 2 and "layer_gate=()" in r.output, r.output
    assert not run.exists()


def test_spp_weights_set_the_odds_of_each_sample_count():
    """pair_odds: a count weighted 2 is drawn about twice as often as one left at 1, a count weighted 0 never;
    without weights the draws are the uniform ones runs made before the option (same random stream)."""
    from ranad_core.train.data import Pair
    from ranad_core.train.trainer import draw, pair_odds

    pairs = [Pair(Path(f"n{i}"), Path(f"r{i}"), "s", "deepz", spp) for i, spp in enumerate((4, 16, 64, 64, 4, 16))]
    odds = pair_odds(pairs, ((64, 2.0), (16, 0.0)))
    rng = np.random.default_rng(0)
    drawn = [draw(pairs, odds, rng).spp for _ in range(6000)]
    count = {s: drawn.count(s) for s in (4, 16, 64)}
    assert count[16] == 0 and 1.8 < count[64] / count[4] < 2.2        # (2 pairs x 2) / (2 pairs x 1)
    assert pair_odds(pairs, ()) is None
    a, b = np.random.default_rng(3), np.random.default_rng(3)
    assert [draw(pairs, None, a) for _ in range(20)] == [pairs[int(b.integers(0, 6))] for _ in range(20)]
    two = [(p, p) for p in pairs]                                     # consecutive frames: tuples of one count
    assert np.allclose(pair_odds(two, ((64, 2.0),)), pair_odds(pairs, ((64, 2.0),)))
    with pytest.raises(RanadError, match="weight 0"):
        pair_odds(pairs, ((4, 0.0), (16, 0.0), (64, 0.0)))


def test_spp_weights_from_the_command_line(tmp_path):
    """--spp-weight reaches the checkpoint's train_config; a malformed one is a usage error before any folder."""
    ds = dataset_from_example(tmp_path / "ds")
    run = tmp_path / "run"
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(run), "--steps", "2", "--crop", "16",
                                 "--spp-weight", "64=2"])
    assert r.exit_code == 0, r.output
    assert dict(torch.load(run / "checkpoint.pt", weights_only=False)["train_config"]["spp_weights"]) == {64: 2.0}
    for bad in ("64", "x=1", "0=1", "64=-1"):
        r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(tmp_path / "r2"), "--spp-weight", bad])
        assert r.exit_code == 2 and "--spp-weight" in r.output and "SPP=W" in r.output
    assert not (tmp_path / "r2").exists()


def _poison_reference(scene: Path, rows: slice) -> None:
    """The scene's reference with +inf in diffuse.R of `rows` (what a broken render leaves)."""
    from ranad_core.exr import write_deep

    path = scene / "deepoid" / "reference_spp16.0001.exr"
    img = read_deep(path)
    vals = img.values.copy()
    vals[rows, img.channels.index("diffuse.R")] = np.inf
    write_deep(path, img.with_values(vals))


def test_training_skips_draws_with_a_non_finite_loss(tmp_path):
    """A pair whose reference holds infinities makes some draws' loss non-finite: those are skipped (logged), the
    weights stay finite and the run reaches its steps; a dataset where every draw is non-finite stops with an
    error instead of spinning."""
    ds = tmp_path / "ds"
    dataset_from_example(ds)
    shutil.copytree(ds / "scene_0000", ds / "scene_0001")
    _poison_reference(ds / "scene_0001", slice(None))
    run = tmp_path / "run"
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(run), "--steps", "8", "--crop", "16",
                                 "--checkpoint-every", "100", "--seed", "3"])
    assert r.exit_code == 0, r.output
    state = torch.load(run / "checkpoint.pt", weights_only=False)
    assert state["step"] == 8
    assert all(torch.isfinite(v).all() for v in state["model"].values() if v.is_floating_point())
    assert "non-finite draws skipped" in (run / "train.log").read_text()
    bad = tmp_path / "bad"
    dataset_from_example(bad)
    _poison_reference(bad / "scene_0000", slice(None))
    r = CliRunner().invoke(cli, ["train", str(bad), "-o", str(tmp_path / "run2"), "--steps", "4", "--crop", "16"])
    assert r.exit_code == 2 and "not finite on 50 draws in a row" in r.output


def test_normals_turned_by_a_rotation_keep_everything_else():
    """rotated_normals turns every bin's normal by one rotation (lengths and the angles between bins kept, the
    other channels untouched); random_rotation gives proper rotations; an image without normals is left as it is."""
    from ranad_core.channels import NORMAL
    from ranad_core.train.data import random_rotation, rotated_normals, without_aux

    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    rng = np.random.default_rng(3)
    rots = [random_rotation(rng) for _ in range(20)]
    for rot in rots:
        np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(rot) == pytest.approx(1.0)
    assert np.abs(np.mean(rots, axis=0)).max() < 0.5    # not one fixed turn
    out = rotated_normals(img, rots[0])
    cols = [img.channels.index(c) for c in NORMAL]
    n0, n1 = img.values[:, cols].astype(np.float64), out.values[:, cols].astype(np.float64)
    np.testing.assert_allclose(n1, n0 @ rots[0].T, atol=2e-3)          # half-float channels
    np.testing.assert_allclose(np.linalg.norm(n1, axis=1), np.linalg.norm(n0, axis=1), atol=2e-3)
    pairs = np.random.default_rng(0).integers(0, img.num_bins, (200, 2))
    np.testing.assert_allclose((n1[pairs[:, 0]] * n1[pairs[:, 1]]).sum(1), (n0[pairs[:, 0]] * n0[pairs[:, 1]]).sum(1),
                               atol=4e-3)
    others = [i for i in range(len(img.channels)) if i not in cols]
    assert np.array_equal(out.values[:, others], img.values[:, others])
    assert np.array_equal(out.offsets, img.offsets) and out.channels == img.channels
    bare = without_aux(img)
    assert rotated_normals(bare, rots[0]) is bare


def test_rotate_normals_draws_only_when_asked(tmp_path):
    """p_rotate 0 leaves the crop and the random stream as before the option (earlier recipes train the same);
    p_rotate 1 turns the noisy crop's normals and not the reference; --rotate-normals reaches the train_config."""
    from ranad_core.channels import NORMAL
    from ranad_core.train.data import reduce_inputs

    noisy = read_deep(SHOT / "noisy_spp16.0001.exr")
    ref = read_deep(SHOT / "reference_spp16.0001.exr")
    a, b = np.random.default_rng(5), np.random.default_rng(5)
    n0, r0 = reduce_inputs(noisy, ref, a, 0.0, 0.0, 0.0)
    b.random(), b.random()                     # the two draws reduce_inputs made before the option
    assert n0 is noisy and r0 is ref and a.random() == b.random()
    n1, r1 = reduce_inputs(noisy, ref, np.random.default_rng(5), 0.0, 0.0, 1.0)
    cols = [noisy.channels.index(c) for c in NORMAL]
    assert not np.allclose(n1.values[:, cols], noisy.values[:, cols], atol=0.05)
    assert r1 is ref
    ds = dataset_from_example(tmp_path / "ds")
    run = tmp_path / "run"
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(run), "--steps", "2", "--crop", "16",
                                 "--rotate-normals", "0.5"])
    assert r.exit_code == 0, r.output
    assert torch.load(run / "checkpoint.pt", weights_only=False)["train_config"]["p_rotate_normals"] == 0.5


def test_composite_coarse_charges_lost_energy():
    """The coarse term, on a block that is evenly lit in the reference: a firefly that kept its energy and the even
    light itself cost nothing, a dimmed firefly (the energy the held-out glass scenes lost) does, while per-pixel
    SMAPE scores the dimmed and the kept firefly alike; it is computed only when weighted, and its gradient
    reaches the prediction."""
    from ranad_core.train.losses import coarse_smape, smape

    ref = torch.ones(3, 8, 8)
    kept, dimmed = torch.zeros(3, 8, 8), torch.zeros(3, 8, 8)
    kept[:, 3, 4], dimmed[:, 3, 4] = 64.0, 8.0                   # the block's whole energy, and an eighth of it
    assert coarse_smape(ref, ref).item() == 0
    assert coarse_smape(kept, ref, (8,)).item() == pytest.approx(0, abs=1e-6)
    assert coarse_smape(dimmed, ref, (8,)).item() > 0.5
    assert smape(dimmed, ref).item() == pytest.approx(smape(kept, ref).item(), abs=0.01)
    corner = torch.ones(3, 6, 6)
    corner[:, 5, 5] = 0                                          # light lost in the partial block at the edge
    assert coarse_smape(corner, torch.ones(3, 6, 6), (4,)).item() > 0

    _check_optional_term("composite_coarse", lambda d: d * 0.5)


def test_an_unwritable_run_folder_is_refused_before_training(tmp_path, monkeypatch):
    """A run folder that cannot be made was an internal error; one that cannot be written to was found at the
    first checkpoint, --checkpoint-every steps of work later: both are one-line errors before step 1."""
    from ranad_core import fileutil

    ds = dataset_from_example(tmp_path / "ds")
    (tmp_path / "afile").write_text("")
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(tmp_path / "afile" / "run"), "--steps", "1"])
    assert r.exit_code == 2 and "cannot create the run folder" in r.output, r.output

    def refuse(*a, **k):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(fileutil.tempfile, "mkstemp", refuse)
    r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(tmp_path / "run"), "--steps", "1"])
    assert r.exit_code == 2 and "cannot write in this folder (Operation not permitted)" in r.output, r.output
    assert not (tmp_path / "run" / "checkpoint.pt").exists()


def _flip_test_images():
    """(reference, noisy, blurred) [H, W, 3] HDR images: gradients, a colour step and a bright bar (several
    exposures)."""
    import torch.nn.functional as F

    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[0:48, 0:40] / 40.0
    ref = np.stack([0.2 + 2.0 * xx * yy, 0.5 + 0.3 * np.sin(6 * xx), 0.1 + 4.0 * (xx > 0.6)], -1).astype(np.float32)
    ref[20:24, 10:30] *= 8.0
    noisy = (ref * rng.gamma(2.0, 0.5, ref.shape)).astype(np.float32)
    t = torch.from_numpy(ref).permute(2, 0, 1)
    blurred = F.avg_pool2d(t[None], 3, 1, 1, count_include_pad=False)[0].permute(1, 2, 0).numpy()
    return ref, noisy, blurred


def test_flip_term_is_hdr_flip():
    """The `flip` term's differentiable HDR-FLIP (train/flip_loss.py) against NVIDIA's evaluator (`ranad eval`'s
    metric, an independent implementation) on a noisy and a blurred copy of an HDR image; the gradient is finite."""
    pytest.importorskip("flip_evaluator", reason="the oracle needs flip-evaluator (pip install 'ranad[eval]')")
    from ranad_core import metrics
    from ranad_core.train.flip_loss import hdr_flip

    ref, noisy, blurred = _flip_test_images()
    for test in (noisy, blurred):
        want = metrics.flip(ref, test)
        x = torch.from_numpy(np.ascontiguousarray(test)).permute(2, 0, 1).requires_grad_()
        got = hdr_flip(torch.from_numpy(ref).permute(2, 0, 1), x)
        assert got.item() == pytest.approx(want, rel=0.01, abs=2e-4)
        got.backward()
        assert torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0


def test_flip_term_is_zero_for_the_reference_and_reaches_the_prediction():
    """Identical images score exactly 0 with a finite gradient (the papers' powers and norms have none at zero
    difference); a noisy copy scores well above 0; and the term through total_loss:
    absent unless weighted, positive for a spoilt prediction, its gradient reaching it (_check_optional_term)."""
    from ranad_core.train.flip_loss import hdr_flip

    ref, noisy, _ = _flip_test_images()
    t = torch.from_numpy(ref).permute(2, 0, 1)
    same = t.clone().requires_grad_()
    loss = hdr_flip(t, same)
    loss.backward()
    assert loss.item() == 0 and torch.isfinite(same.grad).all()
    assert hdr_flip(t, torch.from_numpy(noisy).permute(2, 0, 1)).item() > 0.05

    _check_optional_term("flip", lambda d: d * 0.5)
    _check_optional_term("edit_flip", lambda d: d * 0.5)   # the same HDR-FLIP on the compositing edit's image
