"""Packaging: a wheel carries everything a user's install needs, the C++ kernel sources included.

A non-editable install once shipped without ``cuda/``, and the op fell back to the slow reference without a word.
The wheel test builds the wheel, installs it into a fresh virtual environment (its dependencies, torch and numpy,
come from this environment's site-packages through a ``.pth`` path entry: a path entry runs no ``.pth`` files, so
this checkout's editable install stays out of it), and from outside the source tree builds the kernels into an
empty ``RANAD_KERNEL_CACHE`` and compares the op with the reference.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_package_list_covers_every_package_folder():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for top in ("ranad_core", "ranad_cli")
             for p in (ROOT / top).rglob("__init__.py") if "__pycache__" not in p.parts}
    assert found <= listed, f"packages missing from pyproject.toml: {sorted(found - listed)}"
    assert listed - found == {"ranad_core.kernels"}  # the one mapped folder (cuda/)


def test_kernel_cache_folder_follows_the_environment(monkeypatch, tmp_path):
    from ranad_core.rana import extension

    monkeypatch.setenv("RANAD_KERNEL_CACHE", str(tmp_path))
    folder = extension.build_folder("ranad_rana_cpu_x")
    assert folder.parent.parent == tmp_path and folder.name == "ranad_rana_cpu_x"
    assert folder.parent.name.startswith(f"py{sys.version_info[0]}{sys.version_info[1]}_torch")



def test_the_build_compiles_the_staged_copy_of_the_sources():
    """The loaded kernels were compiled from the build folder's copy of the sources, not from this checkout's path:
    another install's path would otherwise make torch's build file differ and rebuild the shared build."""
    from ranad_core.rana import extension

    ext = extension.load_cpu_extension()
    folder = Path(ext.__file__).parent
    ninja = (folder / "build.ninja").read_text()
    assert str(folder / extension.STAGED / "rana_cpu.cpp") in ninja
    assert str(extension.SOURCE_DIR) not in ninja
    for name in extension.CPU_SOURCES + extension.CPU_HEADERS:
        assert (folder / extension.STAGED / name).read_bytes() == (extension.SOURCE_DIR / name).read_bytes()


def _built_module_in_cache(monkeypatch, tmp_path):
    """This machine's built kernel module copied alone into a fresh kernel cache ($RANAD_KERNEL_CACHE = tmp_path):
    (module, extension name, its folder there)."""
    import shutil

    from ranad_core.rana import extension

    ext = extension.load_cpu_extension()
    built = Path(ext.__file__).parent
    monkeypatch.setenv("RANAD_KERNEL_CACHE", str(tmp_path))
    name = built.name
    folder = extension.build_folder(name)
    folder.mkdir(parents=True)
    shutil.copy(built / f"{name}.so", folder / f"{name}.so")
    return ext, name, folder


def test_a_read_only_kernel_cache_is_used_as_it_is(monkeypatch, tmp_path):
    """A farm's prebuilt kernel cache mounted read-only: the build lock could not be opened there, so ranad fell
    back to the slow torch reference (2.5 s against 0.4 s a frame). The folder's name carries the sources'
    digest and the CPU type, so its module is imported as it is, nothing written."""
    import os

    from ranad_core.rana import extension

    _, name, folder = _built_module_in_cache(monkeypatch, tmp_path)
    real_access = os.access
    monkeypatch.setattr(extension.os, "access", lambda p, mode: False if Path(p) == folder and mode == os.W_OK
                        else real_access(p, mode))
    monkeypatch.setattr(extension, "build_lock", lambda *a, **k: (_ for _ in ()).throw(AssertionError("built")))
    module = extension._build("C++", name, extension.CPU_SOURCES, extension.CPU_HEADERS)
    assert hasattr(module, "forward")   # (Python hands back the module already loaded under that name)
    assert sorted(p.name for p in folder.iterdir()) == [f"{name}.so"]


def test_staged_sources_are_written_only_when_they_differ(tmp_path):
    from ranad_core.rana import extension

    names = extension.CPU_SOURCES + extension.CPU_HEADERS
    src = extension.staged_sources(tmp_path, names)
    first = {n: (src / n).stat().st_mtime_ns for n in names}
    (src / "rows_cpu.h").write_text("// edited")
    extension.staged_sources(tmp_path, names)
    assert (src / "rows_cpu.h").read_bytes() == (extension.SOURCE_DIR / "rows_cpu.h").read_bytes()
    assert all((src / n).stat().st_mtime_ns == first[n] for n in names if n != "rows_cpu.h")
    assert sorted(p.name for p in src.iterdir()) == sorted(names)   # no temporary file left


def test_a_load_that_takes_build_time_says_so(monkeypatch, tmp_path, capsys):
    """A module that exists but whose build is out of date (a newer torch or header): torch's builder recompiles it,
    which took 90 s without a word. The load still runs; once it takes longer than a load does, the user is told.
    A load that returns at once prints nothing."""
    import time

    import torch.utils.cpp_extension as cpp

    from ranad_core.rana import extension

    ext, name, folder = _built_module_in_cache(monkeypatch, tmp_path)
    monkeypatch.setattr(extension, "REBUILD_NOTICE_S", 0.2)
    monkeypatch.setattr(cpp, "load", lambda **kw: ext)
    assert extension._build("C++", name, extension.CPU_SOURCES, extension.CPU_HEADERS) is ext
    time.sleep(0.4)
    assert "RaNA kernels" not in capsys.readouterr().err   # a quick load: no message, none later

    monkeypatch.setattr(cpp, "load", lambda **kw: time.sleep(0.6) or ext)
    assert extension._build("C++", name, extension.CPU_SOURCES, extension.CPU_HEADERS) is ext
    err = capsys.readouterr().err
    assert "rebuilding the C++ RaNA kernels" in err and str(folder) in err


HOLDER = """
import sys, time
from pathlib import Path
from ranad_core.rana.extension import build_lock
with build_lock(Path(sys.argv[1])):
    print("held", flush=True)
    time.sleep(float(sys.argv[2]))
