"""The single-frame RaNAD model (paper Fig. 6): input embedding, multi-U-Net backbone, one reconstruction module
per output layer. Every output is a softmax-weighted combination of that layer's noisy values (linear in them);
with `demodulate`, the diffuse layer's is one of its albedo-demodulated values, times the bin's albedo
(reconstruction.demodulated).
"""

from __future__ import annotations

import torch
from torch import nn

from . import fused
from .backbone import MultiUNet
from .config import ModelConfig
from .inputs import PRIOR_GUIDES_WIDTH, ModelInputs, prior_guides
from .reconstruction import Reconstruction, demodulated, layer_gate

DEMODULATED = ("diffuse",)   # the layers a demodulating model divides by the albedo (inputs.modulation)
RANGE_LR_SCALE = 10.0        # lr_scale of the prior-range weights (ModelConfig.prior_range)


class RaNAD(nn.Module):
    def __init__(self, config: ModelConfig, in_dim: int, backend: str = "auto"):
        super().__init__()
        self.config = config
        c = config
        self.embed = nn.Sequential(nn.Linear(in_dim, c.dim), nn.ReLU(), nn.Linear(c.dim, c.dim))
        self.backbone = MultiUNet(c.dim, c.unets, c.levels, c.blocks_per_level, c.heads, c.head_dim, c.radius,
                                  c.radius_growth, backend, c.dropout_lattice)
        self.recon = nn.ModuleDict({name: Reconstruction(c.dim, r.scales, r.heads, r.head_dim, r.radius,
                                                         r.radius_growth, backend, c.dropout_lattice,
                                                         c.prior_range, c.alpha_residual and name == "alpha",
                                                         name in c.layer_gate)
                                    for name, r in c.recon.items()})
        unknown = set(c.layer_gate) - set(c.recon)
        if unknown:
            raise ValueError(f"config {c.name!r}: layer_gate names layers it does not reconstruct: {sorted(unknown)}")

    def lr_scale(self, name: str) -> float:
        """Learning-rate multiplier of parameter `name` (trainer.param_groups): the prior-range weights start at 0
        and are single numbers per head, which at the base rate would barely move in a fine-tune."""
        return RANGE_LR_SCALE if name.endswith(".range") else 1.0

    def embeddings(self, inputs: ModelInputs) -> torch.Tensor:
        """The backbone's per-bin embeddings (what the AOV reuse caches); a prior-range model's carry the bins' six
        prior guides behind them (inputs.prior_guides), so the cached kernels of `ranad aov` have them too."""
        emb = self.backbone(self.embed_features(inputs.features), inputs.layout)
        if self.config.prior_range:
            emb = torch.cat([emb, *prior_guides(inputs.features)], 1)
        return emb

    def embedding_width(self) -> int:
        """Width of `embeddings`' rows."""
        return self.config.dim + (PRIOR_GUIDES_WIDTH if self.config.prior_range else 0)

    def embed_features(self, x: torch.Tensor) -> torch.Tensor:
        """The input embedding of features [N, F] (the fused inference path where it applies, fused.py)."""
        return fused.relu_mlp(self.embed, x)

    def modulation(self, name: str, inputs: ModelInputs):
        """What layer `name`'s values are demodulated by for these inputs (None: not demodulated)."""
        return inputs.modulation if self.config.demodulate and name in DEMODULATED else None

    def reconstruct_layer(self, name: str, emb: torch.Tensor, inputs: ModelInputs, values: torch.Tensor):
        """Layer `name`'s reconstruction of `values` ([N, C], the noisy layer or AOVs batched) with embeddings
        `emb`: the one way every caller (denoise, AOVs, training) applies a reconstruction module."""
        guide = None
        if self.config.prior_range:   # the guides ride behind the embeddings (see embeddings)
            emb, guide = emb[:, :self.config.dim], tuple(emb[:, self.config.dim:].split(3, 1))
        guide = with_layer_gate(self.recon[name], guide, inputs)
        return demodulated(self.recon[name], emb, inputs.layout, values, self.modulation(name, inputs), guide)

    def reconstruct(self, emb: torch.Tensor, inputs: ModelInputs) -> dict:
        """Denoised layers: name -> [N, C] for every configured layer the inputs carry."""
        return {name: self.reconstruct_layer(name, emb, inputs, inputs.layers[name]) for name in self.recon
                if name in inputs.layers}

    def forward(self, inputs: ModelInputs) -> dict:
        return self.reconstruct(self.embeddings(inputs), inputs)


def with_layer_gate(rec: Reconstruction, guide, inputs: ModelInputs):
    """`guide` (None or (a, b)) with the layer gate's columns behind it when `rec` is gated (layer_gate of the
    inputs' depths): what Reconstruction.forward takes."""
    if not rec.gated:
        return guide
    if inputs.depth is None:
        raise ValueError("a gated reconstruction needs the bins' depths (ModelInputs.depth)")
    a, b = layer_gate(inputs.depth, inputs.layout)
    return (a, b) if guide is None else (torch.cat([guide[0], a], 1), torch.cat([guide[1], b], 1))
