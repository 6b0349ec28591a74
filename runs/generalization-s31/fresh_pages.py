"""What first-touching fresh memory costs on this machine: allocates GB gigabytes (numpy, no huge pages), writes
them once and prints the wall time and the process's system time. Run twice in a row and again after 20 s idle:
on the 2-core VM of sessions 24-31 the idle case pays ~1.3 s per GB against ~0.55 s right after another run (the
host backs returned guest memory again), which every `ranad denoise` pays on its peak resident set.

Usage: NUMPY_MADVISE_HUGEPAGE=0 python fresh_pages.py GB"""
import resource
import sys
import time

import numpy as np

n = int(float(sys.argv[1]) * 2**28)  # float32 values
t = time.perf_counter()
a = np.empty(n, np.float32)
a.fill(1)
t1 = time.perf_counter()
r = resource.getrusage(resource.RUSAGE_SELF)
print(f"first touch of {sys.argv[1]} GB: {t1 - t:.3f} s wall, {r.ru_stime:.2f} s system")
