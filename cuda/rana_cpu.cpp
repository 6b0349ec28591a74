// CPU (OpenMP) kernels of the RaNA operator and their torch bindings.
//
// Work is organised by pixel: the queries (or keys) of one pixel share their neighbourhood, so they are
// processed together in groups of up to rana::kGroup, and every loaded key (or query) serves the group.
// Forward: online softmax over the disc row blocks (rana_math.h), saving the log-sum-exp; keys are read
// transposed so each block's logits are broadcast-FMAs over consecutive keys.
// Backward (FlashAttention-2 style, probabilities recomputed from the log-sum-exp):
//   pass 1, per group of queries: dQ;
//   pass 2, per chunk of key pixels: dK and dV of every key bin from its reverse neighbourhood (queries
//           sorted by centre pixel and transposed), plus the bias gradient of the chunk.
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
  int64_t nq, H, dk, dv;
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
  TORCH_CHECK(q.size(2) <= rana::kMaxDim && v.size(2) <= rana::kMaxDim, "head dimensions above ", rana::kMaxDim,
              " are not supported");
  for (const auto* t : {&q, &k, &v, &q_pixels, &k_offsets})
    TORCH_CHECK(t->is_contiguous() && t->device().is_cpu(), "inputs must be contiguous CPU tensors");
}

Problem make_problem(const torch::Tensor& q, const torch::Tensor& k, const torch::Tensor& v,
                     const torch::Tensor& k_offsets, int64_t Hk, int64_t Wk, const torch::Tensor& rows_dy,
                     const torch::Tensor& rows_dx0, const torch::Tensor& rows_dx1, int64_t R) {
  Problem pb;
  pb.nq = q.size(0);
  pb.H = q.size(1);
  pb.dk = q.size(2);
  pb.dv = v.size(2);
  pb.grid = Grid{k_offsets.data_ptr<int64_t>(), Hk, Wk};
  pb.rows = DiscRows{int(rows_dy.numel()), int(R), rows_dy.data_ptr<int32_t>(), rows_dx0.data_ptr<int32_t>(),
                     rows_dx1.data_ptr<int32_t>()};
  return pb;
}

int threads() { return at::get_num_threads(); }

// [N, H, d] -> [N / kTile + 1, H, d, kTile] (zero padding): the tiled transposed layout of rana_math.h.
// Row j of the result is row order[j] of x when order is given (queries in pixel order). One parallel pass:
// torch's generic strided copy took ~60 ms per operand on a 256x256 layout.
template <typename T>
torch::Tensor transposed(const torch::Tensor& x, const int64_t* order = nullptr) {
  const int64_t n = x.size(0), H = x.size(1), d = x.size(2), tiles = n / rana::kTile + 1;
  auto out = torch::empty({tiles, H, d, rana::kTile}, x.options());
  const T* src = x.data_ptr<T>();
  T* dst = out.data_ptr<T>();
#pragma omp parallel for schedule(static) num_threads(threads())
  for (int64_t tile = 0; tile < tiles; ++tile) {
    T* block = dst + tile * H * d * rana::kTile;
    for (int64_t jj = 0; jj < rana::kTile; ++jj) {
      const int64_t j = tile * rana::kTile + jj;
      if (j >= n) {
        for (int64_t e = 0; e < H * d; ++e) block[e * rana::kTile + jj] = T(0);
        continue;
      }
      const T* row = src + (order ? order[j] : j) * H * d;
      for (int64_t e = 0; e < H * d; ++e) block[e * rana::kTile + jj] = row[e];
    }
  }
  return out;
}

// Queries sorted by centre pixel: CSR over the key grid (ptr[p]..ptr[p+1] index into order), ascending query id
// within a pixel, so every sum over queries runs in a fixed order.
struct QueryIndex {
  std::vector<int64_t> ptr;
  torch::Tensor order;
  bool identity;  // queries already in pixel order (self-attention layouts): no reordered copies needed
};

QueryIndex index_queries(const torch::Tensor& qpix_t, const Grid& g) {
  const int64_t nq = qpix_t.size(0), npix = g.Hk * g.Wk;
  const int64_t* qpix = qpix_t.data_ptr<int64_t>();
  QueryIndex qi{std::vector<int64_t>(npix + 1, 0), torch::empty({nq}, qpix_t.options()), true};
  int64_t* order = qi.order.data_ptr<int64_t>();
  for (int64_t i = 0; i < nq; ++i) qi.ptr[qpix[2 * i] * g.Wk + qpix[2 * i + 1] + 1]++;
  for (int64_t p = 0; p < npix; ++p) qi.ptr[p + 1] += qi.ptr[p];
  std::vector<int64_t> fill(qi.ptr.begin(), qi.ptr.end() - 1);
  for (int64_t i = 0; i < nq; ++i) order[fill[qpix[2 * i] * g.Wk + qpix[2 * i + 1]]++] = i;
  for (int64_t i = 0; i < nq && qi.identity; ++i) qi.identity = order[i] == i;
  return qi;
}

