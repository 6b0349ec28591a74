"""Small model configurations the tests build models from (not in the registry: no model ships with them)."""

from ranad_core.model import get_config
from ranad_core.model.config import ModelConfig


def input_keys_config() -> ModelConfig:
    """cpu-small-xf with the temporal step keyed by the bins' inputs (the *-xk configs, on log1p features)."""
    return ModelConfig(**{**get_config("cpu-small-xf").__dict__, "name": "xk", "temporal_keys": "inputs"})


def demodulating(config: ModelConfig) -> ModelConfig:
    """`config` with albedo demodulation of the diffuse layer (reconstruction.demodulated)."""
    return ModelConfig(**{**config.__dict__, "name": config.name + "-d", "demodulate": True})


def matching_config(guard: bool = False) -> ModelConfig:
    """cpu-small-xf with the matching temporal step (the *-xm configs; *-xg with the guard), on log1p features."""
    return ModelConfig(**{**get_config("cpu-small-xf").__dict__, "name": "xg" if guard else "xm",
                          "temporal_keys": "match", "temporal_radius": 0.0, "temporal_guard": guard})


def depth_kernel(config: ModelConfig) -> ModelConfig:
    """`config` with the reconstruction's depth term (the *-pdz configs, reconstruction.KernelAttention)."""
    return ModelConfig(**{**config.__dict__, "name": config.name + "-z", "depth_kernel": True})


def open_depth_term(model, w: float = 300.0):
    """Sets every depth term of `model` to weight w (a strong term, so tests see it work)."""
    import math

    from ranad_core.model.reconstruction import DEPTH_GAIN, DEPTH_W0

    for name, p in model.named_parameters():
        if name.endswith("depth_theta"):
            p.data.fill_((math.log(w) - DEPTH_W0) / DEPTH_GAIN)
    return model
