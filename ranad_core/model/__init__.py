"""The RaNAD denoiser (paper Sec. 4): building blocks on ragged bins (layers.py) and the multi-scale kernel
reconstruction (reconstruction.py). The backbone, input processing and the config registry are being built
(issue 5)."""

from .layers import Layout, MultiHeadRaNA, RaNABlock, bin_dropout
from .reconstruction import KernelAttention, Reconstruction

__all__ = ["Layout", "MultiHeadRaNA", "RaNABlock", "bin_dropout", "KernelAttention", "Reconstruction"]
