"""Albedo demodulation of the diffuse layer (configs with `demodulate`, reconstruction.demodulated): a texture the
albedo guide shows passes the kernels untouched, the operator stays linear in the values, and files without
albedo or without the diffuse/specular split are not demodulated."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from model_factory import demodulating
from ranad_core.channels import ALBEDO, SPECULAR, canonical, detect
from ranad_core.exr import read_deep
from ranad_core.model import RaNAD, feature_dim, get_config, prepare
from ranad_core.model.inputs import DEMOD_FLOOR, modulation

FRAME = Path(__file__).resolve().parents[1] / "examples" / "synth_shot" / "noisy_spp16.0001.exr"


def inputs_of(img):
    return prepare(canonical(img, detect(img))[0].sorted()[0])


def models():
    torch.manual_seed(0)
    plain = RaNAD(get_config("cpu-small"), feature_dim()).eval()
    demod = RaNAD(demodulating(get_config("cpu-small")), feature_dim()).eval()
    demod.load_state_dict(plain.state_dict())
    return plain, demod


def test_irradiance_times_albedo_comes_back_unchanged():
    """A diffuse layer that is a constant irradiance times (albedo + floor) is flat after demodulation, so it comes
    back as the texture times what the kernels make of a constant layer (1 wherever they are convex; less where a
    coarse scale finds no bins near a sparse bin): the texture is kept exactly. The same kernels without
    demodulation average the texture (the oracle that the test can fail)."""
    inputs = inputs_of(read_deep(FRAME))
    mod = inputs.modulation
    assert mod is not None and float(mod.std(0).min()) > 0.05          # a textured albedo
    textured = mod * torch.tensor([0.3, 0.5, 0.7])
    plain, demod = models()
    with torch.no_grad():
        emb = demod.embeddings(inputs)
        out = demod.reconstruct_layer("diffuse", emb, inputs, textured)
        blurred = plain.reconstruct_layer("diffuse", emb, inputs, textured)
        flat = plain.reconstruct_layer("diffuse", emb, inputs, torch.ones_like(textured))
    torch.testing.assert_close(out, textured * flat, rtol=1e-5, atol=1e-6)
    assert float((flat - 1).abs().median()) < 1e-6                   # mostly convex: the check has teeth
    assert float((blurred - textured).abs().max()) > 0.05


def test_demodulated_reconstruction_is_linear_in_the_values():
    inputs = inputs_of(read_deep(FRAME))
    _, demod = models()
    g = torch.Generator().manual_seed(1)
    x, y = (torch.rand(inputs.layout.bins, 6, generator=g) for _ in range(2))   # two RGB triplets batched
    with torch.no_grad():
        emb = demod.embeddings(inputs)
        r = lambda v: demod.reconstruct_layer("diffuse", emb, inputs, v)  # noqa: E731
        torch.testing.assert_close(r(2 * x - 3 * y), 2 * r(x) - 3 * r(y), rtol=1e-4, atol=1e-5)
        torch.testing.assert_close(r(x)[:, 3:], r(torch.cat([x[:, 3:], x[:, :3]], 1))[:, :3])


def test_no_modulation_without_albedo_or_without_the_split():
    img = canonical(read_deep(FRAME), detect(read_deep(FRAME)))[0]
    mod = modulation(img)
    albedo = np.stack([img.channel(c) for c in ALBEDO], 1)
    np.testing.assert_allclose(mod, np.clip(albedo, 0, 1) + DEMOD_FLOOR, rtol=1e-6)
    without = lambda names: img.select([c for c in img.channels if c not in names])  # noqa: E731
    assert modulation(without(ALBEDO)) is None
    assert modulation(without(SPECULAR)) is None     # the "diffuse" layer then holds the whole beauty
    _, demod = models()
    assert demod.modulation("specular", inputs_of(read_deep(FRAME))) is None
