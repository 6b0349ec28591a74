// Helpers shared by the torch bindings of the CPU kernels (rana_cpu.cpp) and the CUDA kernels (rana_cuda.cpp):
// input checks, the operands' layouts, and padding to the head sizes the kernels are compiled for.
#pragma once

#include <torch/extension.h>

#include "rana_math.h"

namespace rana_binding {

using rana::kScalarLaneDim;


inline void check_inputs(const torch::Tensor& q, const torch::Tensor& k, const torch::Tensor& v,
                  const torch::Tensor& q_pixels, const torch::Tensor& k_offsets, int64_t Hk, int64_t Wk) {
  TORCH_CHECK(q.dim() == 3 && k.dim() == 3 && v.dim() == 3, "q, k, v must be [N, heads, d]");
  TORCH_CHECK(q.size(1) == k.size(1) && k.size(1) == v.size(1), "q, k, v must have the same heads");
  TORCH_CHECK(q.size(2) == k.size(2), "q and k must have the same head dimension");
  TORCH_CHECK(k.size(0) == v.size(0), "k and v must have the same number of bins");
  TORCH_CHECK(q.scalar_type() == k.scalar_type() && k.scalar_type() == v.scalar_type(), "dtype mismatch");
  TORCH_CHECK(q_pixels.dim() == 2 && q_pixels.size(0) == q.size(0) && q_pixels.size(1) == 2,
              "q_pixels must be [Nq, 2]");
  TORCH_CHECK(k_offsets.numel() == Hk * Wk + 1, "k_offsets must have Hk*Wk+1 entries");
  TORCH_CHECK(q.size(2) <= rana::kMaxDim && v.size(2) <= rana::kMaxDim, "head dimensions above ", rana::kMaxDim,
              " are not supported");
  for (const auto* t : {&q_pixels, &k_offsets})
    TORCH_CHECK(t->is_contiguous() && t->device() == q.device(), "q_pixels and k_offsets must be contiguous and on q's device");
  for (const auto* t : {&q, &k, &v})
    TORCH_CHECK(t->device() == q.device() && (t->is_contiguous() || t->transpose(1, 2).is_contiguous()),
                "q, k, v must be on one device, contiguous [N, H, d] or channel-major (a transposed [N, d, H])");
}

// q, k, v may come channel-major (the transposed view of a contiguous [N, d, H] tensor, as a projection can write
// them): then the kernels stream them without the copy.
inline bool is_channel_major(const torch::Tensor& x) { return !x.is_contiguous() && x.transpose(1, 2).is_contiguous(); }

template <typename T>
rana::Operand<T> operand(const torch::Tensor& x) {
  return rana::Operand<T>{x.data_ptr<T>(), x.stride(0), x.stride(1), x.stride(2)};
}

template <typename T>
rana::Output<T> output(torch::Tensor& x) {
  return rana::Output<T>{x.data_ptr<T>(), x.stride(0), x.stride(1), x.stride(2)};
}

// An [n, H, d] gradient in the layout of its input (autograd would otherwise copy it into that layout), allocated
// by empty(sizes, options).
template <typename Empty>
torch::Tensor empty_like_layout(const torch::Tensor& like, int64_t n, int64_t H, int64_t d, Empty&& empty) {
  if (is_channel_major(like)) return empty({n, d, H}, like.options()).transpose(1, 2);
  return empty({n, H, d}, like.options());
}
inline torch::Tensor empty_like_layout(const torch::Tensor& like, int64_t n, int64_t H, int64_t d) {
  return empty_like_layout(like, n, H, d, [](at::IntArrayRef s, const torch::TensorOptions& o) {
    return torch::empty(s, o);
  });
}

// How a call runs: heads per block, and the padded sizes the kernels are compiled for.
struct Plan {
  bool scalar;  // one lane per block
  int HB;
  int64_t H, dk, dv;  // padded
};

inline Plan plan_for(int64_t H, int64_t dk, int64_t dv, bool is_double, bool scalar_lanes) {
  if (scalar_lanes) {
    TORCH_CHECK(dk <= kScalarLaneDim && dv <= kScalarLaneDim,
                "one-lane blocks: head dimensions up to 16");
    return Plan{true, 1, H, kScalarLaneDim, kScalarLaneDim};
  }
  if (is_double)
    return Plan{false, 1, H, dk <= 16 ? 16 : 64, dv <= 3 ? 3 : dv <= 16 ? 16 : 64};
  const int64_t pdk = dk <= 8 ? 8 : dk <= 16 ? 16 : dk <= 32 ? 32 : 64;
  const int64_t pdv = dv <= 3 ? 3 : dv <= 8 ? 8 : dv <= 16 ? 16 : dv <= 32 ? 32 : 64;
  if (H == 1) return Plan{false, 1, 1, pdk, pdv};
  // two heads: blocks of 2 heads (twice the entries per block), rather than padding to 4 heads, half of them zero
  if (H == 2) return Plan{false, 2, 2, pdk, pdv};
  return Plan{false, 4, (H + 3) / 4 * 4, pdk, pdv};
}

// [N, h, c] -> [N, H, d], zero heads and channels appended; keeps a channel-major view as it is when no padding
// is needed
inline torch::Tensor pad_to(const torch::Tensor& x, int64_t H, int64_t d) {
  if (x.size(1) == H && x.size(2) == d) return x;
  return torch::constant_pad_nd(x, {0, d - x.size(2), 0, H - x.size(1)}, 0).contiguous();
}

inline torch::Tensor pad_heads(const torch::Tensor& x, int64_t H, double fill) {
  if (x.size(1) == H) return x;
  return torch::constant_pad_nd(x, {0, H - x.size(1)}, fill).contiguous();
}

inline torch::Tensor unpad(const torch::Tensor& x, int64_t H, int64_t d) {
  if (x.size(1) == H && x.size(2) == d) return x;
  return x.narrow(1, 0, H).narrow(2, 0, d).contiguous();
}

}  // namespace rana_binding
