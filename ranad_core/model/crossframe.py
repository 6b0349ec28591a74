"""Cross-frame RaNAD (paper Sec. 4.2): the centre frame denoised with its motion-compensated neighbours.

- Inputs: every frame of the window is prepared like a single frame, plus a one-hot of its offset from the
  centre (-3..+3), after motion compensation onto the centre frame (motion.py), so all frames share one grid.
- Backbone: the single-frame U-Nets run on every frame (frame-parallel, shared weights); after each U-Net a
  temporal-mix (T-Mix) RaNA block lets every bin attend to the bins of its pixel (within `temporal_radius`) in
  all frames of the window.
- Reconstruction: a temporal step (the centre frame's bins attend over the window's bins with the noisy values
  as values, a kernel like every other: linear in the noisy values), then the single-frame spatial multi-scale
  reconstruction on the centre frame.
- Output mix (configs with `output_mix`, not in the paper): every other frame of the window is reconstructed
  spatially too, and a last temporal kernel step mixes the centre's result with them, gated per bin. Consecutive
  centre frames then share most of what their outputs are averaged from, denoised, rather than only noisy inputs
  that the spatial kernels weigh differently in each window: this targets flicker directly. Still a kernel over
  noisy values (linear in them), so AOVs reuse it.

With `temporal_keys="inputs"` (configs *-xk) or `"match"` (configs *-xm and, guarded, *-xg; matching.py: the
temporal step scores each candidate bin by an MLP of its difference from the query rather than a dot product) there
are no T-Mix blocks: only the centre frame runs the backbone, so its features, and with a frozen spatial part its
whole spatial reconstruction, are the single-frame model's whatever the neighbours hold, and the temporal step's
keys are a small MLP of each window bin's own inputs (colour, prior, guides, depth, frame offset): enough to tell
whether a neighbour's bin shows the same surface, at the cost of one backbone pass per window instead of one per
frame.

A window of one frame skips the T-Mix blocks and the temporal step, so a cross-frame model with one frame is the
single-frame model it was initialised from (`from_single`): the new one-hot inputs start with zero weights and
the T-Mix output projections start at zero (identity blocks).
"""

from __future__ import annotations

import torch
from torch import nn

from ..rana import concat_frames
from . import fused
from .config import ModelConfig
from .inputs import GUIDE_WIDTH, ModelInputs, concat_columns, guides
from .layers import Layout, MultiHeadRaNA
from .matching import MatchKernel, consistent, pixel_pairs
from .ranad import RaNAD, with_layer_gate
from .reconstruction import KernelAttention, per_channel

MAX_OFFSET = 3                       # frames -3..+3 around the centre (windows up to 7)
FRAME_FEATURES = 2 * MAX_OFFSET + 1

# Learning-rate multipliers (by parameter-name prefix) for the parts that start as identities: the T-Mix
# output projections at zero, the temporal gate nearly closed. AdamW moves a parameter by about the learning
# rate per step whatever its gradient, so at the base rate a gate logit starting at -4 hardly moves
# (cpu-small-xf-v1's first 2500 steps moved it by at most 0.06) and the model stays the single-frame one.
LR_SCALE = {"temporal_gate.": 10.0, "tmix.": 3.0, "temporal.": 3.0, "temporal_embed.": 3.0, "mix_gate.": 10.0,
            "mix.": 3.0}
TEMPORAL_KEYS = ("backbone", "inputs", "match")


def temporal_layout(layouts: list) -> tuple[Layout, torch.Tensor, torch.Tensor]:
    """(the window's bins per pixel frame after frame as one key layout, gather rows into cat(frames), the frame of
    each key row)."""
    offsets, gather, frame = concat_frames([l.offsets for l in layouts])
    return Layout.of(offsets, layouts[0].height, layouts[0].width), gather, frame


