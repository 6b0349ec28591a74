// Front-to-back "over" composite of sorted deep bins on the CPU (composite_cpu.cpp), for inference-side flattening
// (the flat prior, baselines). Bound into the CPU extension by rana_cpu.cpp.
#pragma once

#include <torch/extension.h>

#include <vector>

// Per pixel p (offsets [P+1]) and block b (float32 [N, k_b] each): sum_i w_i v_i over the pixel's bins with
// w_i = T_i for a premultiplied block and T_i a_i for another, T_i = prod_{j<i} (1 - clamp(a_j, 0, 1)); another
// block's sum is then divided by the pixel's alpha, max(sum_i T_i a_i, eps). Returns one float32 [P, k_b] per block.
std::vector<torch::Tensor> composite_blocks(std::vector<torch::Tensor> blocks, std::vector<bool> premultiplied,
                                            torch::Tensor alpha, torch::Tensor offsets, double eps);