"""


def _holder(folder: Path, seconds: float) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, "-c", HOLDER, str(folder), str(seconds)], stdout=subprocess.PIPE,
                         text=True, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert p.stdout.readline().strip() == "held"
    return p


def test_a_killed_build_leaves_no_lock_behind(tmp_path):
    """A build killed while it holds the lock (a farm job killed, Ctrl-C) and torch's lock file it left: the next
    build takes the lock at once and removes the stale file (torch would wait for it for ever)."""
    import fcntl

    from ranad_core.rana import extension

    holder = _holder(tmp_path, 600)
    (tmp_path / extension.TORCH_LOCK).write_text("")
    with open(tmp_path / extension.BUILD_LOCK) as f:
        with pytest.raises(BlockingIOError):
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)   # held while the holder lives
    holder.kill()
    holder.wait()
    with extension.build_lock(tmp_path):
        assert not (tmp_path / extension.TORCH_LOCK).exists()


def test_a_second_build_waits_for_the_first_and_says_so(tmp_path, capsys):
    import time

    from ranad_core.rana import extension

    holder = _holder(tmp_path, 1.5)
    t = time.perf_counter()
    with extension.build_lock(tmp_path, "C++"):
        waited = time.perf_counter() - t
    holder.wait()
    assert waited > 0.5
    assert "waiting for another process building the C++ RaNA kernels" in capsys.readouterr().err


SCRIPT = r"""
import sys, torch
import ranad_core
from ranad_core.rana import extension, rana, self_attention_layout
site = sys.argv[1]
assert ranad_core.__file__.startswith(site), ranad_core.__file__
assert str(extension.SOURCE_DIR).startswith(site), extension.SOURCE_DIR
ext = extension.load_cpu_extension()
assert ext.__file__.startswith(sys.argv[2]), ext.__file__
g = torch.Generator().manual_seed(0)
counts = torch.randint(0, 4, (12 * 12,), generator=g)
offsets = torch.cat([torch.zeros(1, dtype=torch.int64), counts.cumsum(0)])
qp, ko, ks = self_attention_layout(offsets, 12, 12)
q, k, v = (torch.randn(int(offsets[-1]), 2, 8, generator=g) for _ in range(3))
args = (q, k, v, qp, ko, ks, 2.5)
out = rana(*args, backend="cpu")
ref = rana(*args, backend="reference")
err = (out - ref).abs().max().item()
assert err < 1e-4, err
print("ok", err)
"""


def test_wheel_builds_and_uses_the_kernels_outside_the_source_tree(tmp_path):
    import shutil

    if not (shutil.which(os.environ.get("CXX", "c++")) or shutil.which("g++")):
        pytest.skip("no C++ compiler on PATH: the kernels cannot be built here")
    wheels = tmp_path / "wheels"
    (tmp_path / "src").mkdir()
    # build isolation, as `pip install .` does: pyproject.toml's setuptools, not whatever this venv holds
    src = tmp_path / "src"   # a copy: setuptools builds in the source folder (build/, *.egg-info), not here
    for name in ("pyproject.toml", "README.md", "ranad_core", "ranad_cli", "cuda"):
        copy = shutil.copytree if (ROOT / name).is_dir() else shutil.copy2
        copy(ROOT / name, src / name, **({"ignore": shutil.ignore_patterns("__pycache__")}
                                         if (ROOT / name).is_dir() else {}))
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q", "-w", str(wheels)],
                           cwd=tmp_path, capture_output=True, text=True)
    assert build.returncode == 0, build.stderr[-3000:]
    (wheel,) = wheels.glob("ranad-*.whl")
    env_dir = tmp_path / "fresh"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env_dir)], check=True)
    python = env_dir / "bin" / "python"
    site = Path(subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                               check=True, capture_output=True, text=True).stdout.strip())
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
                   check=True, capture_output=True)
    (site / "deps.pth").write_text(sysconfig.get_path("purelib") + "\n")
    cache = tmp_path / "kernel-cache"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "TORCH_EXTENSIONS_DIR")}
    env["RANAD_KERNEL_CACHE"] = str(cache)
    run = subprocess.run([python, "-c", SCRIPT, str(site), str(cache)], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    assert run.stdout.startswith("ok")
    assert "building the C++ RaNA kernels" in run.stderr  # the user is told while the build runs
