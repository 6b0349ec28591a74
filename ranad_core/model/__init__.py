"""The RaNAD denoiser (paper Sec. 4): building blocks on ragged bins (layers.py), the multi-U-Net backbone
(backbone.py), the multi-scale kernel reconstruction (reconstruction.py), input processing (inputs.py), the
assembled single-frame model (ranad.py) and the registry of named configurations (config.py). Training,
evaluation and shipped weights are being built (issue 5)."""

from .backbone import MultiUNet, UNet
from .config import CONFIGS, ModelConfig, ReconConfig, get_config
from .layers import Layout, MultiHeadRaNA, RaNABlock, bin_dropout
from .inputs import ModelInputs, feature_dim, prepare
from .ranad import RaNAD
from .reconstruction import KernelAttention, Reconstruction

__all__ = ["Layout", "MultiHeadRaNA", "RaNABlock", "bin_dropout", "KernelAttention", "Reconstruction", "UNet",
           "MultiUNet", "CONFIGS", "ModelConfig", "ReconConfig", "get_config", "ModelInputs", "feature_dim", "prepare",
           "RaNAD"]
