"""Session 30: the RaNA forward alone on bench/rana.py's problem (512x512, 0-6 bins per pixel, 4 heads, radius 3.5,
channel-major), best of N calls, for `perf record` (the bench times forward+backward too, and the reference).
Usage: python runs/generalization-s30/perf_fwd.py [DIM] [N]   (from the repository root)"""
import sys
import time

import torch

sys.path.insert(0, "bench")
sys.path.insert(0, ".")
from rana import pairs_of, problem  # noqa: E402  (bench/rana.py)

from ranad_core.rana import rana, self_attention_layout  # noqa: E402

torch.set_num_threads(2)
dim = int(sys.argv[1]) if len(sys.argv) > 1 else 16
offsets, q, k, v = problem(512, 4, dim, layout="channel-major")
qp, ko, ks = self_attention_layout(offsets, 512, 512)
bias = torch.zeros(4, 7, 7)
rana(q, k, v, qp, ko, ks, 3.5, bias, backend="cpu")   # warm-up (and the kernels' build)
pairs = pairs_of(offsets, 512, 3.5)
times = []
for _ in range(int(sys.argv[2]) if len(sys.argv) > 2 else 10):
    t = time.perf_counter()
    rana(q, k, v, qp, ko, ks, 3.5, bias, backend="cpu")
    times.append(time.perf_counter() - t)
print(f"d={dim} forward best of {len(times)}: {min(times) * 1e3:.1f} ms = {pairs / min(times) / 1e6:.0f} M pairs/s")