def with_frame_id(inputs: ModelInputs, offset: int) -> torch.Tensor:
    onehot = inputs.features.new_zeros(inputs.features.shape[0], FRAME_FEATURES)
    onehot[:, offset + MAX_OFFSET] = 1
    return concat_columns([inputs.features, onehot])


class TemporalMix(nn.Module):
    """T-Mix: pre-norm multi-head RaNA from every bin to the window's bins at (and around) its pixel."""

    def __init__(self, dim: int, heads: int, head_dim: int, radius: float, backend: str = "auto"):
        super().__init__()
        self.norm = nn.LayerNorm(dim)
        self.attn = MultiHeadRaNA(dim, dim, dim, heads, head_dim, radius, backend)
        nn.init.zeros_(self.attn.out.weight)
        nn.init.zeros_(self.attn.out.bias)

    def forward(self, feats: list, layouts: list, keys: Layout, gather: torch.Tensor) -> list:
        allf = torch.cat(feats)
        x = self.norm(allf)
        q_pixels = torch.cat([l.pixels for l in layouts])
        out = allf + self.attn(x, x[gather], q_pixels, keys)
        return list(torch.split(out, [f.shape[0] for f in feats]))


class CrossFrameRaNAD(nn.Module):
    def __init__(self, config: ModelConfig, in_dim: int, backend: str = "auto"):
        super().__init__()
        if config.prior_range or config.alpha_residual:
            raise ValueError(f"config {config.name!r}: the prior-range and alpha-residual reconstructions have no "
                             f"cross-frame model yet")
        self.config = config
        self.single = RaNAD(config, in_dim + FRAME_FEATURES, backend)
        c = config
        self.input_keys = c.temporal_keys in ("inputs", "match")
        self.matching = c.temporal_keys == "match"
        if c.temporal_keys not in TEMPORAL_KEYS or (self.input_keys and c.output_mix) \
                or (self.matching and c.temporal_radius != 0) or (c.temporal_guard and not self.matching):
            raise ValueError(f"config {c.name!r}: temporal_keys {c.temporal_keys!r} (one of {TEMPORAL_KEYS}; "
                             f"input keys have no per-frame features for an output mix; 'match' has radius 0 and "
                             f"is the only one with a guard)")
        self.tmix = nn.ModuleList(TemporalMix(c.dim, c.heads, c.head_dim, c.temporal_radius, backend)
                                  for _ in range(0 if self.input_keys else c.unets))
        if self.input_keys:
            self.temporal_embed = nn.Sequential(nn.Linear(in_dim + FRAME_FEATURES, c.dim), nn.ReLU(),
                                                nn.Linear(c.dim, c.dim))
        self.temporal = nn.ModuleDict({name: MatchKernel(c.dim) if self.matching else
                                       KernelAttention(c.dim, r.heads, r.head_dim, c.temporal_radius, backend)
                                       for name, r in c.recon.items()})
        # per-bin share of the temporal result (a function of the features only, so the output stays linear in
        # the values); starts near 0: training begins from the single-frame behaviour
        self.temporal_gate = nn.ModuleDict({name: nn.Linear(c.dim, 1) for name in c.recon})
        if c.output_mix:
            self.mix = nn.ModuleDict({name: KernelAttention(c.dim, r.heads, r.head_dim, c.temporal_radius, backend)
                                      for name, r in c.recon.items()})
            self.mix_gate = nn.ModuleDict({name: nn.Linear(c.dim, 1) for name in c.recon})
        for g in [*self.temporal_gate.values(), *(self.mix_gate.values() if c.output_mix else ())]:
            nn.init.zeros_(g.weight)
            nn.init.constant_(g.bias, -4.0)
        if self.matching:   # open: the matching step starts mostly as the identity itself (matching.SELF_BONUS)
            for g in self.temporal_gate.values():
                nn.init.constant_(g.bias, 4.0)

    @classmethod
    def from_single(cls, single: RaNAD, config: ModelConfig, in_dim: int) -> "CrossFrameRaNAD":
        """A cross-frame model that starts as `single` (its weights copied, the frame one-hot weights zero)."""
        model = cls(config, in_dim)
        state = single.state_dict()
        w = state["embed.0.weight"]
        state["embed.0.weight"] = torch.cat([w, w.new_zeros(w.shape[0], FRAME_FEATURES)], 1)
        model.single.load_state_dict(state)
        return model

    @classmethod
    def from_cross(cls, other: "CrossFrameRaNAD", config: ModelConfig, in_dim: int) -> "CrossFrameRaNAD":
        """A cross-frame model for `config` that starts as `other` (a cross-frame model of the same backbone
        without the output mix): its weights copied, the output mix's gates nearly closed."""
        model = cls(config, in_dim)
        missing, unexpected = model.load_state_dict(other.state_dict(), strict=False)
        extra = [k for k in missing if not k.startswith(("mix.", "mix_gate."))]
        if extra or unexpected:
            raise ValueError(f"weights do not fit config {config.name!r}: missing {extra[:3]}, unexpected "
                             f"{unexpected[:3]}")
        return model

    def lr_scale(self, name: str) -> float:
        """Learning-rate multiplier of parameter `name` (see LR_SCALE)."""
        return next((m for prefix, m in LR_SCALE.items() if name.startswith(prefix)), 1.0)

    def embeddings(self, frames: list, centre: int) -> list:
        """Per-frame embeddings of the window (inputs of every frame on the centre frame's grid): the backbone's
        for every frame, or with input keys the temporal keys for every frame and, for the centre, its backbone
        features in front of its keys ([N, 2 dim]). What the AOV cache keeps."""
        if self.input_keys:
            c = frames[centre]
            own = self.single.backbone(self.single.embed_features(with_frame_id(c, 0)), c.layout)
            if len(frames) == 1:
                return [own]
            feats = [fused.relu_mlp(self.temporal_embed, with_frame_id(f, i - centre)) for i, f in enumerate(frames)]
            if self.config.temporal_guard:   # the guides travel in the embeddings, so the AOV cache keeps them
                feats = [torch.cat([e, guides(f.features, self.config.features)], 1) for e, f in zip(feats, frames)]
            feats[centre] = torch.cat([own, feats[centre]], 1)
            return feats
        layouts = [f.layout for f in frames]
        feats = [self.single.embed_features(with_frame_id(f, i - centre)) for i, f in enumerate(frames)]
        keys, gather, _ = temporal_layout(layouts) if len(frames) > 1 else (None, None, None)
        for k, unet in enumerate(self.single.backbone.unets):
            feats = [unet(f, l) for f, l in zip(feats, layouts)]
            if len(frames) > 1:
                feats = self.tmix[k](feats, layouts, keys, gather)
        return feats

    def embedding_width(self, is_centre: bool, frames: int) -> int:
        """Width of a window frame's embedding (see embeddings): the centre's [backbone | keys] with input keys in
        a window of several frames, the model's dim otherwise; plus the guides (temporal_guard, several frames)."""
        guard = GUIDE_WIDTH if self.config.temporal_guard and frames > 1 else 0
        return (2 * self.config.dim if self.input_keys and is_centre and frames > 1 else self.config.dim) + guard

    def _match_args(self, feats: list, frames: list, centre: int, keys: Layout, gather: torch.Tensor,
                    frame: torch.Tensor) -> dict:
        """The matching step's arguments shared by every layer: each centre bin's own row among the keys, the
        pairs that take part (with the guard only the bin itself and neighbours' bins whose guides agree; other bins
        of the centre frame, which are other surfaces of the pixel, never: pairs left out rather than masked, so
        the pair scores run on few), and the keys without their guides ("feats")."""
        c = frames[centre]
        rows = torch.empty_like(gather)
        rows[gather] = torch.arange(gather.numel(), device=gather.device)
        first = sum(f.layout.bins for f in frames[:centre])
        own_rows = rows[first:first + c.layout.bins]
        pairs = pixel_pairs(c.layout.pixels, keys)
        out = {"own": own_rows, "pairs": pairs, "feats": feats}
        if self.config.temporal_guard:
            frame_guides = torch.cat([f[:, -GUIDE_WIDTH:] for f in feats])   # key row r's are row gather[r]'s
            out["feats"] = [f[:, :-GUIDE_WIDTH] for f in feats]
            qi, kj = pairs
            ok = kj == own_rows[qi]
            # the guides compared only on the neighbours' pairs, about half of a pixel's pairs (centre bin i's own
            # key row holds row first + i of the frames' guides)
            other = torch.nonzero(frame[kj] != centre).squeeze(1)
            ok[other] |= consistent(frame_guides[qi[other] + first], frame_guides[gather[kj[other]]])
            out["pairs"] = (qi[ok], kj[ok])
        return out

    def reconstruct(self, feats: list, frames: list, centre: int, values: dict | None = None) -> dict:
        """Denoised layers of the centre frame; `values` (name -> per-frame [N_f, C] list) replaces the noisy
        layers, which is how AOVs reuse the kernels."""
        c = frames[centre]
        out = {}
        keys, gather, frame = temporal_layout([f.layout for f in frames]) if len(frames) > 1 else (None, None, None)
        if self.input_keys and len(frames) > 1:   # split the centre's [backbone | keys] (see embeddings)
            dim = self.config.dim
            feats = list(feats)
            # each part made contiguous once: as column views, every fused layer that reads them copied them again
            # (0.4 s of bench/shot.py's 5-frame 480x270 shot)
            own, feats[centre] = feats[centre][:, :dim].contiguous(), feats[centre][:, dim:].contiguous()
        else:
            own = feats[centre]
        match = {}
        if self.matching and len(frames) > 1:
            match = self._match_args(feats, frames, centre, keys, gather, frame)
            feats = match.pop("feats")
        # the window's keys, shared by every layer (index_select: torch's row gather, a third faster than indexing)
        allf = torch.index_select(torch.cat(feats), 0, gather) if len(frames) > 1 else None
        for name, rec in self.single.recon.items():
            if name not in c.layers:
                continue
            vals = values[name] if values is not None else [f.layers[name] for f in frames]
            # a demodulating model works on every frame's values divided by that frame's modulation and multiplies
            # the result by the centre's (reconstruction.demodulated)
            mods = [self.single.modulation(name, f) for f in frames]
            if mods[centre] is not None:
                mods = [v.new_ones(v.shape[0], 3) if m is None else m for m, v in zip(mods, vals)]
                vals = [v / per_channel(m, v) for v, m in zip(vals, mods)]
            v = vals[centre]
            if len(frames) > 1:
                allv = torch.index_select(torch.cat(vals), 0, gather)
                # the matching step compares the centre's own keys with the window's; the others query with the
                # backbone features
                query = feats[centre] if self.matching else own
                t = self.temporal[name](query, allf, c.layout.pixels, keys, allv, **match)
                g = torch.sigmoid(self.temporal_gate[name](own))
                v = v + g * (t - v)
            out[name] = rec(own, c.layout, v, with_layer_gate(rec, None, c))
            if self.config.output_mix and len(frames) > 1:
                spatial = [out[name] if i == centre else
                           rec(feats[i], f.layout, vals[i], with_layer_gate(rec, None, f))
                           for i, f in enumerate(frames)]
                m = self.mix[name](feats[centre], allf, c.layout.pixels, keys, torch.cat(spatial)[gather])
                g = torch.sigmoid(self.mix_gate[name](feats[centre]))
                out[name] = out[name] + g * (m - out[name])
            if mods[centre] is not None:
                out[name] = out[name] * per_channel(mods[centre], out[name])
        return out

    def forward(self, frames: list, centre: int) -> dict:
        return self.reconstruct(self.embeddings(frames, centre), frames, centre)
