"""Worker processes that do not outlive the command that started them.

Farm schedulers stop a job by signalling (or killing) its main process only. `ranad synth`'s render workers are
spawned processes; killed that way, the parent left them running as orphans, still rendering and writing into the
dataset folder while a rerun started its own workers on the same scenes. A worker calls `die_with_parent()` first
thing, so the kernel sends it SIGTERM when its parent exits, however the parent ends.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def die_with_parent(sig: int = signal.SIGTERM) -> bool:
    """Ask Linux to send `sig` to this process when its parent exits; exits at once if the parent is already
    gone (it may have died before the call). Returns False where the request is unavailable (not Linux)."""
    if not sys.platform.startswith("linux"):
        return False
    parent = os.getppid()
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):
        return False
    if os.getppid() != parent:  # the parent died between getppid() and prctl(): no signal will come
        os._exit(1)
    return True