// Runs body(p, first, G) for every pixel p holding entries ptr[p]..ptr[p+1], in groups of at most kGroup
// consecutive entries, pixels spread over the threads.
template <typename F>
void for_each_group(const int64_t* ptr, int64_t npix, F&& body) {
#pragma omp parallel for schedule(dynamic, 16) num_threads(threads())
  for (int64_t p = 0; p < npix; ++p) {
    for (int64_t t = ptr[p]; t < ptr[p + 1]; t += rana::kGroup) {
      const int n = int(std::min<int64_t>(rana::kGroup, ptr[p + 1] - t));
      body(p, t, n);
    }
  }
}

template <typename T, int DK, int DV>
void forward_impl(const Problem& pb, const T* q, const T* Kt, const T* v, const QueryIndex& qi, const T* bias,
                  T scale, T* out, T* lse) {
  const int H = int(pb.H), dk = int(pb.dk), dv = int(pb.dv);
  const Grid& g = pb.grid;
  const int64_t* order = qi.order.data_ptr<int64_t>();
  for_each_group(qi.ptr.data(), g.Hk * g.Wk, [&](int64_t p, int64_t first, int n) {
    alignas(64) T s[rana::kGroup * rana::kStride];
    rana::Segment seg[rana::kMaxSegments];
    rana::with_group_size(n, [&]<int G>() {
      const T* q_g[G];
      T* out_g[G];
      T lse_g[G];
      for (int h = 0; h < H; ++h) {
        for (int gi = 0; gi < G; ++gi) {
          q_g[gi] = q + (order[first + gi] * H + h) * dk;
          out_g[gi] = out + (order[first + gi] * H + h) * dv;
        }
        rana::forward_group_head<T, DK, DV, G>(q_g, Kt, v, g, pb.rows, bias, p / g.Wk, p % g.Wk, h, H, dk, dv, scale,
                                               out_g, lse_g, s, seg);
        for (int gi = 0; gi < G; ++gi) lse[order[first + gi] * H + h] = lse_g[gi];
      }
    });
  });
}

