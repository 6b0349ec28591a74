"""Build and load the C++ RaNA kernels (``cuda/rana_cpu*.cpp``) with torch's JIT extension builder.

Built on first use and cached by torch (``$TORCH_EXTENSIONS_DIR``, default ``~/.cache/torch_extensions``),
so later runs load in milliseconds. The build is tuned for the CPU it runs on (``-march=native``); the
extension name carries a hash of the CPU's feature flags so that a cache shared between different
machines (a render farm's home directory) never hands a binary to a CPU that cannot run it.
When no compiler is available or the build fails, a warning says so once and callers use the reference.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import warnings
from functools import lru_cache
from pathlib import Path

SOURCE_DIR = Path(__file__).resolve().parents[2] / "cuda"
# the bindings, and the kernel instantiations split so that the build runs them in parallel
CPU_SOURCES = ("rana_cpu.cpp", "rana_cpu_f32_hb4.cpp", "rana_cpu_f32_hb1.cpp", "rana_cpu_other.cpp")
CPU_HEADERS = ("rana_math.h", "rana_cpu_kernels.h")


def _cpu_tag() -> str:
    flags = ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("flags"):
                    flags = line
                    break
    except OSError:
        pass
    import platform

    return hashlib.sha1((platform.machine() + flags).encode()).hexdigest()[:10]


def _sources_digest() -> str:
    h = hashlib.sha1()
    for name in CPU_SOURCES + CPU_HEADERS:
        h.update((SOURCE_DIR / name).read_bytes())
    return h.hexdigest()[:10]


class BuildUnavailable(RuntimeError):
    """The C++ kernels cannot be built or loaded here (no compiler, no sources, or a failed build)."""


@lru_cache(maxsize=None)
def load_cpu_extension():
    """The compiled module (``forward``/``backward``), building it if needed; raises BuildUnavailable."""
    if os.environ.get("RANAD_NO_EXTENSION"):
        raise BuildUnavailable("disabled by RANAD_NO_EXTENSION")
    missing = [n for n in CPU_SOURCES + CPU_HEADERS if not (SOURCE_DIR / n).is_file()]
    if missing:
        raise BuildUnavailable(f"kernel sources not found in {SOURCE_DIR} ({', '.join(missing)})")
    if not (shutil.which(os.environ.get("CXX", "c++")) or shutil.which("g++")):
        raise BuildUnavailable("no C++ compiler on PATH (install g++ or set CXX)")
    from torch.utils.cpp_extension import load

    flags = ["-O3", "-std=c++20", "-fopenmp", "-march=native", "-fno-math-errno", "-fno-trapping-math"]
    try:
        return load(name=f"ranad_rana_cpu_{_cpu_tag()}_{_sources_digest()}",
                    sources=[str(SOURCE_DIR / n) for n in CPU_SOURCES], extra_cflags=flags,
                    extra_include_paths=[str(SOURCE_DIR)], extra_ldflags=["-fopenmp"], verbose=False)
    except Exception as e:  # noqa: BLE001 - any build failure means: use the reference
        lines = str(e).strip().splitlines() or ["unknown error"]
        first_error = next((ln for ln in lines if "error" in ln.lower()), lines[-1])
        raise BuildUnavailable(f"building the C++ RaNA kernels failed: {first_error.strip()}") from e


@lru_cache(maxsize=None)
def cpu_extension_or_none():
    """The compiled module, or None after warning once why the slow reference path will be used."""
    try:
        return load_cpu_extension()
    except BuildUnavailable as e:
        warnings.warn(f"ranad: C++ RaNA kernels unavailable ({e}); using the slow torch reference",
                      RuntimeWarning, stacklevel=3)
        return None


# ---- CUDA ---------------------------------------------------------------------------------------------------
CUDA_SOURCES = ("rana_cuda.cpp", "rana_cuda_kernels.cu")
CUDA_HEADERS = ("rana_math.h", "rana_binding.h", "rana_cuda_kernels.h")
CUDA_ARCHS = ("80", "86", "89", "90")   # what CI compiles for (cuda/check_build.sh)


@lru_cache(maxsize=None)
def load_cuda_extension():
    """The CUDA kernels' module (``forward``/``backward`` taking the stream as an integer), built with nvcc by
    torch's JIT builder for the GPU present; raises BuildUnavailable without CUDA torch, a GPU or nvcc."""
    import torch

    if os.environ.get("RANAD_NO_EXTENSION"):
        raise BuildUnavailable("disabled by RANAD_NO_EXTENSION")
    if not torch.cuda.is_available():
        raise BuildUnavailable("no CUDA device (or a CPU-only build of torch)")
    missing = [n for n in CUDA_SOURCES + CUDA_HEADERS if not (SOURCE_DIR / n).is_file()]
    if missing:
        raise BuildUnavailable(f"kernel sources not found in {SOURCE_DIR} ({', '.join(missing)})")
    from torch.utils.cpp_extension import load

    h = hashlib.sha1()
    for name in CUDA_SOURCES + CUDA_HEADERS:
        h.update((SOURCE_DIR / name).read_bytes())
    try:
        return load(name=f"ranad_rana_cuda_{h.hexdigest()[:10]}", sources=[str(SOURCE_DIR / n) for n in CUDA_SOURCES],
                    extra_cflags=["-O3", "-std=c++20"],
                    extra_cuda_cflags=["-O3", "-std=c++20", "-Xptxas", "-warn-spills", "--expt-relaxed-constexpr"],
                    extra_include_paths=[str(SOURCE_DIR)], verbose=False)
    except Exception as e:  # noqa: BLE001
        lines = str(e).strip().splitlines() or ["unknown error"]
        first_error = next((ln for ln in lines if "error" in ln.lower()), lines[-1])
        raise BuildUnavailable(f"building the CUDA RaNA kernels failed: {first_error.strip()}") from e


@lru_cache(maxsize=None)
def cuda_extension_or_none():
    """The CUDA module, or None after warning once why the reference will run on the GPU instead."""
    try:
        return load_cuda_extension()
    except BuildUnavailable as e:
        warnings.warn(f"ranad: CUDA RaNA kernels unavailable ({e}); using the torch reference on the GPU",
                      RuntimeWarning, stacklevel=3)
        return None
