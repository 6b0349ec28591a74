"""The single-frame RaNAD model (paper Fig. 6): input embedding, multi-U-Net backbone, one reconstruction module
per output layer. Every output is a softmax-weighted combination of that layer's noisy values (linear in them).
"""

from __future__ import annotations

import torch
from torch import nn

from .backbone import MultiUNet
from .config import ModelConfig
from .inputs import ModelInputs
from .reconstruction import Reconstruction


class RaNAD(nn.Module):
    def __init__(self, config: ModelConfig, in_dim: int, backend: str = "auto"):
        super().__init__()
        self.config = config
        c = config
        self.embed = nn.Sequential(nn.Linear(in_dim, c.dim), nn.ReLU(), nn.Linear(c.dim, c.dim))
        self.backbone = MultiUNet(c.dim, c.unets, c.levels, c.blocks_per_level, c.heads, c.head_dim, c.radius,
                                  c.radius_growth, backend)
        self.recon = nn.ModuleDict({name: Reconstruction(c.dim, r.scales, r.heads, r.head_dim, r.radius,
                                                         r.radius_growth, backend)
                                    for name, r in c.recon.items()})

    def embeddings(self, inputs: ModelInputs) -> torch.Tensor:
        """The backbone's per-bin embeddings (what the AOV reuse caches)."""
        return self.backbone(self.embed(inputs.features), inputs.layout)

    def forward(self, inputs: ModelInputs) -> dict:
        """Denoised layers: name -> [N, C] for every configured layer the inputs carry."""
        emb = self.embeddings(inputs)
        return {name: mod(emb, inputs.layout, inputs.layers[name]) for name, mod in self.recon.items()
                if name in inputs.layers}
