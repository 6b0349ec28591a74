"""The kernel maths in cuda/rana_math.h must compile as CUDA device code too (the GPU kernels reuse it).

Compile-only (no GPU needed): a smoke kernel calling the forward, dQ and dK/dV group bodies with G = 1 is
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
__global__ void smoke(const float* q, const float* Kt, const float* Vt, const float* k, const float* v,
                      const float* dout, const float* lse, const float* delta, Grid g, DiscRows rows,
                      const float* bias, const int64_t* qpix, const int64_t* q_ptr, float* out, float* lse_out,
                      float* dq, float* dk, float* dv, float* dbias, int n) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  float s[kStride], t[kStride], L[kStride], D[kStride];
  Segment seg[kMaxSegments];
  const float* qg[1] = {q + i * 16};
  const float* dg[1] = {dout + i * 16};
  float* og[1] = {out + i * 16};
  float* dqg[1] = {dq + i * 16};
  float* dkg[1] = {dk + i * 16};
  float* dvg[1] = {dv + i * 16};
  forward_group_head<float, 16, 16, 1>(qg, Kt, v, g, rows, bias, qpix[2 * i], qpix[2 * i + 1], 0, 1, 16, 16, 0.25f,
                                       og, lse_out + i, s, seg);
  backward_dq_group_head<float, 16, 16, 1>(qg, dg, lse + i, delta + i, Kt, Vt, k, g, rows, bias, qpix[2 * i],
                                           qpix[2 * i + 1], 0, 1, 16, 16, 0.25f, dqg, s, t, seg);
  const float* kg[1] = {k + i * 16};
  const float* vg[1] = {v + i * 16};
  backward_dkdv_group_head<float, 16, 16, 1>(kg, vg, Kt, Vt, q, dout, lse, delta, q_ptr, g, rows, bias, qpix[2 * i],
                                             qpix[2 * i + 1], 0, 1, 16, 16, 0.25f, dkg, dvg, dbias, s, t, L, D, seg);
}
"""


@pytest.mark.skipif(shutil.which("nvcc") is None, reason="nvcc (CUDA toolkit) is not installed")
def test_rana_math_compiles_as_device_code(tmp_path):
    src = tmp_path / "smoke.cu"
    src.write_text(SMOKE)
    result = subprocess.run(["nvcc", "-std=c++20", "-arch=sm_80", f"-I{CUDA_DIR}", "-c", str(src), "-o",
                             str(tmp_path / "smoke.o")], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-3000:]
