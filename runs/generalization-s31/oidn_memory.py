"""OIDN's maxMemoryMB on the flat prior's job: the held-out 1080p frame's flattened beauty (bench/denoise.py
--frame, written to FRAME by its make_1080p) denoised with the default scratch and with maxMemoryMB = MB, in a fresh
process each (run it once per setting). Prints the time, the process's peak and whether the output is bitwise the
default's (saved to /tmp/oidn_0.npy by the default run).

Usage: python oidn_memory.py FRAME MB   (MB 0: OIDN's default)"""
import sys
import time
from pathlib import Path

import numpy as np
import pyoidn

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from ranad_core import metrics  # noqa: E402
from ranad_core.exr import read_deep  # noqa: E402

flat = np.ascontiguousarray(np.maximum(metrics.flat_rgb(read_deep(sys.argv[1])), 0), np.float32)
mm = int(sys.argv[2])
out = np.empty_like(flat)
t = time.perf_counter()
with pyoidn.Device() as d:
    d.commit()
    with pyoidn.Filter(d, pyoidn.OIDN_FILTER_TYPE_RT) as f:
        f.set_image("color", flat, pyoidn.OIDN_FORMAT_FLOAT3)
        f.set_image("output", out, pyoidn.OIDN_FORMAT_FLOAT3)
        f.set_bool("hdr", True)
        if mm > 0:
            f.set_int("maxMemoryMB", mm)
        f.commit()
        f.execute()
dt = time.perf_counter() - t
peak = [int(ln.split()[1]) for ln in open("/proc/self/status") if ln.startswith("VmHWM")][0] / 1024
same = ""
if mm > 0 and Path("/tmp/oidn_0.npy").exists():
    same = f", bitwise the default's: {bool(np.array_equal(np.load('/tmp/oidn_0.npy'), out))}"
else:
    np.save("/tmp/oidn_0.npy", out)
print(f"maxMemoryMB {mm}: {dt:.2f} s, peak {peak:.0f} MB{same}")
