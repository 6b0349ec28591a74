"""The layer gate (ModelConfig.layer_gate, reconstruction.layer_gate): a gated layer's kernels keep to the query
bin's own depth layer in pixels of several bins, leave single-bin pixels alone, and stay linear in the values."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from ranad_core.channels import canonical, detect
from ranad_core.deep import DeepImage
from ranad_core.model import RaNAD, feature_dim, get_config, prepare
from ranad_core.model.config import ModelConfig
from ranad_core.model.layers import Layout
from ranad_core.model.reconstruction import GATE_STRENGTH, GATE_WIDTH_FLOOR, KernelAttention, layer_gate


def _config(layers=("depth", "alpha")):
    return dataclasses.replace(get_config("cpu-small-pdl"), name="gated-test", layer_gate=tuple(layers))


def test_gate_width_is_half_the_gap_to_the_pixels_nearest_other_bin():
    # pixels (1 row of 4): one bin; three bins at depths 1, 2, 2.05; none; two bins 5 apart in log depth
    z = torch.tensor([[3.0], [1.0], [2.0], [2.05], [1.0], [math.e ** 5]])
    layout = Layout.of(torch.tensor([0, 1, 4, 4, 6]), 1, 4)
    a, b = layer_gate(z, layout)
    lz = torch.log(z[:, 0])
    torch.testing.assert_close(a[:, 0], lz - lz.mean())
    assert torch.equal(a, b)                      # the same guides as queries and as keys
    gap = torch.tensor([math.inf, math.log(2), math.log(2.05 / 2), math.log(2.05 / 2), 5.0, 5.0])
    h = torch.clamp(gap / 2, min=GATE_WIDTH_FLOOR)
    expected = torch.where(torch.isinf(gap), torch.zeros(6), GATE_STRENGTH / h ** 2)
    torch.testing.assert_close(a[:, 1], expected, rtol=1e-5, atol=1e-5)
    assert float(a[0, 1]) == 0.0 and float(a[2, 1]) == GATE_STRENGTH / GATE_WIDTH_FLOOR ** 2   # floored


def test_gate_term_is_minus_both_lambdas_times_the_squared_log_depth_distance():
    """-(lambda_q + lambda_k) (za - zb)^2, plus terms of the query alone; with the prior range too, both terms
    add to the plain logits."""
    g = torch.Generator().manual_seed(0)
    att = KernelAttention(dim=4, heads=2, head_dim=8, radius=1.5, prior_range=True, gated=True)
    with torch.no_grad():
        att.range.copy_(torch.tensor([0.7, -0.3]))
    q, k = torch.randn(5, 2, 8, generator=g), torch.randn(7, 2, 8, generator=g)
    pa, pb = torch.rand(5, 3, generator=g), torch.rand(7, 3, generator=g)
    za, zb = torch.randn(5, 1, generator=g), torch.randn(7, 1, generator=g)
    lq, lk = torch.rand(5, 1, generator=g) * 9, torch.rand(7, 1, generator=g) * 9
    qa, ka = att._with_range(q, k, (torch.cat([pa, za, lq], 1), torch.cat([pb, zb, lk], 1)))
    assert qa.shape == (5, 2, 32) and ka.shape == (7, 2, 32)     # 8 + 4 + 5 columns: the next size, 32
    got = torch.einsum("qhd,khd->qkh", qa, ka) / math.sqrt(32)
    plain = torch.einsum("qhd,khd->qkh", q, k) / math.sqrt(8)
    rng = att.range.detach()
    prior = -rng * ((pa[:, None] - pb[None]) ** 2).sum(-1)[..., None] + rng * (pa * pa).sum(1)[:, None, None]
    gate = -(lq + lk.T) * (za - zb.T) ** 2 + lq * za ** 2                               # [q, k]
    torch.testing.assert_close(got, plain + prior + gate[..., None], rtol=1e-5, atol=1e-4)


def _two_layer_image(size=12, seed=0) -> DeepImage:
    """Every pixel: a semi-transparent layer at depth 1 (+-0.1% noise) in front of one at depth 1.3; a band of
    single-bin pixels (depth 1) in the middle rows. Noisy colours; the depths are what the test follows."""
    rng = np.random.default_rng(seed)
    counts = np.full(size * size, 2)
    counts[(size // 2) * size:(size // 2 + 2) * size] = 1
    offsets = np.concatenate([[0], np.cumsum(counts)])
    n = int(offsets[-1])
    z = np.ones(n, np.float32)
    back = np.zeros(n, bool)
    back[offsets[1:][counts == 2] - 1] = True
    z[back] = 1.3
    z *= 1 + 0.001 * rng.standard_normal(n).astype(np.float32)
    rgb = rng.uniform(0, 2, (n, 3)).astype(np.float32)
    alpha = np.where(back, 1.0, 0.4).astype(np.float32)
    values = np.concatenate([rgb * alpha[:, None], alpha[:, None], z[:, None]], 1)
    return DeepImage(values=values, offsets=offsets, channels=["R", "G", "B", "A", "Z"],
                     data_window=(0, 0, size - 1, size - 1), display_window=(0, 0, size - 1, size - 1))


@pytest.mark.parametrize("seed", [0, 1])
def test_gated_depth_keeps_each_bin_on_its_own_layer(seed):
    """An untrained model's kernels mix the two layers' depths; gated, every bin keeps its layer's depth: in
    two-bin pixels (the other layer weighs e^-16 or less) and in the band of single-bin pixels too, whose
    neighbours' back bins are gated as keys."""
    img = _two_layer_image(seed=seed)
    inputs = prepare(canonical(img, detect(img))[0].sorted()[0], features="prior")
    torch.manual_seed(seed)
    plain = RaNAD(get_config("cpu-small-pdl"), feature_dim("prior")).eval()
    gated = RaNAD(_config(), feature_dim("prior")).eval()
    gated.load_state_dict(plain.state_dict())         # parameter-free: the same weights load
    z = inputs.layers["depth"][:, 0]
    layer = torch.where(z > 1.15, 1.3, 1.0)
    multi = torch.from_numpy(np.repeat(img.counts == 2, img.counts))
    with torch.no_grad():
        zp = plain(inputs)["depth"][:, 0]
        zg = gated(inputs)["depth"][:, 0]
    err_plain = (zp - layer).abs() / layer
    err_gated = (zg - layer).abs() / layer
    assert float(err_plain[multi].max()) > 0.02 and float(err_plain[~multi].max()) > 0.02   # the layers bleed
    assert float(err_gated.max()) < 0.005                    # the bins' own noise (0.1%) is all that is left


