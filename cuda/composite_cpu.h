// Front-to-back "over" composite of sorted deep bins on the CPU (composite_cpu.cpp), for inference-side flattening
// (the flat prior, baselines). Bound into the CPU extension by rana_cpu.cpp.
#pragma once

#include <torch/extension.h>

// out[p, c] = sum_i values[i, c] T_i over the bins i of pixel p (offsets [P+1]), T_i = prod_{j<i} (1 - a_j) with
// a = values[:, alpha_col] clamped to [0, 1]: float32 [N, C] in, float32 [P, C] out.
torch::Tensor composite_rows(torch::Tensor values, torch::Tensor offsets, int64_t alpha_col);
