"""The kernel maths in cuda/rana_math.h must compile as CUDA device code too (the GPU kernels reuse it).

Compile-only (no GPU needed): a smoke kernel calling the forward, dQ and dK/dV block bodies with one lane per thread is
built with nvcc for sm_80. Skipped with a reason when nvcc is not installed.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

CUDA_DIR = Path(__file__).resolve().parents[1] / "cuda"

SMOKE = r"""
#include "rana_math.h"
using namespace rana;
// One thread per (entry, head), L = 1: the same block bodies the CPU kernels run with 16 lanes.
__global__ void smoke(Op<float> op, const float* q, const float* kt, const float* vt, const float* dout,
                      const float* lse, const float* delta, const float* qst, const float* dost, const float* k,
                      const float* v, const int64_t* qpix, const int64_t* q_ptr, float* out, float* lse_out,
                      float* dq, float* dk, float* dv, float* dbias_lanes, int n) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n * op.H) return;
  const int e = i / op.H, h = i % op.H;
  Block<1> b;
  b.y = qpix[2 * e];
  b.x0 = qpix[2 * e + 1];
  b.span = 0;
  b.n = 1;
  b.id[0] = e;
  b.rel[0] = 0;
  const LaneTable<1> lq = lane_table<1, 1>(b, op.rows, op.H, h, 1), lk = lane_table<1, 1>(b, op.rows, op.H, h, -1);
  const PixelWalk keys{op.g, op.rows, op.g.offsets, 1, b.y, b.x0, 0};
  const PixelWalk queries{op.g, op.rows, q_ptr, -1, b.y, b.x0, 0};
  const Operand<float> qo{q, op.H * 16, 16, 1}, dout_o{dout, op.H * 16, 16, 1};
  const Operand<float> ko{k, op.H * 16, 16, 1}, vo{v, op.H * 16, 16, 1};
  forward_block<float, 1, 16, 16, 32, 0>(op, b, lq, keys, h, qo, kt, vt, out, lse_out);
  const Output<float> dq_o{dq, op.H * 16, 16, 1}, dk_o{dk, op.H * 16, 16, 1}, dv_o{dv, op.H * 16, 16, 1};
  backward_dq_block<float, 1, 16, 16, 32, 0>(op, b, lq, keys, h, qo, dout_o, lse, delta, kt, vt, dq_o);
  backward_dkdv_block<float, 1, 16, 16, 32, 0>(op, b, lk, queries, h, qst, dost, lse, delta, ko, vo, dk_o, dv_o,
                                            dbias_lanes);
}
"""


@pytest.mark.skipif(shutil.which("nvcc") is None, reason="nvcc (CUDA toolkit) is not installed")
def test_rana_math_compiles_as_device_code(tmp_path):
    src = tmp_path / "smoke.cu"
    src.write_text(SMOKE)
    result = subprocess.run(["nvcc", "-std=c++20", "-arch=sm_80", f"-I{CUDA_DIR}", "-c", str(src), "-o",
                             str(tmp_path / "smoke.o")], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-3000:]
