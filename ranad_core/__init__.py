"""ranad core: deep EXR I/O, the ragged DeepImage container, and (later) the RaNAD denoiser."""

__version__ = "0.1.0"