def test_gate_leaves_images_of_single_bin_pixels_alone():
    img = _two_layer_image()
    one = img.keep(np.arange(img.num_bins) == img.offsets[:-1].repeat(img.counts))      # each pixel's front bin
    assert (one.counts == 1).all()
    inputs = prepare(canonical(one, detect(one))[0].sorted()[0], features="prior")
    torch.manual_seed(0)
    plain = RaNAD(get_config("cpu-small-pdl"), feature_dim("prior")).eval()
    gated = RaNAD(_config(("depth", "alpha", "diffuse", "specular")), feature_dim("prior")).eval()
    gated.load_state_dict(plain.state_dict())
    with torch.no_grad():
        a, b = plain(inputs), gated(inputs)
    for name in a:
        torch.testing.assert_close(b[name], a[name], rtol=1e-5, atol=1e-6)


def test_gated_reconstruction_stays_linear_and_config_round_trips():
    img = _two_layer_image()
    inputs = prepare(canonical(img, detect(img))[0].sorted()[0], features="prior")
    torch.manual_seed(3)
    cfg = _config(("depth", "alpha", "diffuse"))
    model = RaNAD(cfg, feature_dim("prior")).eval()
    x, y = (torch.rand(inputs.layout.bins, 6, generator=torch.Generator().manual_seed(s)) for s in (3, 4))
    with torch.no_grad():
        emb = model.embeddings(inputs)
        r = lambda v: model.reconstruct_layer("diffuse", emb, inputs, v)  # noqa: E731
        torch.testing.assert_close(r(2 * x - 3 * y), 2 * r(x) - 3 * r(y), rtol=1e-4, atol=1e-5)
    back = ModelConfig.from_dict(cfg.to_dict())
    assert back == cfg and back.layer_gate == ("depth", "alpha", "diffuse")
    assert ModelConfig.from_dict({k: v for k, v in cfg.to_dict().items() if k != "layer_gate"}).layer_gate == ()
    with pytest.raises(ValueError, match="layer_gate names layers it does not reconstruct"):
        RaNAD(dataclasses.replace(cfg, layer_gate=("depht",)), feature_dim("prior"))


def test_gated_model_tiles_like_the_whole_frame_and_keeps_depth_on_request():
    """log z is centred per tile, which the range term does not see: tiles give the whole frame's result to
    float rounding. --keep-depth writes the file's depths while alpha, gated, still reads them."""
    from ranad_core.denoise import denoise_frame, denoise_window, halo_for

    img = _two_layer_image(size=40, seed=2)
    torch.manual_seed(4)
    model = RaNAD(_config(), feature_dim("prior")).eval()
    whole = denoise_frame(model, img).image
    tiled = denoise_frame(model, img, tile=16, halo=halo_for(model)).image
    assert tiled.num_bins == whole.num_bins
    for c in ("R", "A", "Z"):
        np.testing.assert_allclose(tiled.channel(c), whole.channel(c), rtol=1e-4, atol=1e-5)
    kept = denoise_window(model, [img], 0, keep_depth=True).image
    assert np.array_equal(kept.channel("Z"), img.channel("Z"))
    np.testing.assert_allclose(kept.channel("A"), whole.channel("A"), rtol=1e-5, atol=1e-6)


STACK = Path(__file__).resolve().parent / "data" / "ranad-synth"


def test_default_model_gets_a_held_out_layer_stacks_depths_closer_than_the_noisy_input():
    """A crop of a scene family no training set holds (tests/data/ranad-synth): against its 1024-spp reference,
    the default model's per-bin depths beat the noisy input's, and its flattened image too; the ungated
    `cpu-small-pdl-v1`, whose kernels averaged the layers into each other, is the case this catches."""
    from ranad_core.denoise import denoise_frame
    from ranad_core.exr import read_deep
    from ranad_core.metrics import flat_rgb, flip, z_rel
    from ranad_core.model.store import DEFAULT_MODEL, load_model

    noisy = read_deep(STACK / "layer_stack_noisy_spp16.exr")
    ref = read_deep(STACK / "layer_stack_reference_spp16.exr")
    assert (noisy.counts > 1).all()
    out = denoise_frame(load_model(DEFAULT_MODEL).model, noisy).image
    z_noisy = z_rel(ref, noisy)
    assert z_rel(ref, out) < 0.9 * z_noisy                                          # measured 0.81x
    assert flip(flat_rgb(ref), flat_rgb(out)) < flip(flat_rgb(ref), flat_rgb(noisy))
    ungated = denoise_frame(load_model("cpu-small-pdl-v1").model, noisy).image
    assert z_rel(ref, ungated) > 1.3 * z_noisy                                      # measured 1.71x
