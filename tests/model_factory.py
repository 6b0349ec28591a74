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
