"""The C allocator's policy for a denoising process: keep freed memory for reuse, give it back when measuring.

Why: every layer of the model writes its outputs into fresh tensors of tens to hundreds of MB. glibc serves
allocations that large with their own mmap and unmaps them when freed, so each layer's outputs landed on pages
the kernel first had to fault in and zero. The first remedy (raising the mmap threshold to glibc's 32 MB ceiling,
no trimming: bench/denoise.py's held-out 1080p frame 62.7 s -> 49.8 s) left every tensor above 32 MB on fresh
mappings, and at 1080p most of a tile's are: a [1M, 32] x [32, 96] projection took 138 ms into fresh memory, 61
ms into reused memory. `keep_freed_memory` makes glibc serve every allocation from its heap (no mmap at all) and
keep freed blocks there, so the next layer reuses the pages already mapped: the same frame 42.0 s -> 38.6 s
(`ranad denoise --profile`), output bit-identical.

The price is that freed memory stays resident until `give_back` returns it (malloc_trim): `memory.py` calls it
before it measures the process's resident set, so `--max-memory`'s accounting sees what is in use, not what the
heap keeps for later. Kept memory also counts against the ceiling itself: on the held-out 1080p frame at
`--max-memory 4G` the resident set only grew, to 3.6 GB after the flat prior (OIDN's freed scratch kept) and 4.1 GB
after the output was assembled, 2% under the ceiling. So a denoise sets the ceiling (`set_ceiling`) and calls
`relieve` between its stages and tiles: above RELIEVE_AT of the ceiling the kept memory goes back, below it
(the default 8G on that frame) nothing is given back and nothing is faulted in again. RELIEVE_AT was 0.8 until a
3-frame shot of that frame at `--max-memory 4G` peaked at 3.25-4.08 GiB over seven runs, over the ceiling in four
(the tiles' resident set sat at 3.14-3.16 GiB, just under 0.8 of it, so nothing went back between tiles and the
kept memory grew where a tile's allocations fell differently); at 0.7 three runs peaked at 3.24-3.28 GiB, in
the same time (runs/generalization-s38). Elsewhere than glibc (musl, macOS) all of this is a no-op.
"""

from __future__ import annotations

import ctypes
import os
import sys

_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_MAX = -1, -2, -4   # <malloc.h>
_TOP_PAD = 64 << 20            # heap growth per sbrk: fewer system calls as a tile's tensors grow the heap
_NEVER_TRIM = (1 << 31) - 1    # mallopt takes an int: 2 GiB of free heap top before free() trims on its own

RELIEVE_AT = 0.7               # of the ceiling: the resident set above which relieve() gives kept memory back

_state = {"libc": None, "ceiling": None}   # libc: glibc's handle once the policy is in effect


def _libc():
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None)
        return libc if hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


def keep_freed_memory() -> bool:
    """Serve large allocations from the heap and keep freed memory mapped for reuse (process-wide; idempotent).
    Returns whether the policy is in effect (False where the C library is not glibc)."""
    if _state["libc"] is not None:
        return True
    libc = _libc()
    if libc is None:
        return False
    ok = (libc.mallopt(_M_MMAP_MAX, 0) == 1) & (libc.mallopt(_M_TRIM_THRESHOLD, _NEVER_TRIM) == 1)
    ok &= libc.mallopt(_M_TOP_PAD, _TOP_PAD) == 1
    if ok:
        _state["libc"] = libc
    return bool(ok)


def give_back() -> None:
    """Return the heap's free pages to the system (a no-op unless `keep_freed_memory` is in effect)."""
    if _state["libc"] is not None:
        _state["libc"].malloc_trim(0)


class _Mallinfo2(ctypes.Structure):   # <malloc.h>, glibc 2.33 and later
    _fields_ = [(name, ctypes.c_size_t) for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                     "fsmblks", "uordblks", "fordblks", "keepcost")]


def kept_bytes() -> int | None:
    """Free bytes the heap keeps for reuse, every arena (mallinfo2's fordblks; an upper bound of what give_back
    would return, as some of them may not be resident); None where unknown (the policy not in effect, or a glibc
    without mallinfo2)."""
    libc = _state["libc"]
    if libc is None or not hasattr(libc, "mallinfo2"):
        return None
    info = libc.mallinfo2
    info.restype, info.argtypes = _Mallinfo2, []
    return int(info().fordblks)


def resident_now() -> int:
    """The resident set now, kept memory included (Linux /proc; 0 where it cannot be read)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def set_ceiling(max_bytes: float | None) -> None:
    """The memory ceiling (`--max-memory`) `relieve` keeps the kept memory under; None: no ceiling."""
    _state["ceiling"] = max_bytes


def relieve() -> bool:
    """Gives the kept memory back when the resident set is above RELIEVE_AT of the ceiling (called between a
    denoise's stages and tiles); returns whether it did."""
    ceiling = _state["ceiling"]
    if _state["libc"] is None or not ceiling or resident_now() <= RELIEVE_AT * ceiling:
        return False
    give_back()
    return True
