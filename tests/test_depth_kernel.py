"""The reconstruction's depth term (configs with `depth_kernel`, reconstruction.KernelAttention): the kernels are the
softmax of q.k/sqrt(d) + bias - w (z_q - z_k)^2, written out pair by pair as the oracle; only depth differences
count; a layer far in depth gets none of a bin's weight; the model stays linear in the values; a model starts from
one without the term."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from model_factory import demodulating, depth_kernel, open_depth_term
from ranad_core.channels import canonical, detect
from ranad_core.exr import read_deep
from ranad_core.model import RaNAD, feature_dim, get_config, prepare
from ranad_core.model.layers import Layout
from ranad_core.model.reconstruction import KernelAttention
from ranad_core.rana.reference import neighbour_pairs

FRAME = Path(__file__).resolve().parents[1] / "examples" / "synth_shot" / "noisy_spp16.0001.exr"


def ragged(h=9, w=11, seed=0, dim=12):
    g = torch.Generator().manual_seed(seed)
    counts = torch.randint(0, 4, (h * w,), generator=g)
    offsets = torch.cat([torch.zeros(1, dtype=torch.int64), torch.cumsum(counts, 0)])
    layout = Layout.of(offsets, h, w)
    n = layout.bins
    return layout, torch.randn(n, dim, generator=g), torch.randn(n, 3, generator=g), torch.rand(n, generator=g) * 2


def by_pairs(att: KernelAttention, feat, layout, values, z):
    """The kernel written out per (query, key) pair in float64: softmax of q.k/sqrt(d) + bias - w (zq - zk)^2."""
    H, d = att.heads, att.head_dim
    with torch.no_grad():
        q = att.q(feat).double().view(-1, d, H).transpose(1, 2)
        k = att.k(feat).double().view(-1, d, H).transpose(1, 2)
        w = att.depth_weight().double()
        qi, kj, oy, ox = neighbour_pairs(layout.pixels, layout.offsets, layout.size, att.radius)
        z = z.double()
        logit = (q[qi] * k[kj]).sum(-1) / math.sqrt(d) + att.bias.double()[:, oy, ox].T \
            - w[None, :] * (z[qi] - z[kj])[:, None] ** 2                                   # [P, H]
        out = torch.zeros(len(feat), H, values.shape[1], dtype=torch.float64)
        for i in range(len(feat)):
            sel = qi == i
            if sel.any():
                p = torch.softmax(logit[sel], 0)                                               # [n, H]
                out[i] = (p[:, :, None] * values.double()[kj[sel]][:, None, :]).sum(0)
        return (out * torch.softmax(att.head_mix.double(), 0)[None, :, None]).sum(1)


def test_depth_term_matches_the_pairwise_oracle():
    torch.manual_seed(1)
    layout, feat, values, z = ragged()
    att = KernelAttention(12, heads=2, head_dim=8, radius=2.5, depth_term=True)
    open_depth_term(att, 40.0)
    with torch.no_grad():
        att.bias.normal_()
        got = att(feat, feat, layout.pixels, layout, values, z, z)
    want = by_pairs(att, feat, layout, values, z)
    np.testing.assert_allclose(got.double().numpy(), want.numpy(), atol=2e-5, rtol=1e-4)
    # and the term matters: without it (w -> 0) the result is another one
    open_depth_term(att, 1e-6)
    with torch.no_grad():
        off = att(feat, feat, layout.pixels, layout, values, z, z)
    assert (off - got).abs().max() > 1e-2


def test_only_depth_differences_count_and_far_layers_get_no_weight():
    """A shift of every log depth (a change of depth unit) leaves the output as it is. Two layers of constant
    colour, one ten times deeper than the other, in a checkerboard: with a strong term each bin averages its own
    layer only, so the colours come back exactly."""
    torch.manual_seed(2)
    layout, feat, values, z = ragged(seed=3)
    att = KernelAttention(12, heads=2, head_dim=8, radius=2.5, depth_term=True)
    open_depth_term(att, 50.0)
    with torch.no_grad():
        a = att(feat, feat, layout.pixels, layout, values, z, z)
        b = att(feat, feat, layout.pixels, layout, values, z + 3.0, z + 3.0)
    # to float32 rounding of the larger products (2 w z_q z_k ~ 2.5e3 here: ~1e-4 in the logits)
    np.testing.assert_allclose(a.numpy(), b.numpy(), atol=5e-4)
    assert (a - values).abs().max() > 1e-2   # (and the output is not the values themselves)

    h = w = 8
    offsets = torch.arange(h * w + 1, dtype=torch.int64)
    checker = Layout.of(offsets, h, w)
    far = ((checker.pixels[:, 0] + checker.pixels[:, 1]) % 2).bool()
    zc = torch.where(far, torch.tensor(math.log(10.0)), torch.tensor(0.0))
    colour = torch.where(far[:, None], torch.tensor([[0.1, 0.2, 0.3]]), torch.tensor([[2.0, 1.0, 0.5]]))
    feat = torch.randn(h * w, 12)
    open_depth_term(att, 1e4)
    with torch.no_grad():
        out = att(feat, feat, checker.pixels, checker, colour, zc, zc)
        open_depth_term(att, 1e-6)
        mixed = att(feat, feat, checker.pixels, checker, colour, zc, zc)
    np.testing.assert_allclose(out.numpy(), colour.numpy(), rtol=1e-5)
    assert (mixed - colour).abs().max() > 0.1


def test_model_with_the_term_is_linear_and_needs_depths():
    img = read_deep(FRAME)
    inputs = prepare(canonical(img, detect(img))[0].sorted()[0])
    torch.manual_seed(0)
    model = open_depth_term(RaNAD(depth_kernel(demodulating(get_config("cpu-small"))), feature_dim()).eval())
    with torch.no_grad():
        emb = model.embeddings(inputs)
        x, y = inputs.layers["diffuse"], torch.rand_like(inputs.layers["diffuse"])
        fx, fy = (model.reconstruct_layer("diffuse", emb, inputs, v) for v in (x, y))
        fxy = model.reconstruct_layer("diffuse", emb, inputs, 2 * x - 3 * y)
    np.testing.assert_allclose(fxy.numpy(), (2 * fx - 3 * fy).numpy(), atol=1e-4 * float(fx.abs().max()))
    inputs.log_depth = None
    try:
        model.reconstruct_layer("diffuse", emb, inputs, x)
    except ValueError as e:
        assert "depth" in str(e)
    else:
        raise AssertionError("a model with the depth term ran without depths")


def test_starts_from_a_model_without_the_term(tmp_path):
    """--init from a model without the term: every shared weight is the old model's, the term starts at its
    (weak) initial weight, and the output is close to the old model's."""
    import json

    from safetensors.torch import save_file

    from ranad_core.train.trainer import init_single

    torch.manual_seed(0)
    old = RaNAD(get_config("cpu-small-pd"), feature_dim("prior")).eval()
    path = tmp_path / "old.safetensors"
    save_file({k: v.contiguous() for k, v in old.state_dict().items()}, str(path),
              metadata={"model_config": json.dumps(old.config.to_dict())})
    new = RaNAD(get_config("cpu-small-pdz"), feature_dim("prior")).eval()
    init_single(new, str(path))
    theirs, ours = old.state_dict(), new.state_dict()
    assert set(ours) - set(theirs) and all(k.endswith("depth_theta") for k in set(ours) - set(theirs))
    for k, v in theirs.items():
        assert torch.equal(ours[k], v), k
    assert all(float(v.abs().max()) == 0 for k, v in ours.items() if k.endswith("depth_theta"))
