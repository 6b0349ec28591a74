// The over composite of sorted deep bins, one pixel per loop iteration (composite_cpu.h).
//
// Why: flatten_torch builds the transmittance from a float64 prefix sum over the whole image (differentiable, with
// exact opaque handling), a dozen passes over [N] and [N, C] arrays; for inference a pixel's bins are a few dozen
// contiguous rows, so one pass with a running product does it (1080p, 2.9 M bins, 10 columns: ~1.2 s -> ~0.05 s).
// T is carried in double; a bin behind an opaque one (alpha >= 1) gets exactly T = 0, as in flatten_torch. Each
// pixel is summed by one thread in bin order: results do not depend on the number of threads.
#include "composite_cpu.h"

#include <omp.h>

#include <algorithm>
#include <vector>

torch::Tensor composite_rows(torch::Tensor values, torch::Tensor offsets, int64_t alpha_col) {
  TORCH_CHECK(values.device().is_cpu() && values.scalar_type() == torch::kFloat && values.dim() == 2 &&
                  values.is_contiguous(),
              "composite_rows values: contiguous float32 CPU [N, C] expected");
  TORCH_CHECK(offsets.device().is_cpu() && offsets.scalar_type() == torch::kLong && offsets.dim() == 1 &&
                  offsets.is_contiguous() && offsets.numel() >= 1,
              "composite_rows offsets: contiguous int64 CPU [P+1] expected");
  const int64_t n = values.size(0), c = values.size(1), p = offsets.numel() - 1;
  TORCH_CHECK(alpha_col >= 0 && alpha_col < c, "composite_rows: alpha column ", alpha_col, " outside ", c);
  const int64_t* off = offsets.data_ptr<int64_t>();
  TORCH_CHECK(off[0] == 0 && off[p] == n, "composite_rows: offsets do not span the ", n, " bins");
  for (int64_t i = 0; i < p; ++i) TORCH_CHECK(off[i] <= off[i + 1], "composite_rows: offsets decrease");
  auto out = torch::empty({p, c}, values.options());
  const float* v = values.data_ptr<float>();
  float* o = out.data_ptr<float>();
#pragma omp parallel num_threads(at::get_num_threads())
  {
    std::vector<double> acc(c);
#pragma omp for schedule(static)
    for (int64_t px = 0; px < p; ++px) {
      std::fill(acc.begin(), acc.end(), 0.0);
      double t = 1.0;
      for (int64_t i = off[px]; i < off[px + 1] && t != 0.0; ++i) {
        const float* row = v + i * c;
        for (int64_t k = 0; k < c; ++k) acc[k] += t * double(row[k]);
        const float a = row[alpha_col];
        t *= 1.0 - double(a >= 1.f ? 1.f : a > 0.f ? a : 0.f);   // a NaN alpha counts as 0
      }
      for (int64_t k = 0; k < c; ++k) o[px * c + k] = float(acc[k]);
    }
  }
  return out;
}
