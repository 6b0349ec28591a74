"""Named model configurations (a registry, as timm's): a CPU-sized default and the paper's size.

`ranad train --config NAME` and the model cards refer to these names; a checkpoint stores its config so that
weights always load into the architecture they were trained with.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field


@dataclass(frozen=True)
class ReconConfig:
    scales: int = 3
    heads: int = 2
    head_dim: int = 8
    radius: float = 2.5
    radius_growth: float = 1.0


@dataclass(frozen=True)
class ModelConfig:
    name: str
    dim: int                     # embedding width of the backbone
    unets: int                   # U-Nets in the multi-U-Net chain
    levels: int                  # down-sampling steps per U-Net
    blocks_per_level: int        # RaNA blocks per encoder/decoder stage
    heads: int
    head_dim: int
    radius: float                # RaNA radius at full resolution
    radius_growth: float         # added per coarser level
    recon: dict = field(default_factory=dict)  # output layer -> ReconConfig (diffuse, specular, alpha, depth)
    window: int = 1              # frames the model sees (1: single-frame; >1: cross-frame, up to this many)
    temporal_radius: float = 1.0  # radius of the T-Mix blocks and the temporal reconstruction step
    output_mix: bool = False      # cross-frame: a temporal step over the window's spatially denoised frames at the end
    features: str = "log1p"       # input feature set (inputs.FEATURE_SETS): "prior" = exposure-normalised + flat prior
    # cross-frame: what the temporal step's keys are made of. "backbone": every frame's U-Net features, mixed by
    # T-Mix blocks; "inputs": a small MLP of each bin's own inputs (no T-Mix), so only the centre frame runs the
    # backbone and its features are the single-frame model's, untouched by the neighbours (crossframe.py); "match":
    # as "inputs", with candidates scored by an MLP of their difference from the query (matching.py)
    temporal_keys: str = "backbone"
    # divide the diffuse layer by its albedo guide before the kernels and multiply back after (reconstruction.py)
    demodulate: bool = False
    # matching temporal step: neighbours' bins take part only where their guides agree with the bin's (matching.GUARD)
    temporal_guard: bool = False
    # bin dropout on a quincunx pyramid (layers.bin_dropout): every down-sampling level keeps half the bins, single-bin
    # pixels included; False (the first models) empties the second level of single-bin pixels
    dropout_lattice: bool = False
    # reconstruction kernels with a learned range term per head: -lambda |prior(query pixel) - noisy flat(key
    # pixel)|^2 added to the logits (reconstruction.KernelAttention), so the kernels can pick the noisy neighbours
    # that agree with OIDN's flat estimate while the output stays a combination of noisy values; lambda starts at 0
    prior_range: bool = False
    # alpha's reconstruction plus a learned per-bin correction from the bin's embedding (Reconstruction.residual),
    # zero at start: deep-Z bins made of few samples carry an alpha biased high behind the first bin (a bin exists
    # only where a sample stopped), shared by all neighbours, so no kernel removes it (runs/edit-oracles-s12)
    alpha_residual: bool = False
    # output layers whose reconstruction kernels keep to the bins' own depth layers (reconstruction.layer_gate): a
    # query bin of a pixel with several bins reads only keys near its depth, and a key bin of such a pixel is read
    # only by queries near its depth. Parameter-free; images of single-bin pixels are untouched. Stacks of parallel
    # semi-transparent layers, a family no training set held, got depths 2-5x worse than the noisy input's without it
    layer_gate: tuple = ()

    def to_dict(self) -> dict:
        d = asdict(self)
        d["recon"] = {k: asdict(v) for k, v in self.recon.items()}
        d["layer_gate"] = list(self.layer_gate)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "ModelConfig":
        d = dict(d)
        d["recon"] = {k: ReconConfig(**v) for k, v in d.get("recon", {}).items()}
        d["layer_gate"] = tuple(d.get("layer_gate", ()))
        return cls(**d)


def _recon(**over) -> dict:
    base = {"diffuse": ReconConfig(), "specular": ReconConfig(scales=2, radius=2.0), "alpha": ReconConfig(scales=2),
            "depth": ReconConfig(scales=2, radius=1.5)}
    return {k: ReconConfig(**{**asdict(v), **over.get(k, {})}) for k, v in base.items()}


CONFIGS = {
    # trains in hours on 2 CPU cores: 2 U-Nets of 2 levels, 32-wide embeddings, 4 heads of 8
    "cpu-small": ModelConfig("cpu-small", dim=32, unets=2, levels=2, blocks_per_level=1, heads=4, head_dim=8,
                             radius=2.5, radius_growth=1.0, recon=_recon()),
    # the paper's size (GPU training)
    "paper": ModelConfig("paper", dim=64, unets=3, levels=3, blocks_per_level=2, heads=4, head_dim=16,
                         radius=3.5, radius_growth=1.0,
                         recon=_recon(diffuse={"scales": 4, "radius": 3.5}, specular={"scales": 3})),
}


CONFIGS["cpu-small-xf"] = ModelConfig(**{**CONFIGS["cpu-small"].__dict__, "name": "cpu-small-xf", "window": 7,
                                        "temporal_radius": 1.0})
# cpu-small-xf plus the output mix (crossframe.py): every frame of the window reconstructed, then mixed in time
CONFIGS["cpu-small-xfm"] = ModelConfig(**{**CONFIGS["cpu-small-xf"].__dict__, "name": "cpu-small-xfm",
                                         "output_mix": True})


# cpu-small reading exposure-normalised radiance and OIDN's flat prior (inputs.py, prior.py); issue 24
CONFIGS["cpu-small-p"] = ModelConfig(**{**CONFIGS["cpu-small"].__dict__, "name": "cpu-small-p", "features": "prior"})
CONFIGS["cpu-small-p-xf"] = ModelConfig(**{**CONFIGS["cpu-small-xf"].__dict__, "name": "cpu-small-p-xf",
                                          "features": "prior"})


# the cross-frame model whose neighbours only enter through the temporal step, keyed by their inputs: a window
# costs one backbone pass (the centre's) plus a cheap embedding of the neighbours' bins; issues 25, 27
CONFIGS["cpu-small-p-xk"] = ModelConfig(**{**CONFIGS["cpu-small-p-xf"].__dict__, "name": "cpu-small-p-xk",
                                          "temporal_keys": "inputs"})

# cpu-small-p-xk whose temporal step only gathers the bins at the bin's own (motion-compensated) pixel in each
# frame: a radius of 1 also blurred the centre frame spatially before the spatial reconstruction (issue 25)
CONFIGS["cpu-small-p-xk0"] = ModelConfig(**{**CONFIGS["cpu-small-p-xk"].__dict__, "name": "cpu-small-p-xk0",
                                           "temporal_radius": 0.0})

# cpu-small-p with albedo demodulation of the diffuse layer: textures the albedo guide shows are not averaged away
# (issue 24)
CONFIGS["cpu-small-pd"] = ModelConfig(**{**CONFIGS["cpu-small-p"].__dict__, "name": "cpu-small-pd",
                                        "demodulate": True})

# cpu-small-pd whose alpha reconstruction has the diffuse layer's three scales (two before): a wider support for
# the per-bin alpha, whose binomial noise the held-out compositing edit is most sensitive to (issue 24)
CONFIGS["cpu-small-pd3a"] = ModelConfig(**{**CONFIGS["cpu-small-pd"].__dict__, "name": "cpu-small-pd3a",
                                          "recon": _recon(alpha={"scales": 3})})

# the input-keyed cross-frame model (radius-0 temporal step, as cpu-small-p-xk0) on cpu-small-pd
CONFIGS["cpu-small-pd-xk"] = ModelConfig(**{**CONFIGS["cpu-small-p-xk0"].__dict__, "name": "cpu-small-pd-xk",
                                           "demodulate": True})

# cpu-small-pd-xk whose radius-0 temporal step scores each candidate bin by a small MLP of its embedding's
# difference from the query's (matching.py) rather than a dot product: misaligned bins can be told apart (issue 25)
CONFIGS["cpu-small-pd-xm"] = ModelConfig(**{**CONFIGS["cpu-small-pd-xk"].__dict__, "name": "cpu-small-pd-xm",
                                           "temporal_keys": "match"})

# cpu-small-pd-xm with the guard: a neighbour's bin counts only where depth, albedo, normal and flat prior agree
# with the bin's, rules that hold on scene families the scores never saw (issue 25)
CONFIGS["cpu-small-pd-xg"] = ModelConfig(**{**CONFIGS["cpu-small-pd-xm"].__dict__, "name": "cpu-small-pd-xg",
                                           "temporal_guard": True})


# cpu-small-pd whose U-Nets' second level and reconstructions' third scale keep single-bin pixels (a lattice
# twice as sparse as the first level's, where the first dropout left none): on the single-bin pixels that make
# most of a frame, the coarsest level has bins to attend to (issue 24)
CONFIGS["cpu-small-pdl"] = ModelConfig(**{**CONFIGS["cpu-small-pd"].__dict__, "name": "cpu-small-pdl",
                                         "dropout_lattice": True})


# cpu-small-pd with the prior-range term in its reconstruction kernels; starts from cpu-small-pd weights exactly
# (every range weight 0) (issue 24: the glass scenes, whose single-bin colour the guides do not explain)
CONFIGS["cpu-small-pdr"] = ModelConfig(**{**CONFIGS["cpu-small-pd"].__dict__, "name": "cpu-small-pdr",
                                         "prior_range": True})


# cpu-small-pd with the alpha residual (ModelConfig.alpha_residual); starts from cpu-small-pd weights exactly
CONFIGS["cpu-small-pda"] = ModelConfig(**{**CONFIGS["cpu-small-pd"].__dict__, "name": "cpu-small-pda",
                                         "alpha_residual": True})


# the sequence model on cpu-small-pdl: cpu-small-pd-xg's temporal step over the lattice-dropout spatial model
CONFIGS["cpu-small-pdl-xg"] = ModelConfig(**{**CONFIGS["cpu-small-pd-xg"].__dict__, "name": "cpu-small-pdl-xg",
                                            "dropout_lattice": True})


# cpu-small-pdl whose depth reconstruction keeps to the bins' own depth layers (reconstruction.layer_gate): stacks
# of semi-transparent layers, a family no training set holds, got depths 2-5x worse than the noisy input's (issue 24)
CONFIGS["cpu-small-pdl-gz"] = ModelConfig(**{**CONFIGS["cpu-small-pdl"].__dict__, "name": "cpu-small-pdl-gz",
                                            "layer_gate": ("depth",)})
# ... and its alpha reconstruction too
CONFIGS["cpu-small-pdl-gza"] = ModelConfig(**{**CONFIGS["cpu-small-pdl"].__dict__, "name": "cpu-small-pdl-gza",
                                             "layer_gate": ("depth", "alpha")})
# ... and every layer (colour too; measured, not trained: runs/layer-gate-s14)
CONFIGS["cpu-small-pdl-gall"] = ModelConfig(**{**CONFIGS["cpu-small-pdl"].__dict__, "name": "cpu-small-pdl-gall",
                                              "layer_gate": ("diffuse", "specular", "alpha", "depth")})

# the sequence model on cpu-small-pdl-gza: cpu-small-pdl-xg with the spatial model's layer gate
CONFIGS["cpu-small-pdl-gza-xg"] = ModelConfig(**{**CONFIGS["cpu-small-pdl-xg"].__dict__, "name": "cpu-small-pdl-gza-xg",
                                                "layer_gate": ("depth", "alpha")})

# cpu-small-pdl-gza whose diffuse reconstruction has a fourth scale (radius 5.5 on a lattice of 1 bin in 8), for the
# low-frequency noise v7 left in smooth regions of box-filtered held-out interiors. Measured, not shipped: every
# held-out figure within 0.4% of the same fine-tune without it (runs/generalization-s28, section 2)
CONFIGS["cpu-small-pdl-gza-d4"] = ModelConfig(**{**CONFIGS["cpu-small-pdl-gza"].__dict__,
                                               "name": "cpu-small-pdl-gza-d4", "recon": _recon(diffuse={"scales": 4})})

# cpu-small-pdl-gza with one U-Net: the backbone is about 40% of a frame's time and the second U-Net half of it
# (issue 27); started from a two-U-Net model's first U-Net (train.trainer.init_single) and fine-tuned. Measured, not
# shipped: 0.73x the time of the two-U-Net default on the 1080p bench frame, 7-16% worse on held-out sets
# (runs/generalization-s21, section 2)
CONFIGS["cpu-small-pdl-gza-u1"] = ModelConfig(**{**CONFIGS["cpu-small-pdl-gza"].__dict__,
                                                "name": "cpu-small-pdl-gza-u1", "unets": 1})

# cpu-small-pdl-gza with a third U-Net, the other way of issue 24's item 6 (capacity): grown from a two-U-Net model
# with the new U-Net starting as the identity (runs/generalization-s30/grow_unet.py) and fine-tuned. Measured, not
# shipped: within 0.5% of the same fine-tune of the two-U-Net model (runs/generalization-s30, section 5)
CONFIGS["cpu-small-pdl-gza-u3"] = ModelConfig(**{**CONFIGS["cpu-small-pdl-gza"].__dict__,
                                                "name": "cpu-small-pdl-gza-u3", "unets": 3})


def get_config(name: str) -> ModelConfig:
    try:
        return CONFIGS[name]
    except KeyError:
        raise ValueError(f"unknown model config {name!r} (known: {', '.join(sorted(CONFIGS))})") from None
