// CPU (OpenMP) kernels of the RaNA operator and their torch bindings.
//
// Forward: one task per query, all heads, online softmax over the disc row blocks (rana_math.h), saving
// the log-sum-exp; keys are read transposed so each block's logits are broadcast-FMAs over consecutive keys.
// Backward (FlashAttention-2 style, probabilities recomputed from the log-sum-exp):
//   pass 1, one task per query: dQ;
//   pass 2, one task per chunk of key pixels: dK and dV of every key bin from its reverse neighbourhood
//           (queries sorted by centre pixel and transposed), plus the bias gradient of the chunk.
// Every output element is summed by one task in a fixed order and the bias gradient is reduced over a
// fixed number of chunks in order, so results do not depend on the number of threads or the schedule.
#include <torch/extension.h>

#include <omp.h>

#include <vector>

#include "rana_math.h"

namespace {

using rana::DiscRows;
using rana::Grid;

constexpr int64_t kKeyPixelsPerChunk = 256;

struct Problem {
  int64_t nq, nk, H, dk, dv;
  Grid grid;
  DiscRows rows;
};

void check_inputs(const torch::Tensor& q, const torch::Tensor& k, const torch::Tensor& v,
                  const torch::Tensor& q_pixels, const torch::Tensor& k_offsets, int64_t Hk, int64_t Wk) {
  TORCH_CHECK(q.dim() == 3 && k.dim() == 3 && v.dim() == 3, "q, k, v must be [N, heads, d]");
  TORCH_CHECK(q.size(1) == k.size(1) && k.size(1) == v.size(1), "q, k, v must have the same heads");
  TORCH_CHECK(q.size(2) == k.size(2), "q and k must have the same head dimension");
  TORCH_CHECK(k.size(0) == v.size(0), "k and v must have the same number of bins");
  TORCH_CHECK(q.scalar_type() == k.scalar_type() && k.scalar_type() == v.scalar_type(), "dtype mismatch");
  TORCH_CHECK(q_pixels.dim() == 2 && q_pixels.size(0) == q.size(0) && q_pixels.size(1) == 2,
              "q_pixels must be [Nq, 2]");
  TORCH_CHECK(k_offsets.numel() == Hk * Wk + 1, "k_offsets must have Hk*Wk+1 entries");
  for (const auto* t : {&q, &k, &v, &q_pixels, &k_offsets})
    TORCH_CHECK(t->is_contiguous() && t->device().is_cpu(), "inputs must be contiguous CPU tensors");
}

Problem make_problem(const torch::Tensor& q, const torch::Tensor& k, const torch::Tensor& v,
                     const torch::Tensor& k_offsets, int64_t Hk, int64_t Wk, const torch::Tensor& rows_dy,
                     const torch::Tensor& rows_dx0, const torch::Tensor& rows_dx1, int64_t R) {
  Problem pb;
  pb.nq = q.size(0);
  pb.nk = k.size(0);
  pb.H = q.size(1);
  pb.dk = q.size(2);
  pb.dv = v.size(2);
  pb.grid = Grid{k_offsets.data_ptr<int64_t>(), Hk, Wk};
  pb.rows = DiscRows{int(rows_dy.numel()), int(R), rows_dy.data_ptr<int32_t>(), rows_dx0.data_ptr<int32_t>(),
                     rows_dx1.data_ptr<int32_t>()};
  return pb;
}

int threads() { return at::get_num_threads(); }

// [N, H, d] -> [N / kTile + 1, H, d, kTile] (zero padding): the tiled transposed layout of rana_math.h
torch::Tensor transposed(const torch::Tensor& x) {
  const int64_t n = x.size(0), tiles = n / rana::kTile + 1;
  auto padded = torch::zeros({tiles * rana::kTile, x.size(1), x.size(2)}, x.options());
  padded.narrow(0, 0, n).copy_(x);
  return padded.view({tiles, rana::kTile, x.size(1), x.size(2)}).permute({0, 2, 3, 1}).contiguous();
}

template <typename T, int DK, int DV>
void forward_impl(const Problem& pb, const T* q, const T* Kt, const T* v, const int64_t* qpix, const T* bias,
                  T scale, T* out, T* lse) {
  const int H = int(pb.H), dk = int(pb.dk), dv = int(pb.dv);
#pragma omp parallel num_threads(threads())
  {
    alignas(64) T s[rana::kBuffer + rana::kLanes];
    rana::Segment seg[rana::kMaxSegments];
#pragma omp for schedule(dynamic, 32)
    for (int64_t i = 0; i < pb.nq; ++i) {
      const int64_t y = qpix[2 * i], x = qpix[2 * i + 1];
      for (int h = 0; h < H; ++h) {
        lse[i * H + h] = rana::forward_query_head<T, DK, DV>(q + (i * H + h) * dk, Kt, v,
                                                             pb.grid, pb.rows, bias, y, x, h, H, dk, dv, scale,
                                                             out + (i * H + h) * dv, s, seg);
      }
    }
  }
}

template <typename T, int DK, int DV>
void backward_impl(const Problem& pb, const torch::Tensor& q_t, const torch::Tensor& k_t, const torch::Tensor& v_t,
                   const torch::Tensor& dout_t, const torch::Tensor& lse_t, const torch::Tensor& delta_t,
                   const torch::Tensor& qpix_t, const T* bias, T scale, T* dq, T* dk_out, T* dv_out, T* dbias) {
  const int H = int(pb.H), dk = int(pb.dk), dv = int(pb.dv);
  const Grid& g = pb.grid;
  const T* q = q_t.data_ptr<T>();
  const T* k = k_t.data_ptr<T>();
  const T* dout = dout_t.data_ptr<T>();
  const T* lse = lse_t.data_ptr<T>();
  const T* delta = delta_t.data_ptr<T>();
  const int64_t* qpix = qpix_t.data_ptr<int64_t>();
  const int64_t ldq = pb.nq + rana::kLanes;

  // pass 1: dQ, one task per query
  {
    auto Kt_t = transposed(k_t), Vt_t = transposed(v_t);
    const T* Kt = Kt_t.data_ptr<T>();
    const T* Vt = Vt_t.data_ptr<T>();
#pragma omp parallel num_threads(threads())
    {
      alignas(64) T s[rana::kBuffer + rana::kLanes];
      alignas(64) T t[rana::kBuffer + rana::kLanes];
      rana::Segment seg[rana::kMaxSegments];
#pragma omp for schedule(dynamic, 32)
      for (int64_t i = 0; i < pb.nq; ++i) {
        const int64_t y = qpix[2 * i], x = qpix[2 * i + 1];
        for (int h = 0; h < H; ++h) {
          rana::backward_dq_head<T, DK, DV>(q + (i * H + h) * dk, Kt, Vt, k, dout + (i * H + h) * dv,
                                            lse[i * H + h], delta[i * H + h], g, pb.rows, bias, y, x, h, H, dk, dv,
                                            scale, dq + (i * H + h) * dk, s, t, seg);
        }
      }
    }
  }

  // queries sorted by centre pixel (CSR; ascending query id within a pixel: a fixed summation order)
  const int64_t npix = g.Hk * g.Wk;
  std::vector<int64_t> q_ptr(npix + 1, 0);
  auto order_t = torch::empty({pb.nq}, qpix_t.options());
  int64_t* order = order_t.data_ptr<int64_t>();
  for (int64_t i = 0; i < pb.nq; ++i) q_ptr[qpix[2 * i] * g.Wk + qpix[2 * i + 1] + 1]++;
  for (int64_t p = 0; p < npix; ++p) q_ptr[p + 1] += q_ptr[p];
  {
    std::vector<int64_t> fill(q_ptr.begin(), q_ptr.end() - 1);
    for (int64_t i = 0; i < pb.nq; ++i) order[fill[qpix[2 * i] * g.Wk + qpix[2 * i + 1]]++] = i;
  }
  auto qs_t = q_t.index_select(0, order_t), dos_t = dout_t.index_select(0, order_t);
  auto Qt_t = transposed(qs_t), dOt_t = transposed(dos_t);
  // [H, Nq + pad]: +inf log-sum-exp for padding and for queries with an empty disc (probability 0)
  auto lse_s = torch::full({pb.H, ldq}, INFINITY, q_t.options());
  auto delta_s = torch::zeros({pb.H, ldq}, q_t.options());
  {
    auto l = lse_t.index_select(0, order_t).t();
    lse_s.narrow(1, 0, pb.nq).copy_(torch::where(torch::isinf(l), torch::full_like(l, INFINITY), l));
    delta_s.narrow(1, 0, pb.nq).copy_(delta_t.index_select(0, order_t).t());
  }
  const T* qs = qs_t.data_ptr<T>();
  const T* dos = dos_t.data_ptr<T>();
  const T* Qt = Qt_t.data_ptr<T>();
  const T* dOt = dOt_t.data_ptr<T>();
  const T* lse_sp = lse_s.data_ptr<T>();
  const T* delta_sp = delta_s.data_ptr<T>();
  const T* v = v_t.data_ptr<T>();

  // pass 2: dK, dV per key bin; bias gradient per chunk of key pixels, reduced in chunk order
  const int side = 2 * pb.rows.R + 1;
  const int64_t bias_size = int64_t(H) * side * side;
  const int64_t nchunks = (npix + kKeyPixelsPerChunk - 1) / kKeyPixelsPerChunk;
  std::vector<T> partial(dbias ? nchunks * bias_size : 0, T(0));
#pragma omp parallel num_threads(threads())
  {
    alignas(64) T s[rana::kBuffer + rana::kLanes];
    alignas(64) T t[rana::kBuffer + rana::kLanes];
    alignas(64) T L[rana::kBuffer + rana::kLanes];
    alignas(64) T D[rana::kBuffer + rana::kLanes];
    rana::Segment seg[rana::kMaxSegments];
#pragma omp for schedule(dynamic, 1)
    for (int64_t c = 0; c < nchunks; ++c) {
      T* part = dbias ? partial.data() + c * bias_size : nullptr;
      const int64_t pe = std::min(npix, (c + 1) * kKeyPixelsPerChunk);
      for (int64_t p = c * kKeyPixelsPerChunk; p < pe; ++p) {
        const int64_t ky = p / g.Wk, kx = p % g.Wk;
        for (int64_t j = g.offsets[p]; j < g.offsets[p + 1]; ++j) {
          for (int h = 0; h < H; ++h) {
            rana::backward_dkdv_head<T, DK, DV>(
                k + (j * H + h) * dk, v + (j * H + h) * dv, Qt, dOt, qs, dos, lse_sp + h * ldq, delta_sp + h * ldq, q_ptr.data(), g, pb.rows, bias, ky, kx, h, H, dk,
                dv, scale, dk_out + (j * H + h) * dk, dv_out + (j * H + h) * dv,
                part ? part + int64_t(h) * side * side : nullptr, s, t, L, D, seg);
          }
        }
      }
    }
  }
  if (dbias) {
    for (int64_t e = 0; e < bias_size; ++e) dbias[e] = T(0);
    for (int64_t c = 0; c < nchunks; ++c)
      for (int64_t e = 0; e < bias_size; ++e) dbias[e] += partial[c * bias_size + e];
  }
}

// Calls f.template operator()<DK, DV>() with compile-time head dimensions for the common sizes
// (so the inner loops are fully unrolled and vectorised) and 0 (run-time sizes) otherwise.
template <typename F>
void dispatch_dims(int64_t dk, int64_t dv, F&& f) {
  if (dk == 16 && dv == 16) return f.template operator()<16, 16>();
  if (dk == 8 && dv == 8) return f.template operator()<8, 8>();
  if (dk == 32 && dv == 32) return f.template operator()<32, 32>();
  if (dk == 16 && dv == 3) return f.template operator()<16, 3>();
  return f.template operator()<0, 0>();
}

std::vector<torch::Tensor> rana_forward(torch::Tensor q, torch::Tensor k, torch::Tensor v, torch::Tensor q_pixels,
                                        torch::Tensor k_offsets, int64_t Hk, int64_t Wk, torch::Tensor rows_dy,
                                        torch::Tensor rows_dx0, torch::Tensor rows_dx1, int64_t R,
                                        c10::optional<torch::Tensor> bias, double scale) {
  check_inputs(q, k, v, q_pixels, k_offsets, Hk, Wk);
  const Problem pb = make_problem(q, k, v, k_offsets, Hk, Wk, rows_dy, rows_dx0, rows_dx1, R);
  auto out = torch::empty({pb.nq, pb.H, pb.dv}, q.options());
  auto lse = torch::empty({pb.nq, pb.H}, q.options());
  AT_DISPATCH_FLOATING_TYPES(q.scalar_type(), "rana_forward", [&] {
    const scalar_t* b = bias.has_value() ? bias->data_ptr<scalar_t>() : nullptr;
    dispatch_dims(pb.dk, pb.dv, [&]<int DK, int DV>() {
      auto Kt = transposed(k);
      forward_impl<scalar_t, DK, DV>(pb, q.data_ptr<scalar_t>(), Kt.data_ptr<scalar_t>(), v.data_ptr<scalar_t>(),
                                     q_pixels.data_ptr<int64_t>(), b, scalar_t(scale), out.data_ptr<scalar_t>(),
                                     lse.data_ptr<scalar_t>());
    });
  });
  return {out, lse};
}

std::vector<torch::Tensor> rana_backward(torch::Tensor dout, torch::Tensor q, torch::Tensor k, torch::Tensor v,
                                         torch::Tensor lse, torch::Tensor delta, torch::Tensor q_pixels,
                                         torch::Tensor k_offsets, int64_t Hk, int64_t Wk, torch::Tensor rows_dy,
                                         torch::Tensor rows_dx0, torch::Tensor rows_dx1, int64_t R,
                                         c10::optional<torch::Tensor> bias, double scale, bool need_dbias) {
  check_inputs(q, k, v, q_pixels, k_offsets, Hk, Wk);
  TORCH_CHECK(dout.is_contiguous() && lse.is_contiguous() && delta.is_contiguous(), "grads must be contiguous");
  const Problem pb = make_problem(q, k, v, k_offsets, Hk, Wk, rows_dy, rows_dx0, rows_dx1, R);
  auto dq = torch::empty_like(q);
  auto dk = torch::empty_like(k);
  auto dv = torch::empty_like(v);
  const int64_t side = 2 * R + 1;
  auto dbias = need_dbias ? torch::empty({pb.H, side, side}, q.options()) : torch::Tensor();
  AT_DISPATCH_FLOATING_TYPES(q.scalar_type(), "rana_backward", [&] {
    const scalar_t* b = bias.has_value() ? bias->data_ptr<scalar_t>() : nullptr;
    dispatch_dims(pb.dk, pb.dv, [&]<int DK, int DV>() {
      backward_impl<scalar_t, DK, DV>(pb, q, k, v, dout, lse, delta, q_pixels, b, scalar_t(scale),
                                      dq.data_ptr<scalar_t>(), dk.data_ptr<scalar_t>(), dv.data_ptr<scalar_t>(),
                                      need_dbias ? dbias.data_ptr<scalar_t>() : nullptr);
    });
  });
  return {dq, dk, dv, dbias};
}

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("forward", &rana_forward, "RaNA forward (CPU): returns (out, lse)");
  m.def("backward", &rana_backward, "RaNA backward (CPU): returns (dq, dk, dv, dbias)");
}
