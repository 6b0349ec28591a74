"""Which device the model runs on: `ranad denoise --device auto|cpu|cuda`.

The GPU path needs two things, each checked here so that a user gets one clear answer rather than a failure
mid-shot: a CUDA build of torch that sees a GPU, and the CUDA RaNA kernels built for it (without them the GPU
would run the plain-torch reference, which is slow and memory-hungry). `auto` takes the GPU when all of that
holds and says why not otherwise; `cuda` makes a missing piece an error.
"""

from __future__ import annotations

import warnings

from .errors import RanadError


def resolve(choice: str):
    """torch.device for `choice` ("auto", "cpu" or "cuda"); raises RanadError when "cuda" cannot be honoured."""
    import torch

    if choice == "cpu":
        return torch.device("cpu")
    if choice not in ("auto", "cuda"):
        raise RanadError(f"unknown device {choice!r} (auto, cpu or cuda)", "--device")
    if not torch.cuda.is_available():
        if choice == "cuda":
            raise RanadError("no CUDA GPU is visible to torch (a CPU-only torch build, or no driver)", "--device")
        return torch.device("cpu")
    from .rana.extension import BuildUnavailable, load_cuda_extension

    try:
        load_cuda_extension()
    except BuildUnavailable as e:
        if choice == "cuda":
            raise RanadError(f"the CUDA RaNA kernels cannot be used: {e}", "--device") from None
        warnings.warn(f"ranad: a GPU is present but the CUDA RaNA kernels are not ({e}); running on the CPU",
                      RuntimeWarning, stacklevel=2)
        return torch.device("cpu")
    return torch.device("cuda")