template <typename T, int DK, int DV>
void backward_impl(const Problem& pb, const torch::Tensor& q_t, const torch::Tensor& k_t, const torch::Tensor& v_t,
                   const torch::Tensor& dout_t, const torch::Tensor& lse_t, const torch::Tensor& delta_t,
                   const QueryIndex& qi, const T* bias, T scale, T* dq, T* dk_out, T* dv_out, T* dbias) {
  const int H = int(pb.H), dk = int(pb.dk), dv = int(pb.dv);
  const Grid& g = pb.grid;
  const int64_t npix = g.Hk * g.Wk;
  const int64_t* order = qi.order.data_ptr<int64_t>();
  // queries with an empty disc: lse +inf gives them probability 0 everywhere below
  auto lse_pos = torch::where(torch::isinf(lse_t), torch::full_like(lse_t, INFINITY), lse_t).contiguous();
  const T* q = q_t.data_ptr<T>();
  const T* k = k_t.data_ptr<T>();
  const T* v = v_t.data_ptr<T>();
  const T* dout = dout_t.data_ptr<T>();
  const T* lse = lse_pos.data_ptr<T>();
  const T* delta = delta_t.data_ptr<T>();

  // pass 1: dQ, per group of queries of one pixel
  {
    torch::Tensor Kt_t = transposed<T>(k_t), Vt_t = transposed<T>(v_t);
    const T* Kt = Kt_t.data_ptr<T>();
    const T* Vt = Vt_t.data_ptr<T>();
    for_each_group(qi.ptr.data(), npix, [&](int64_t p, int64_t first, int n) {
      alignas(64) T s[rana::kGroup * rana::kStride];
      alignas(64) T t[rana::kGroup * rana::kStride];
      rana::Segment seg[rana::kMaxSegments];
      rana::with_group_size(n, [&]<int G>() {
        const T *q_g[G], *do_g[G];
        T* dq_g[G];
        T lse_g[G], delta_g[G];
        for (int h = 0; h < H; ++h) {
          for (int gi = 0; gi < G; ++gi) {
            const int64_t i = order[first + gi];
            q_g[gi] = q + (i * H + h) * dk;
            do_g[gi] = dout + (i * H + h) * dv;
            dq_g[gi] = dq + (i * H + h) * dk;
            lse_g[gi] = lse[i * H + h];
            delta_g[gi] = delta[i * H + h];
          }
          rana::backward_dq_group_head<T, DK, DV, G>(q_g, do_g, lse_g, delta_g, Kt, Vt, k, g, pb.rows, bias, p / g.Wk,
                                                     p % g.Wk, h, H, dk, dv, scale, dq_g, s, t, seg);
        }
      });
    });
  }

  // pass 2: dK, dV per group of keys of one pixel; the queries' operands in pixel order
  const int64_t ldq = pb.nq + rana::kLanes;
  auto qs_t = qi.identity ? q_t : q_t.index_select(0, qi.order);
  auto dos_t = qi.identity ? dout_t : dout_t.index_select(0, qi.order);
  torch::Tensor Qt_t = transposed<T>(q_t, qi.identity ? nullptr : order);
  torch::Tensor dOt_t = transposed<T>(dout_t, qi.identity ? nullptr : order);
  auto lse_s = torch::full({pb.H, ldq}, INFINITY, q_t.options());
  auto delta_s = torch::zeros({pb.H, ldq}, q_t.options());
  lse_s.narrow(1, 0, pb.nq).copy_(lse_pos.index_select(0, qi.order).t());
  delta_s.narrow(1, 0, pb.nq).copy_(delta_t.index_select(0, qi.order).t());
  const T* qs = qs_t.data_ptr<T>();
  const T* dos = dos_t.data_ptr<T>();
  const T* Qt = Qt_t.data_ptr<T>();
  const T* dOt = dOt_t.data_ptr<T>();
  const T* lse_sp = lse_s.data_ptr<T>();
  const T* delta_sp = delta_s.data_ptr<T>();
  // the bias gradient is summed per chunk of key pixels, then over chunks in order (thread-count independent)
  const int side = 2 * pb.rows.R + 1;
  const int64_t bias_size = int64_t(H) * side * side;
  const int64_t nchunks = (npix + kKeyPixelsPerChunk - 1) / kKeyPixelsPerChunk;
  std::vector<T> partial(dbias ? nchunks * bias_size : 0, T(0));
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads())
  for (int64_t c = 0; c < nchunks; ++c) {
    alignas(64) T s[rana::kGroup * rana::kStride];
    alignas(64) T t[rana::kGroup * rana::kStride];
    alignas(64) T L[rana::kStride];
    alignas(64) T D[rana::kStride];
    rana::Segment seg[rana::kMaxSegments];
    T* part = dbias ? partial.data() + c * bias_size : nullptr;
    const int64_t pe = std::min(npix, (c + 1) * kKeyPixelsPerChunk);
    for (int64_t p = c * kKeyPixelsPerChunk; p < pe; ++p) {
      for (int64_t first = g.offsets[p]; first < g.offsets[p + 1]; first += rana::kGroup) {
        const int n = int(std::min<int64_t>(rana::kGroup, g.offsets[p + 1] - first));
        rana::with_group_size(n, [&]<int G>() {
          const T *k_g[G], *v_g[G];
          T *dk_g[G], *dv_g[G];
          for (int h = 0; h < H; ++h) {
            for (int gi = 0; gi < G; ++gi) {
              const int64_t j = first + gi;
              k_g[gi] = k + (j * H + h) * dk;
              v_g[gi] = v + (j * H + h) * dv;
              dk_g[gi] = dk_out + (j * H + h) * dk;
              dv_g[gi] = dv_out + (j * H + h) * dv;
            }
            rana::backward_dkdv_group_head<T, DK, DV, G>(
                k_g, v_g, Qt, dOt, qs, dos, lse_sp + h * ldq, delta_sp + h * ldq, qi.ptr.data(), g, pb.rows, bias,
                p / g.Wk, p % g.Wk, h, H, dk, dv, scale, dk_g, dv_g, part ? part + int64_t(h) * side * side : nullptr,
                s, t, L, D, seg);
          }
        });
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
  const QueryIndex qi = index_queries(q_pixels, pb.grid);
  auto out = torch::empty({pb.nq, pb.H, pb.dv}, q.options());
  auto lse = torch::empty({pb.nq, pb.H}, q.options());
  AT_DISPATCH_FLOATING_TYPES(q.scalar_type(), "rana_forward", [&] {
    const scalar_t* b = bias.has_value() ? bias->data_ptr<scalar_t>() : nullptr;
    dispatch_dims(pb.dk, pb.dv, [&]<int DK, int DV>() {
      torch::Tensor Kt = transposed<scalar_t>(k);
      forward_impl<scalar_t, DK, DV>(pb, q.data_ptr<scalar_t>(), Kt.data_ptr<scalar_t>(), v.data_ptr<scalar_t>(), qi, b,
                                     scalar_t(scale), out.data_ptr<scalar_t>(), lse.data_ptr<scalar_t>());
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
  const QueryIndex qi = index_queries(q_pixels, pb.grid);
  auto dq = torch::empty_like(q);
  auto dk = torch::empty_like(k);
  auto dv = torch::empty_like(v);
  const int64_t side = 2 * R + 1;
  auto dbias = need_dbias ? torch::empty({pb.H, side, side}, q.options()) : torch::Tensor();
  AT_DISPATCH_FLOATING_TYPES(q.scalar_type(), "rana_backward", [&] {
    const scalar_t* b = bias.has_value() ? bias->data_ptr<scalar_t>() : nullptr;
    dispatch_dims(pb.dk, pb.dv, [&]<int DK, int DV>() {
      backward_impl<scalar_t, DK, DV>(pb, q, k, v, dout, lse, delta, qi, b, scalar_t(scale),
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
