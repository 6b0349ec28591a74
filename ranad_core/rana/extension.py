"""Build and load the C++ RaNA kernels (``cuda/rana_cpu*.cpp``) with torch's JIT extension builder.

Built on first use (with a message on stderr: it takes a minute or two) and cached, so later runs load in
milliseconds; a cached build that torch's builder finds out of date is rebuilt, with a message too once the load
takes longer than a load does. The cache folder is ``$RANAD_KERNEL_CACHE`` when set (a folder a render farm shares),
else torch's (``$TORCH_EXTENSIONS_DIR``, default ``~/.cache/torch_extensions``). The build is tuned for the CPU it
runs on (``-march=native``); the extension name carries a hash of the CPU's feature flags and of the sources, so a
shared cache holds one build per CPU type and version and never hands a binary to a CPU that cannot run it. The
sources are compiled from a copy inside the build folder, so no install's path enters the build: installs in
different places share one build (compiled from their own paths, each would make the other's look out of date and
rebuild it).

Builds of one folder take turns under a lock the system releases when its holder dies: a build interrupted (Ctrl-C, a
farm job killed) leaves no lock behind that would make every later run wait for ever, as torch's own lock file would.

The sources are the package's ``kernels`` folder in an installed wheel (pyproject.toml ships ``cuda/`` there), or
the source tree's ``cuda/`` in a checkout or an editable install.
When no compiler is available or the build fails, a warning says so once and callers use the reference.
"""

from __future__ import annotations

import contextlib
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
               "rana_cpu_other.cpp", "rows_cpu.cpp", "composite_cpu.cpp")
CPU_HEADERS = ("rana_math.h", "rana_binding.h", "rana_cpu_kernels.h", "rana_cpu_buffers.h", "rows_cpu.h",
               "composite_cpu.h")


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


def _build(what: str, name: str, sources, headers, **kwargs):
    """torch's JIT build of `sources` into build_folder(name) (reused when built before), from their copy in the
    folder (`staged_sources`), under the folder's build lock (`build_lock`); any failure becomes BuildUnavailable
    with its first error."""
    import sys

    from torch.utils.cpp_extension import load

    try:
        folder = build_folder(name)
        so = folder / f"{name}.so"
        if so.is_file() and not os.access(folder, os.W_OK):
            # a farm's shared cache mounted read-only: its folder's name carries the sources' digest and the CPU
            # type, so the module there is this build; torch's builder would need to write (its lock, ninja)
            return _import_built(name, so)
        folder.mkdir(parents=True, exist_ok=True)
        with build_lock(folder, what):
            src = staged_sources(folder, tuple(sources) + tuple(headers))
            ninja = folder / "build.ninja"   # it names the sources by path: a cache copied elsewhere rebuilds
            moved = ninja.is_file() and str(src) not in ninja.read_text(errors="replace")
            if not so.is_file() or moved:
                print(f"ranad: building the {what} RaNA kernels for this machine (once per CPU type and version, a "
                      f"minute or two) in {folder}" + (" (the folder was built elsewhere)" if moved else ""),
                      file=sys.stderr, flush=True)
                notice = contextlib.nullcontext()
            else:
                notice = rebuild_notice(f"ranad: rebuilding the {what} RaNA kernels in {folder} (their build is out "
                                        "of date: a compiler, torch or header changed; a minute or two)")
            with notice:
                return load(name=name, sources=[str(src / n) for n in sources], build_directory=str(folder),
                            verbose=False, **kwargs)
    except Exception as e:  # noqa: BLE001 - any build failure means: use the reference
        lines = str(e).strip().splitlines() or ["unknown error"]
        first_error = next((ln for ln in lines if "error" in ln.lower()), lines[-1])
        raise BuildUnavailable(f"building the {what} RaNA kernels failed: {first_error.strip()}") from e


REBUILD_NOTICE_S = 3.0   # a built module loads in a fraction of a second; longer means the builder is compiling


@contextlib.contextmanager
def rebuild_notice(message: str):
    """Prints `message` on stderr if the block is still running REBUILD_NOTICE_S seconds on.
    Torch's builder recompiles a module that exists when its build is out of date (a newer torch or header, another
    compiler: ninja's own rules), which took 90 s without a word on a machine whose files were restored; the module
    being there, nothing says in advance that it will, so the notice comes when the load takes build time."""
    import sys
    import threading

    timer = threading.Timer(REBUILD_NOTICE_S, lambda: print(message, file=sys.stderr, flush=True))
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()


def _import_built(name: str, so: Path):
    """The already built module `so` imported as it is (no build step, nothing written)."""
    import importlib
    import importlib.util

    importlib.import_module("torch")   # the module links against torch's libraries, loaded with it
    spec = importlib.util.spec_from_file_location(name, str(so))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


STAGED = "src"            # the build folder's copy of the sources
TORCH_LOCK = "lock"        # torch's lock file in a build folder (cpp_extension's FileBaton)
BUILD_LOCK = "ranad.lock"  # ours: flock'ed, so released with the process that holds it


@contextlib.contextmanager
def build_lock(folder: Path, what: str = "C++"):
    """Holds the build folder's lock (fcntl.flock on BUILD_LOCK, waited for with a message when another process
    holds it). Every ranad build of the folder runs under it, so a torch lock file found while holding it was left
    by a build that died, and is removed: torch would otherwise wait for it for ever."""
    import fcntl
    import sys

    with open(folder / BUILD_LOCK, "a") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            print(f"ranad: waiting for another process building the {what} RaNA kernels in {folder}", file=sys.stderr,
                  flush=True)
            fcntl.flock(f, fcntl.LOCK_EX)
        try:
            (folder / TORCH_LOCK).unlink(missing_ok=True)
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def staged_sources(folder: Path, names) -> Path:
    """folder/STAGED holding `names` as in SOURCE_DIR (each rewritten, through a temporary file, only when it
    differs; the folder's name carries the sources' digest, so normally they are written once): what the build
    compiles, at the same path whichever install asks."""
    dst = folder / STAGED
    dst.mkdir(exist_ok=True)
    for n in names:
        data = (SOURCE_DIR / n).read_bytes()
        target = dst / n
        if target.is_file() and target.read_bytes() == data:
            continue
        tmp = dst / f".{n}.{os.getpid()}.tmp"
        tmp.write_bytes(data)
        os.replace(tmp, target)
    return dst


@lru_cache(maxsize=None)
def load_cpu_extension():
    """The compiled module (``forward``/``backward``), building it if needed; raises BuildUnavailable."""
    _check_sources(CPU_SOURCES + CPU_HEADERS)
    if not (shutil.which(os.environ.get("CXX", "c++")) or shutil.which("g++")):
        raise BuildUnavailable("no C++ compiler on PATH (install g++ or set CXX)")
    flags = ["-O3", "-std=c++20", "-fopenmp", "-march=native", "-fno-math-errno", "-fno-trapping-math"]
    return _build("C++", f"ranad_rana_cpu_{_cpu_tag()}_{_sources_digest(CPU_SOURCES + CPU_HEADERS)}", CPU_SOURCES,
                  CPU_HEADERS, extra_cflags=flags, extra_ldflags=["-fopenmp"])


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
                  CUDA_HEADERS, extra_cflags=["-O3", "-std=c++20"],
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
