"""The prior-range reconstruction (ModelConfig.prior_range, reconstruction.KernelAttention._with_range): the logits
gain -lambda |prior(query) - noisy flat(key)|^2 per head, the model starts exactly as the weights it is grown from,
and its outputs stay linear in the values."""

from __future__ import annotations

import math
from pathlib import Path

import torch

from ranad_core.channels import canonical, detect
from ranad_core.exr import read_deep
from ranad_core.model import RaNAD, feature_dim, get_config, prepare
from ranad_core.model.inputs import PRIOR_AT
from ranad_core.model.reconstruction import KernelAttention

FRAME = Path(__file__).resolve().parents[1] / "examples" / "synth_shot" / "noisy_spp16.0001.exr"


def test_range_term_is_minus_lambda_times_the_squared_distance():
    """q'.k' / sqrt(d') of the extended operands, written out against the plain q.k / sqrt(d): the difference is
    -lambda_h |a - b|^2 plus lambda_h |a|^2, a term of the query alone (the softmax over keys ignores it)."""
    g = torch.Generator().manual_seed(0)
    att = KernelAttention(dim=4, heads=2, head_dim=8, radius=1.5, prior_range=True)
    with torch.no_grad():
        att.range.copy_(torch.tensor([0.7, -0.3]))
    q, k = torch.randn(5, 2, 8, generator=g), torch.randn(7, 2, 8, generator=g)
    a, b = torch.rand(5, 3, generator=g), torch.rand(7, 3, generator=g)
    qa, ka = att._with_range(q, k, (a, b))
    assert qa.shape == (5, 2, 16) and ka.shape == (7, 2, 16)
    got = torch.einsum("qhd,khd->qkh", qa, ka) / math.sqrt(16)
    plain = torch.einsum("qhd,khd->qkh", q, k) / math.sqrt(8)
    dist = ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)                    # [q, k]
    lam = att.range.detach()
    expected = plain - lam * dist[..., None] + lam * (a * a).sum(1)[:, None, None]
    torch.testing.assert_close(got, expected, rtol=1e-5, atol=1e-5)


def _inputs():
    img = read_deep(FRAME)
    inputs = prepare(canonical(img, detect(img))[0].sorted()[0], features="prior")
    g = torch.Generator().manual_seed(2)
    inputs.features[:, PRIOR_AT:PRIOR_AT + 6] = torch.rand(inputs.layout.bins, 6, generator=g)   # some guides
    return inputs


def test_prior_range_model_starts_as_its_init_and_stays_linear():
    torch.manual_seed(0)
    plain = RaNAD(get_config("cpu-small-pd"), feature_dim("prior")).eval()
    ranged = RaNAD(get_config("cpu-small-pdr"), feature_dim("prior")).eval()
    result = ranged.load_state_dict(plain.state_dict(), strict=False)
    assert result.missing_keys and all(k.endswith(".range") for k in result.missing_keys)
    inputs = _inputs()
    with torch.no_grad():
        emb, emb_r = plain.embeddings(inputs), ranged.embeddings(inputs)
        # the guides ride behind the embeddings (what the AOV cache keeps)
        assert emb_r.shape[1] == ranged.embedding_width() == emb.shape[1] + 6
        torch.testing.assert_close(emb_r[:, :emb.shape[1]], emb)
        torch.testing.assert_close(emb_r[:, emb.shape[1]:], inputs.features[:, PRIOR_AT:PRIOR_AT + 6])
        for name in ("diffuse", "alpha"):
            torch.testing.assert_close(ranged.reconstruct_layer(name, emb_r, inputs, inputs.layers[name]),
                                       plain.reconstruct_layer(name, emb, inputs, inputs.layers[name]),
                                       rtol=1e-5, atol=1e-6)
        for m in ranged.modules():
            if isinstance(m, KernelAttention):
                m.range.fill_(2.0)
        x, y = (torch.rand(inputs.layout.bins, 6, generator=torch.Generator().manual_seed(s)) for s in (3, 4))
        r = lambda v: ranged.reconstruct_layer("diffuse", emb_r, inputs, v)  # noqa: E731
        torch.testing.assert_close(r(2 * x - 3 * y), 2 * r(x) - 3 * r(y), rtol=1e-4, atol=1e-5)
        moved = ranged.reconstruct_layer("specular", emb_r, inputs, inputs.layers["specular"])
        same = plain.reconstruct_layer("specular", emb, inputs, inputs.layers["specular"])
        assert float((moved - same).abs().max()) > 1e-3                   # the term does something


def test_range_weights_learn_at_their_own_rate():
    """A loss on the output reaches every range weight, and the trainer gives them RANGE_LR_SCALE."""
    from ranad_core.model.ranad import RANGE_LR_SCALE
    from ranad_core.train.trainer import param_groups

    torch.manual_seed(0)
    model = RaNAD(get_config("cpu-small-pdr"), feature_dim("prior"))
    inputs = _inputs()
    out = model(inputs)
    sum(v.square().mean() for v in out.values()).backward()
    ranges = {n: p for n, p in model.named_parameters() if n.endswith(".range")}
    assert len(ranges) == 14 and all(float(p.grad.abs().sum()) > 0 for p in ranges.values())
    groups = {g["lr_scale"]: set(g["names"]) for g in param_groups(model)}
    assert groups[RANGE_LR_SCALE] == set(ranges) and RANGE_LR_SCALE > 1
