"""The GPU path of `ranad denoise --device` and `ranad train --device`: device choice everywhere, and on a machine
with a CUDA GPU the model, tiles, AOV reuse, the flat prior's OIDN and a training loss on the GPU against the same
run on the CPU.

The GPU cases skip without a CUDA GPU (CI has none); their code is still imported and the device choice is
tested on every machine. The CUDA kernels themselves are checked against the reference in test_rana_cuda.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core.aov import aov_layers, denoise_aovs
from ranad_core.channels import detect
from ranad_core.denoise import denoise_window, is_cross_frame
from ranad_core.device import resolve
from ranad_core.errors import RanadError
from ranad_core.exr import read_deep
from ranad_core.model.store import DEFAULT_CROSS_MODEL, DEFAULT_MODEL, load_checkpoint, load_model
from test_train import dataset_from_example

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"
HAS_GPU = torch.cuda.is_available()
gpu = pytest.mark.skipif(not HAS_GPU, reason="no CUDA GPU here (CPU-only torch or no device)")


def test_cpu_is_always_available():
    assert resolve("cpu") == torch.device("cpu")


@pytest.mark.skipif(HAS_GPU, reason="checks the refusal on a machine without a GPU")
def test_without_a_gpu_cuda_is_refused_and_auto_runs_on_the_cpu(tmp_path):
    with pytest.raises(RanadError, match="no CUDA GPU"):
        resolve("cuda")
    assert resolve("auto") == torch.device("cpu")
    out = tmp_path / "out.exr"
    r = CliRunner().invoke(cli, ["denoise", str(SHOT / "noisy_spp16.0001.exr"), "-o", str(out), "--device", "cuda"])
    assert r.exit_code == 2, r.output
    assert "--device: no CUDA GPU is visible" in r.output and len(r.output.strip().splitlines()) == 1
    assert not out.exists()
    r = CliRunner().invoke(cli, ["aov", str(tmp_path), "--layers", "lg_*", "-o", str(tmp_path / "aov/"),
                                 "--device", "cuda"])
    assert r.exit_code == 2 and "--device: no CUDA GPU is visible" in r.output, r.output


@pytest.mark.skipif(HAS_GPU, reason="checks the refusal on a machine without a GPU")
def test_without_a_gpu_training_on_cuda_is_refused(tmp_path):
    """`ranad train --device cuda` on a CPU machine: one line, exit 2, no run folder; data-parallel processes on a
    GPU are refused on any machine."""
    ds = dataset_from_example(tmp_path / "ds")
    for extra, msg in ((["--device", "cuda"], "--device: no CUDA GPU is visible"),
                       (["--device", "cuda", "--processes", "2"], "data-parallel --processes run on the CPU")):
        run = tmp_path / "run"
        r = CliRunner().invoke(cli, ["train", str(ds), "-o", str(run), "--steps", "1", "--crop", "16", *extra])
        assert r.exit_code == 2 and msg in r.output, r.output
        assert not run.exists()


def _close(a: np.ndarray, b: np.ndarray, what: str) -> None:
    """GPU and CPU float32 sums differ in order; embeddings are then rounded to float16 (the AOV cache's
    precision), so an element may move by one float16 step: a mean relative and a worst-case bound."""
    scale = float(np.abs(b).max()) or 1.0
    mean_rel = float(np.abs(a - b).mean() / max(np.abs(b).mean(), 1e-12))
    assert mean_rel < 2e-3, f"{what}: mean relative difference {mean_rel:.2e}"
    assert float(np.abs(a - b).max()) < 5e-2 * scale, f"{what}: worst difference {np.abs(a - b).max():.3g}"


def _run(model_name: str, device: str, frames: list, tile: int = 32):
    model = load_model(model_name).model.to(device)
    images, centre = (frames, 1) if is_cross_frame(model) else ([frames[1]], 0)
    res = denoise_window(model, images, centre, tile=tile, want_embeddings=True)
    layers = aov_layers(frames[1].channels, "lg_*")
    aovs = denoise_aovs(model, images, centre, detect(frames[1]), layers, res.embeddings, res.perms, res.offsets,
                       None, res.merge_gap, res.merges, res.split, res.dark_radius, res.gain)
    return res, aovs


@gpu
@pytest.mark.parametrize("model_name", ["cpu-small-v1", DEFAULT_MODEL, DEFAULT_CROSS_MODEL])
def test_shipped_models_on_the_gpu_equal_the_cpu(model_name):
    frames = [read_deep(SHOT / f"noisy_spp16.{i:04d}.exr") for i in range(3)]
    (cpu, cpu_aovs), (dev, dev_aovs) = _run(model_name, "cpu", frames), _run(model_name, "cuda", frames)
    assert dev.image.channels == cpu.image.channels and np.array_equal(dev.image.offsets, cpu.image.offsets)
    _close(dev.image.values, cpu.image.values, f"{model_name} denoised frame")
    for g in cpu_aovs:
        _close(dev_aovs[g], cpu_aovs[g], f"{model_name} AOV {g}")
    noisy = frames[1].values
    assert np.abs(dev.image.values - noisy).max() > 1e-3 * np.abs(noisy).max()   # it denoised


@gpu
def test_flat_prior_on_the_gpu_equals_the_cpu():
    from ranad_core.model.prior import oidn_on, with_prior

    img = read_deep(SHOT / "noisy_spp16.0001.exr")
    with oidn_on("cpu"):
        a = with_prior(img).values
    with oidn_on("cuda"):
        b = with_prior(img).values
    _close(b, a, "flat prior")


@gpu
def test_cli_device_cuda(tmp_path):
    out = tmp_path / "out.exr"
    r = CliRunner().invoke(cli, ["denoise", str(SHOT / "noisy_spp16.0001.exr"), "-o", str(out), "--device", "cuda",
                                 "--reference", str(SHOT / "reference_spp16.0001.exr")])
    assert r.exit_code == 0, r.output
    assert "device: cuda" in r.output
    before, after = (float(x) for x in r.output.split("SMAPE vs reference ")[1].split(" (")[0].split(" -> "))
    assert after < before


@gpu
def test_training_loss_on_the_gpu_equals_the_cpu(tmp_path):
    """One training crop's loss (the model in eval mode, so bin dropout draws nothing) on the GPU and on the CPU,
    from the same random stream: equal to float32 summation order."""
    from ranad_core.train.trainer import TrainConfig, pair_loss
    from ranad_core.train.data import find_pairs

    ds = dataset_from_example(tmp_path / "ds")
    cfg = TrainConfig(dataset=str(ds), run=str(tmp_path / "run"), config="cpu-small-pd", crop=32)
    pair = find_pairs(cfg.dataset)[0]
    model = load_model(DEFAULT_MODEL).model.eval()
    cpu_loss, cpu_parts = pair_loss(model, pair, np.random.default_rng(3), cfg, False)
    gpu_loss, gpu_parts = pair_loss(model.to("cuda"), pair, np.random.default_rng(3), cfg, False)
    assert gpu_loss.device.type == "cuda"
    assert gpu_loss.item() == pytest.approx(cpu_loss.item(), rel=2e-3)
    for k in cpu_parts:
        assert gpu_parts[k] == pytest.approx(cpu_parts[k], rel=5e-3, abs=1e-5), k


@gpu
def test_cli_train_on_the_gpu_resumes_on_the_cpu(tmp_path):
    """`ranad train --device cuda` trains and checkpoints; the checkpoint resumes on the CPU."""
    ds = dataset_from_example(tmp_path / "ds")
    run = tmp_path / "run"
    base = ["train", str(ds), "-o", str(run), "--crop", "16", "--config", "cpu-small-pd", "--checkpoint-every", "1"]
    r = CliRunner().invoke(cli, [*base, "--steps", "4", "--until", "2", "--device", "cuda"])
    assert r.exit_code == 0, r.output
    state = load_checkpoint(run / "checkpoint.pt")
    assert state["step"] == 2 and state["train_config"]["device"] == "cuda"
    assert all(torch.isfinite(v).all() for v in state["model"].values())
    r = CliRunner().invoke(cli, [*base, "--steps", "4", "--device", "cpu"])
    assert r.exit_code == 0, r.output
    assert load_checkpoint(run / "checkpoint.pt")["step"] == 4


@gpu
def test_device_free_bytes_reads_the_gpu():
    """The GPU budget of the tiles: positive, below the card's total, and it shrinks by what torch allocates."""
    from ranad_core.memory import device_free_bytes

    total = torch.cuda.get_device_properties(0).total_memory
    before = device_free_bytes("cuda")
    held = torch.empty(256 * 2**20, dtype=torch.uint8, device="cuda")
    after = device_free_bytes("cuda")
    assert 0 < after < before < total
    assert before - after == pytest.approx(held.numel(), rel=0.05)
