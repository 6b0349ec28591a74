"""RaNA forward alone, for A/B runs of kernel variants (session 25): bench/rana.py's 512x512 channel-major problem
(4 heads of D channels, radius 3.5, a zero bias), the mean time of N calls after one warm-up, with the repository
at $REPO (default /work/main), so a worktree's kernels build and run in their own process.
Usage: REPO=/path/to/checkout python fwd.py D [N]"""
import os
import sys
import time

import torch

R = os.environ.get("REPO", "/work/main")
sys.path[:0] = [R, os.path.join(R, "bench")]
from rana import problem  # noqa: E402
from ranad_core.rana import rana, self_attention_layout  # noqa: E402

d, reps, size = int(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 20, 512
offsets, q, k, v = problem(size, 4, d, layout="channel-major")
qp, ko, ks = self_attention_layout(offsets, size, size)
bias = torch.zeros(4, 7, 7)
rana(q, k, v, qp, ko, ks, 3.5, bias)
t = time.perf_counter()
for _ in range(reps):
    rana(q, k, v, qp, ko, ks, 3.5, bias)
print(d, (time.perf_counter() - t) / reps * 1e3, "ms")
