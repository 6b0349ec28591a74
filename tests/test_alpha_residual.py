"""The alpha residual (ModelConfig.alpha_residual, reconstruction.Reconstruction.residual): alpha's kernels plus a
per-bin correction from the bin's embedding. The model starts exactly as the weights it is grown from (`ranad
train --init`), the correction is what an independent MLP computes, it reaches alpha only, and training reaches
it."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from ranad_core.channels import canonical, detect
from ranad_core.exr import read_deep
from ranad_core.model import RaNAD, feature_dim, get_config, prepare
from ranad_core.model.config import ModelConfig
from ranad_core.model.crossframe import CrossFrameRaNAD
from ranad_core.train.trainer import grown_reconstruction

FRAME = Path(__file__).resolve().parents[1] / "examples" / "synth_shot" / "noisy_spp16.0001.exr"


def _inputs():
    img = read_deep(FRAME)
    return prepare(canonical(img, detect(img))[0].sorted()[0], features="prior")


def _grown():
    torch.manual_seed(0)
    plain = RaNAD(get_config("cpu-small-pd"), feature_dim("prior")).eval()
    grown = RaNAD(get_config("cpu-small-pda"), feature_dim("prior")).eval()
    grown.load_state_dict(grown_reconstruction(plain.state_dict(), grown.state_dict(), "test"))
    return plain, grown


def test_grown_model_starts_as_its_init():
    plain, grown = _grown()
    assert {n for n, _ in grown.named_parameters()} - {n for n, _ in plain.named_parameters()} == {
        f"recon.alpha.residual.{i}.{w}" for i in (0, 2) for w in ("weight", "bias")}
    inputs = _inputs()
    with torch.no_grad():
        a, b = plain(inputs), grown(inputs)
    assert set(a) == set(b)
    for name in a:
        torch.testing.assert_close(b[name], a[name], rtol=0, atol=0)


@pytest.mark.parametrize("inference", [False, True], ids=["autograd", "inference (fused where built)"])
def test_residual_adds_the_mlp_of_the_embedding_to_alpha_only(inference):
    plain, grown = _grown()
    g = torch.Generator().manual_seed(5)
    with torch.no_grad():
        for p in grown.recon["alpha"].residual.parameters():
            p.copy_(0.3 * torch.randn(p.shape, generator=g))
    inputs = _inputs()
    ctx = torch.inference_mode() if inference else torch.no_grad()
    with ctx:
        emb = plain.embeddings(inputs)
        a, b = plain.reconstruct(emb, inputs), grown.reconstruct(emb, inputs)
    res = grown.recon["alpha"].residual
    with torch.no_grad():   # the MLP written out with plain tensor maths
        hidden = torch.relu(emb @ res[0].weight.T + res[0].bias)
        correction = hidden @ res[2].weight.T + res[2].bias
    assert float(correction.abs().max()) > 1e-2
    torch.testing.assert_close(b["alpha"], a["alpha"] + correction, rtol=1e-4, atol=1e-5)
    for name in a.keys() - {"alpha"}:
        torch.testing.assert_close(b[name], a[name], rtol=0, atol=0)


def test_training_reaches_the_residual():
    _, grown = _grown()
    grown.train()
    out = grown(_inputs())
    out["alpha"].square().mean().backward()
    last = grown.recon["alpha"].residual[2]
    assert float(last.weight.grad.abs().sum()) > 0 and float(last.bias.grad.abs()) > 0


def test_residual_on_a_layer_with_aovs_is_refused():
    _, grown = _grown()
    inputs = _inputs()
    with torch.no_grad(), pytest.raises(ValueError, match="one channel"):
        grown.reconstruct_layer("alpha", grown.embeddings(inputs), inputs, inputs.layers["diffuse"])


def test_cross_frame_alpha_residual_is_refused():
    cfg = ModelConfig(**{**get_config("cpu-small-pd-xg").__dict__, "name": "x", "alpha_residual": True})
    with pytest.raises(ValueError, match="alpha-residual"):
        CrossFrameRaNAD(cfg, feature_dim("prior"))
