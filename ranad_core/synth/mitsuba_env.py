"""Loading Mitsuba 3's vectorised CPU variant (``llvm_ad_rgb``), which needs LLVM 19.

Dr.Jit finds LLVM through ``DRJIT_LIBLLVM_PATH``; when it is unset we point it at Debian's ``libllvm19``
(``/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1``) if present, since LLVM 14 is refused and 15/16 abort
(DESIGN.md). Anything missing becomes a RanadError that says what to install.
"""

from __future__ import annotations

import glob
import os
from functools import lru_cache

from ..errors import RanadError

VARIANT = "llvm_ad_rgb"
LLVM_CANDIDATES = ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1", "/usr/lib/llvm-19/lib/libLLVM.so.19.1",
                   "/usr/lib/llvm-19/lib/libLLVM-19.so")
INSTALL_HINT = "install Debian's libllvm19 (apt-get install libllvm19) and pip install 'ranad[synth]'"


def _find_llvm() -> str | None:
    for path in LLVM_CANDIDATES + tuple(sorted(glob.glob("/usr/lib/*/libLLVM.so.19*"))):
        if os.path.isfile(path):
            return path
    return None


@lru_cache(maxsize=None)
def mitsuba():
    """The ``mitsuba`` module with the ``llvm_ad_rgb`` variant set; raises RanadError when unavailable."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        found = _find_llvm()
        if found:
            os.environ["DRJIT_LIBLLVM_PATH"] = found
    try:
        import mitsuba as mi
    except ImportError as e:
        raise RanadError(f"Mitsuba 3 is not installed ({e}); {INSTALL_HINT}", "ranad synth") from None
    try:
        mi.set_variant(VARIANT)
    except Exception as e:  # noqa: BLE001 - Dr.Jit reports a missing LLVM in several ways
        raise RanadError(f"Mitsuba variant {VARIANT} unavailable ({e}); {INSTALL_HINT}", "ranad synth") from None
    return mi


def available() -> tuple[bool, str]:
    """(True, "") when Mitsuba's CPU variant loads, else (False, why): for skipping tests with a reason."""
    try:
        mitsuba()
        return True, ""
    except RanadError as e:
        return False, e.problem
