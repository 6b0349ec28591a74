"""Build and load the C++ RaNA kernels (``cuda/rana_cpu*.cpp``) with torch's JIT extension builder.

Built on first use (with a message on stderr: it takes a minute or two) and cached, so later runs load in
milliseconds. The cache folder is ``$RANAD_KERNEL_CACHE`` when set (a folder a render farm shares), else torch's
(``$TORCH_EXTENSIONS_DIR``, default ``~/.cache/torch_extensions``). The build is tuned for the CPU it runs on
(``-march=native``); the extension name carries a hash of the CPU's feature flags and of the sources, so a shared
cache holds one build per CPU type and version and never hands a binary to a CPU that cannot run it. The build
key holds no paths, so installs in different places share it.

The sources are the package's ``kernels`` folder in an installed wheel (pyproject.toml ships ``cuda/`` there), or
the source tree's ``cuda/`` in a checkout or an editable install.
When no compiler is available or the build fails, a warning says so once and callers use the reference.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import warnings
from functools import lru_cache
from pathlib import Path


def _source_dir() -> Path:
    packaged = Path(__file__).resolve().parents[1] / "kernels"
    return packaged if (packaged / "rana_math.h").is_file() else Path(__file__).resolve().parents[2] / "cuda"


SOURCE_DIR = _source_dir()
# the bindings, and the kernel instantiations split so that the build runs them in parallel
CPU_SOURCES = ("rana_cpu.cpp", "rana_cpu_f32_hb4.cpp", "rana_cpu_f32_hb2.cpp", "rana_cpu_f32_hb1.cpp",
               "rana_cpu_other.cpp", "rows_cpu.cpp")
CPU_HEADERS = ("rana_math.h", "rana_binding.h", "rana_cpu_kernels.h", "rana_cpu_buffers.h", "rows_cpu.h")


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


def _sources_digest(names) -> str:
    """Hash of the sources and headers a build reads: an edit to any of them gives a new extension name."""
    h = hashlib.sha1()
    for name in names:
        h.update((SOURCE_DIR / name).read_bytes())
    return h.hexdigest()[:10]


class BuildUnavailable(RuntimeError):
    """The C++ kernels cannot be built or loaded here (no compiler, no sources, or a failed build)."""


def _check_sources(names) -> None:
    if os.environ.get("RANAD_NO_EXTENSION"):
        raise BuildUnavailable("disabled by RANAD_NO_EXTENSION")
    missing = [n for n in names if not (SOURCE_DIR / n).is_file()]
    if missing:
        raise BuildUnavailable(f"kernel sources not found in {SOURCE_DIR} ({', '.join(missing)})")


def build_folder(name: str) -> Path:
    """Where extension `name` is built and cached: $RANAD_KERNEL_CACHE/<python and torch version>/name when the
    variable is set (the binary depends on both), else torch's own folder for it."""
    import sys

    import torch

    root = os.environ.get("RANAD_KERNEL_CACHE")
    if not root:
        from torch.utils.cpp_extension import _get_build_directory  # noqa: PLC0415 - torch's own default

        return Path(_get_build_directory(name, False))
    abi = f"py{sys.version_info[0]}{sys.version_info[1]}_torch{torch.__version__.replace('+', '_')}"
    return Path(root).expanduser() / abi / name


def _build(what: str, name: str, sources, **kwargs):
    """torch's JIT build of `sources` into build_folder(name) (reused when built before); any failure becomes
    BuildUnavailable with its first error. The headers are found beside the sources (quoted includes), so no
    path enters torch's build key."""
    import sys

    from torch.utils.cpp_extension import load

    try:
        folder = build_folder(name)
        folder.mkdir(parents=True, exist_ok=True)
        if not (folder / f"{name}.so").is_file():
            print(f"ranad: building the {what} RaNA kernels for this machine (once per CPU type and version, a "
                  f"minute or two) in {folder}", file=sys.stderr, flush=True)
        return load(name=name, sources=[str(SOURCE_DIR / n) for n in sources], build_directory=str(folder),
                    verbose=False, **kwargs)
    except Exception as e:  # noqa: BLE001 - any build failure means: use the reference
        lines = str(e).strip().splitlines() or ["unknown error"]
        first_error = next((ln for ln in lines if "error" in ln.lower()), lines[-1])
        raise BuildUnavailable(f"building the {what} RaNA kernels failed: {first_error.strip()}") from e


@lru_cache(maxsize=None)
def load_cpu_extension():
    """The compiled module (``forward``/``backward``), building it if needed; raises BuildUnavailable."""
    _check_sources(CPU_SOURCES + CPU_HEADERS)
    if not (shutil.which(os.environ.get("CXX", "c++")) or shutil.which("g++")):
        raise BuildUnavailable("no C++ compiler on PATH (install g++ or set CXX)")
    flags = ["-O3", "-std=c++20", "-fopenmp", "-march=native", "-fno-math-errno", "-fno-trapping-math"]
    return _build("C++", f"ranad_rana_cpu_{_cpu_tag()}_{_sources_digest(CPU_SOURCES + CPU_HEADERS)}", CPU_SOURCES,
                  extra_cflags=flags, extra_ldflags=["-fopenmp"])


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
CUDA_SOURCES = ("rana_cuda.cpp", "rana_cuda_kernels.cu", "rana_cuda_staged.cu")
CUDA_HEADERS = ("rana_math.h", "rana_binding.h", "rana_cuda_kernels.h")
CUDA_ARCHS = ("80", "86", "89", "90")   # what CI compiles for (cuda/check_build.sh)


@lru_cache(maxsize=None)
def load_cuda_extension():
    """The CUDA kernels' module (``forward``/``backward`` taking the stream as an integer), built with nvcc by
    torch's JIT builder for the GPU present; raises BuildUnavailable without CUDA torch, a GPU or nvcc."""
    import torch

    _check_sources(CUDA_SOURCES + CUDA_HEADERS)
    if not torch.cuda.is_available():
        raise BuildUnavailable("no CUDA device (or a CPU-only build of torch)")
    return _build("CUDA", f"ranad_rana_cuda_{_sources_digest(CUDA_SOURCES + CUDA_HEADERS)}", CUDA_SOURCES,
                  extra_cflags=["-O3", "-std=c++20"],
                  extra_cuda_cflags=["-O3", "-std=c++20", "-Xptxas", "-warn-spills", "--expt-relaxed-constexpr"])


@lru_cache(maxsize=None)
def cuda_extension_or_none():
    """The CUDA module, or None after warning once why the reference will run on the GPU instead."""
    try:
        return load_cuda_extension()
    except BuildUnavailable as e:
        warnings.warn(f"ranad: CUDA RaNA kernels unavailable ({e}); using the torch reference on the GPU",
                      RuntimeWarning, stacklevel=3)
        return None
