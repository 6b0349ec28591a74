// Fused per-bin layers for inference on the CPU (rows_cpu.cpp): float32, contiguous [N, C] rows, weights transposed
// ([C_in, C_out]). Bound into the CPU extension by rana_cpu.cpp.
#pragma once

#include <torch/extension.h>

#include <vector>

// [LayerNorm(x)] wt + bias, returned as contiguous column blocks of the given widths (e.g. q, k and v).
std::vector<torch::Tensor> rows_ln_linear(torch::Tensor x, c10::optional<torch::Tensor> ln_w,
                                          c10::optional<torch::Tensor> ln_b, double eps, torch::Tensor wt,
                                          torch::Tensor bias, std::vector<int64_t> splits);

// res + y1 wt1 [+ y2 wt2] + bias: a projection (or the merge of two inputs) added to the residual stream.
torch::Tensor rows_linear_residual(torch::Tensor res, torch::Tensor y1, torch::Tensor wt1,
                                   c10::optional<torch::Tensor> y2, c10::optional<torch::Tensor> wt2,
                                   torch::Tensor bias);

// [x +] ReLU([LayerNorm(x)] wt1 + b1) wt2 + b2: a RaNA block's MLP branch with its residual, or the input embedding.
torch::Tensor rows_mlp(torch::Tensor x, c10::optional<torch::Tensor> ln_w, c10::optional<torch::Tensor> ln_b,
                       double eps, torch::Tensor wt1, torch::Tensor b1, torch::Tensor wt2, torch::Tensor b2,
                       bool residual);

// A reconstruction kernel's wide q or k operand, channel-major [N, wide, heads]: the projection [N, d * heads] (itself
// channel-major) times scale, then each of the terms [N, e] times term_scale on every head, then zeros (the range and
// layer-gate terms of reconstruction.KernelAttention._with_range, in one pass instead of one per block of columns).
torch::Tensor rows_wide_operand(torch::Tensor proj, int64_t heads, double scale, torch::Tensor terms,
                                double term_scale, int64_t wide);

// sum_s softmax(feat wt + bias)[:, s] * outs[s]: a reconstruction's scale mixer (a linear layer, a softmax over each
// row's few scales, the per-bin convex mix of the scales' results) in one pass; each row by one thread, in a fixed
// order, so the weights do not depend on the thread count.
torch::Tensor rows_scale_mix(torch::Tensor feat, torch::Tensor wt, torch::Tensor bias,
                             std::vector<torch::Tensor> outs);

// torch.cat(parts, 1) for contiguous float32 [N, c_k] parts: one pass over the rows, a tile of rows at a time (torch's
// cat of many narrow parts, e.g. a bin's 45 input features from blocks of 1-16 columns, wrote 95 MB in 60 ms).
torch::Tensor rows_concat(std::vector<torch::Tensor> parts);

// [|a[qi] - b[kj]|, a[qi] * b[kj]] for every pair p of row indices (qi[p], kj[p]): the matching step's pair features
// (model/matching.py) in one pass, without the gathered rows and the difference, its absolute value and the product as
// four tensors of their own (torch's six passes over them took 86 ms for 0.63 M pairs of 16 columns, mostly page
// faults of the fresh memory).
torch::Tensor rows_pair_features(torch::Tensor a, torch::Tensor b, torch::Tensor qi, torch::Tensor kj);

// out[q] = sum of w[p] * v[kj[p]] over the pairs p of query q (qi ascending), each product rounded and added in pair
// order from 0: torch's zeros(queries, C).index_add(0, qi, w[:, None] * v[kj]) bit for bit, in one pass without the
// gathered values and products (the matching step's weighted sum, model/matching.py).
torch::Tensor rows_pair_sum(torch::Tensor w, torch::Tensor v, torch::Tensor qi, torch::Tensor kj, int64_t queries);
