"""heap.py's allocator policy, checked on a real process: with the policy, freed memory stays mapped (the next
layer reuses it instead of faulting in fresh pages) until give_back returns it, so memory.resident_bytes, which
gives back first, still measures what is in use."""

import subprocess
import sys

import pytest

SCRIPT = r"""
import sys
import numpy as np
from ranad_core import heap, memory

def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096

if sys.argv[1] in ("keep", "relieve") and not heap.keep_freed_memory():
    print("unsupported")
    sys.exit(0)
before = rss()
a = np.ones(64 << 20, dtype=np.uint8)     # 64 MB, every page touched
held = rss()
del a
after_free = rss()
if sys.argv[1] == "relieve":              # under a ceiling far above the process: kept; just above it: given back
    heap.set_ceiling(1e15)
    assert not heap.relieve() and rss() - before > 60 << 20
    heap.set_ceiling(rss() / heap.RELIEVE_AT * 0.99)
    assert heap.relieve()
    heap.set_ceiling(None)
    print(before, held, after_free, rss(), rss())
    sys.exit(0)
measured = memory.resident_bytes()       # gives back first
print(before, held, after_free, measured, rss())
"""


def _run(mode: str) -> list:
    out = subprocess.run([sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True, check=True)
    if out.stdout.strip() == "unsupported":
        pytest.skip("the C library is not glibc: no allocator policy to check")
    return [int(v) for v in out.stdout.split()]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator policy: Linux only")
def test_freed_memory_is_kept_until_given_back():
    mb = 1 << 20
    before, held, after_free, measured, after = _run("keep")
    assert held - before > 60 * mb
    assert after_free - before > 60 * mb            # kept mapped for reuse
    assert measured - before < 8 * mb and after - before < 8 * mb   # given back before measuring


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator policy: Linux only")
def test_without_the_policy_freed_memory_goes_back_at_once():
    mb = 1 << 20
    before, held, after_free, _, _ = _run("plain")
    assert held - before > 60 * mb
    assert after_free - before < 8 * mb


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator policy: Linux only")
def test_kept_memory_goes_back_only_near_the_ceiling():
    """heap.relieve, called between a denoise's stages and tiles: below RELIEVE_AT of the --max-memory ceiling the
    kept memory stays for reuse; above it, it goes back."""
    mb = 1 << 20
    before, held, after_free, relieved, _ = _run("relieve")
    assert after_free - before > 60 * mb
    assert relieved - before < 8 * mb


@pytest.mark.parametrize("user", [None, "1"])
def test_command_line_turns_numpys_huge_pages_off_unless_the_user_set_it(user):
    """ranad_cli.main sets NUMPY_MADVISE_HUGEPAGE=0 before numpy is imported (numpy reads it once, at import): an
    import of numpy ahead of that line would silently undo it. A user's own setting wins."""
    import os

    getter = "getattr(np, '_core', None) or np.core"
    code = ("import ranad_cli.main, numpy as np; "
            f"print(int(({getter}).multiarray._get_madvise_hugepage()))")
    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    if user is not None:
        env["NUMPY_MADVISE_HUGEPAGE"] = user
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.strip() == ("1" if user == "1" else "0")


OPENBLAS_THREADS_PROBE = """
import ctypes, sys
import ranad_cli.main, numpy  # noqa: F401 (numpy's OpenBLAS reads OPENBLAS_NUM_THREADS when it loads)
paths = {line.split()[-1] for line in open('/proc/self/maps') if 'openblas' in line.split()[-1]}
for path in sorted(paths):
    lib = ctypes.CDLL(path)
    for name in ('scipy_openblas_get_num_threads64_', 'scipy_openblas_get_num_threads', 'openblas_get_num_threads64_',
                 'openblas_get_num_threads'):
        if hasattr(lib, name):
            print(getattr(lib, name)())
            sys.exit(0)
print('none')
"""


@pytest.mark.parametrize("user", [None, "2"])
def test_command_line_gives_numpys_blas_one_thread_unless_the_user_set_it(user):
    """ranad_cli.main sets OPENBLAS_NUM_THREADS=1 before numpy loads its BLAS (whose idle threads otherwise spin on
    the cores torch's threads need); a user's own setting wins. Asked of the loaded OpenBLAS itself."""
    import os

    if not sys.platform.startswith("linux"):
        pytest.skip("reads /proc/self/maps (Linux only)")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if user is not None:
        env["OPENBLAS_NUM_THREADS"] = user
    out = subprocess.run([sys.executable, "-c", OPENBLAS_THREADS_PROBE], capture_output=True, text=True, env=env,
                         check=True).stdout.strip()
    if out == "none":
        pytest.skip("this numpy is not built on OpenBLAS (nothing to limit)")
    assert int(out) == (int(user) if user else 1)
