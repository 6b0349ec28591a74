// The CPU (OpenMP) RaNA kernels: the block bodies of rana_math.h run over every block of a layout.
//
// Torch-free (raw pointers), so the translation units that instantiate them (rana_cpu_f32*.cpp,
// rana_cpu_other.cpp) compile without torch's headers and in parallel; rana_cpu.cpp binds them to torch.
//
// Work is organised in blocks (rana_math.h): entries of one grid row on at most kMaxSpan + 1 consecutive pixels,
// HB heads of each, one (entry, head) per SIMD lane (L = 16 floats and 8 doubles with AVX-512, half as many on
// other CPUs).
// Forward: online softmax per query block, saving the log-sum-exp.
// Backward (FlashAttention-2 style, probabilities recomputed from the log-sum-exp):
//   pass 1, per query block: dQ;
//   pass 2, per key block: dK and dV from the reverse neighbourhood (queries sorted by centre pixel), plus the
//           bias gradient, summed per fixed chunk of key blocks.
// Every output element is summed by one task in a fixed order and the bias gradient is reduced over the chunks
// in order, so results do not depend on the number of threads or the schedule.
// Head dimensions are compiled in (float: d in 8, 16, 32, 64 for q/k and 3, 8, 16, 32, 64 for v; double: 16, 64
// and 3, 16, 64; one-lane blocks: 16); the bindings pad other sizes with zero channels, which changes no logit
// and no output, and pad the heads to a multiple of HB with zero heads.
#pragma once

#include <omp.h>

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "rana_math.h"

namespace rana_cpu {

using rana::Block;
using rana::Grid;

constexpr int kBuffer = 256;             // keys (or queries) buffered per softmax step
constexpr int64_t kBlocksPerChunk = 64;  // key blocks per bias-gradient partial sum
using rana::kScalarLaneDim;

// Queries sorted by centre pixel: CSR over the key grid (ptr[p]..ptr[p+1] index into order), ascending query id
// within a pixel, so every sum over queries runs in a fixed order. order is null when the queries are already in
// pixel order (self-attention layouts).
struct QueryIndex {
  const int64_t* ptr;
  const int64_t* order;
};

// A block before its lanes are filled in: entries first..first+n-1 of a CSR, on grid row y, pixels x0..x0+span.
struct BlockSpan {
  int64_t first, y, x0;
  int32_t n, span;
};

// Cuts the entries of a CSR over the grid (ptr [Hk*Wk+1]) into blocks of at most Q entries, row by row.
inline std::vector<BlockSpan> make_blocks(const int64_t* ptr, int64_t Hk, int64_t Wk, int Q, int threads) {
  std::vector<std::vector<BlockSpan>> per_row(Hk);
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int64_t y = 0; y < Hk; ++y) {
    const int64_t* rp = ptr + y * Wk;
    auto& out = per_row[y];
    int64_t x = 0;
    for (int64_t e = rp[0]; e < rp[Wk];) {
      while (rp[x + 1] <= e) ++x;  // pixel of entry e
      const int64_t xl = std::min(Wk - 1, x + rana::kMaxSpan);
      const int64_t stop = std::min(e + Q, rp[xl + 1]);
      int64_t xe = x;
      while (rp[xe + 1] < stop) ++xe;  // pixel of entry stop - 1
      out.push_back(BlockSpan{e, y, x, int32_t(stop - e), int32_t(xe - x)});
      e = stop;
    }
  }
  std::vector<BlockSpan> all;
  for (auto& r : per_row) all.insert(all.end(), r.begin(), r.end());
  return all;
}

// The entries of a block: operand row (entry, or order[entry] for sorted queries) and pixel.
template <int Q>
Block<Q> fill_block(const BlockSpan& s, const int64_t* ptr, int64_t Wk, const int64_t* order) {
  Block<Q> b;
  b.y = s.y;
  b.x0 = s.x0;
  b.span = s.span;
  b.n = s.n;
  const int64_t* rp = ptr + s.y * Wk + s.x0;
  int32_t x = 0;
  for (int i = 0; i < s.n; ++i) {
    const int64_t e = s.first + i;
    while (rp[x + 1] <= e) ++x;
    b.id[i] = order ? order[e] : e;
    b.rel[i] = x;
  }
  for (int i = s.n; i < Q; ++i) {
    b.id[i] = 0;
    b.rel[i] = 0;
  }
  return b;
}

// Calls f.template operator()<DK, DV>() with the compiled head sizes (rana::dispatch_head_dims; one-lane blocks:
// 16 only).
template <typename V, typename F>
void dispatch_dims(int dk, int dv, F&& f) {
  if constexpr (rana::Lanes<V>::L == 1) {
    if (dk != kScalarLaneDim || dv != kScalarLaneDim) throw std::invalid_argument("one-lane blocks: d = 16 only");
    f.template operator()<kScalarLaneDim, kScalarLaneDim>();
  } else {
    rana::dispatch_head_dims<typename rana::Lanes<V>::T>(dk, dv, f);
  }
}

using rana::Operand;
using rana::Output;

// Calls body.template operator()<DK, DV>(block, lane table, walk, h0) for every query block and head group, the
// blocks spread over the threads (each output row is written by one call).
template <typename T, typename V, int HB, typename F>
void over_query_blocks(const rana::Op<T>& op, const QueryIndex& qi, int threads, F&& body) {
  constexpr int L = rana::Lanes<V>::L, Q = L / HB;
  const auto blocks = make_blocks(qi.ptr, op.g.Hk, op.g.Wk, Q, threads);
  dispatch_dims<V>(op.dk, op.dv, [&]<int DK, int DV>() {
#pragma omp parallel num_threads(threads)
    {
      std::vector<rana::PixelRun> runs(rana::max_runs(op.rows));
#pragma omp for schedule(dynamic, 16)
      for (size_t i = 0; i < blocks.size(); ++i) {
        const Block<Q> b = fill_block<Q>(blocks[i], qi.ptr, op.g.Wk, qi.order);
        const int n = rana::record_runs(rana::PixelWalk{op.g, op.rows, op.g.offsets, 1, b.y, b.x0, b.span},
                                        runs.data());
        for (int h0 = 0; h0 < op.H; h0 += HB)
          body.template operator()<DK, DV>(b, rana::lane_table<L, HB>(b, op.rows, op.H, h0, 1),
                                           rana::RunWalk{runs.data(), n}, h0);
      }
    }
  });
}

// Forward over every query block: q [Nq, H, dk] (any Operand layout); kt, vt head-grouped by HB (rana::Streamed);
// out [Nq, H, dv], lse [Nq, H].
template <typename T, typename V, int HB>
void forward(const rana::Op<T>& op, const Operand<T>& q, const T* kt, const T* vt, const QueryIndex& qi, T* out,
             T* lse, int threads) {
  over_query_blocks<T, V, HB>(op, qi, threads, [&]<int DK, int DV>(const auto& b, const auto& lt, auto walk, int h0) {
    rana::forward_block<V, HB, DK, DV, kBuffer, HB>(op, b, lt, walk, h0, q, kt, vt, out, lse);
  });
}

// Per (query, head) of a block, what the backward needs besides the operands: lse_pos (the forward's lse, with
// +inf for a query whose disc is empty: probability 0 everywhere) and delta = dout . out (FlashAttention-2's row
// term). Computed here, once per entry, rather than by torch ops on [Nq, H] tensors, which cost ~8% of a
// forward+backward at 512x512 (each a fresh allocation and a pass over memory).
template <typename T, int HB, int DV, int Q>
void prepare_rows(const Block<Q>& b, int h0, int H, const Operand<T>& dout, const Operand<T>& out, const T* lse,
                  T* lse_pos, T* delta) {
  for (int i = 0; i < b.n; ++i)
    for (int hh = 0; hh < HB; ++hh) {
      const int64_t id = b.id[i], h = h0 + hh, e = id * H + h;
      const T* a = dout.p + id * dout.sN + h * dout.sH;
      const T* o = out.p + id * out.sN + h * out.sH;
      T s[4] = {T(0), T(0), T(0), T(0)};  // four partial sums: the loop vectorises without reassociating
      for (int c = 0; c < DV; ++c) s[c % 4] += a[c * dout.sC] * o[c * out.sC];
      delta[e] = (s[0] + s[1]) + (s[2] + s[3]);
      lse_pos[e] = lse[e] == rana::neg_inf<T>() ? T(INFINITY) : lse[e];
    }
}

// dQ over every query block: q, dout, out (the forward's output) [Nq, H, d] (Operands); lse [Nq, H] as the forward
// wrote it (-inf for empty discs); kt, vt as forward. Writes dq, and lse_pos, delta [Nq, H] (see prepare_rows) for
// the dK/dV pass.
template <typename T, typename V, int HB>
void backward_dq(const rana::Op<T>& op, const Operand<T>& q, const Operand<T>& dout, const Operand<T>& out,
                 const T* lse, T* lse_pos, T* delta, const T* kt, const T* vt, const QueryIndex& qi,
                 const Output<T>& dq, int threads) {
  over_query_blocks<T, V, HB>(op, qi, threads, [&]<int DK, int DV>(const auto& b, const auto& lt, auto walk, int h0) {
    prepare_rows<T, HB, DV>(b, h0, op.H, dout, out, lse, lse_pos, delta);
    rana::backward_dq_block<V, HB, DK, DV, kBuffer, HB>(op, b, lt, walk, h0, q, dout, lse_pos, delta, kt, vt, dq);
  });
}

// dK, dV (and the bias gradient [H, 2R+1, 2R+1] when dbias is not null) over every key block: queries sorted by
// pixel (q_ptr: their CSR over the grid) with qst, dost head-grouped by HB, lse_s, delta_s [Nq, H]; keys in
// their own order, k, v [Nk, H, d] (Operands); writes dk, dv [Nk, H, d] (Outputs).
template <typename T, typename V, int HB>
void backward_dkdv(const rana::Op<T>& op, const T* qst, const T* dost, const T* lse_s, const T* delta_s,
                   const Operand<T>& k, const Operand<T>& v, const int64_t* q_ptr, const Output<T>& dk,
                   const Output<T>& dv, T* dbias, int threads) {
  constexpr int L = rana::Lanes<V>::L, Q = L / HB;
  const int H = op.H, n_rows = op.rows.n, R = op.rows.R, side = 2 * R + 1;
  const int tw = rana::table_width(R), o = rana::table_centre(R), groups = H / HB;
  const auto blocks = make_blocks(op.g.offsets, op.g.Hk, op.g.Wk, Q, threads);
  const int64_t bias_size = int64_t(H) * side * side, lane_size = int64_t(L) * n_rows * tw;
  const int64_t nchunks = (int64_t(blocks.size()) + kBlocksPerChunk - 1) / kBlocksPerChunk;
  std::vector<T> partial(dbias ? nchunks * bias_size : 0, T(0));
  dispatch_dims<V>(op.dk, op.dv, [&]<int DK, int DV>() {
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
    for (int64_t c = 0; c < nchunks; ++c) {
      std::vector<T> lanes(dbias ? groups * lane_size : 0, T(0));
      std::vector<rana::PixelRun> runs(rana::max_runs(op.rows));
      const int64_t be = std::min<int64_t>(blocks.size(), (c + 1) * kBlocksPerChunk);
      for (int64_t i = c * kBlocksPerChunk; i < be; ++i) {
        const Block<Q> b = fill_block<Q>(blocks[i], op.g.offsets, op.g.Wk, nullptr);
        const int n = rana::record_runs(rana::PixelWalk{op.g, op.rows, q_ptr, -1, b.y, b.x0, b.span}, runs.data());
        for (int h0 = 0; h0 < H; h0 += HB)
          rana::backward_dkdv_block<V, HB, DK, DV, kBuffer, HB>(
              op, b, rana::lane_table<L, HB>(b, op.rows, H, h0, -1), rana::RunWalk{runs.data(), n}, h0, qst, dost,
              lse_s, delta_s, k, v, dk, dv, dbias ? lanes.data() + (h0 / HB) * lane_size : nullptr);
      }
      if (dbias) {  // per-lane tables -> this chunk's [H, side, side], in a fixed order
        T* part = partial.data() + c * bias_size;
        for (int g = 0; g < groups; ++g)
          for (int u = 0; u < L; ++u) {
            const int h = g * HB + u % HB;
            for (int r = 0; r < n_rows; ++r)
              for (int dx = op.rows.dx0[r]; dx <= op.rows.dx1[r]; ++dx)
                part[(int64_t(h) * side + op.rows.dy[r] + R) * side + dx + R] +=
                    lanes[g * lane_size + (int64_t(r) * tw + o + dx) * L + u];
          }
      }
    }
  });
  if (dbias) {
    for (int64_t e = 0; e < bias_size; ++e) dbias[e] = T(0);
    for (int64_t c = 0; c < nchunks; ++c)
      for (int64_t e = 0; e < bias_size; ++e) dbias[e] += partial[c * bias_size + e];
  }
}

// The kernels each translation unit instantiates (declared here so that the bindings do not instantiate them).
#define RANA_CPU_KERNELS(EXTERN, T, V, HB)                                                                         \
  EXTERN template void forward<T, V, HB>(const rana::Op<T>&, const Operand<T>&, const T*, const T*,             \
                                         const QueryIndex&, T*, T*, int);                                          \
  EXTERN template void backward_dq<T, V, HB>(const rana::Op<T>&, const Operand<T>&, const Operand<T>&,            \
                                             const Operand<T>&, const T*, T*, T*, const T*, const T*,              \
                                             const QueryIndex&, const Output<T>&, int);                            \
  EXTERN template void backward_dkdv<T, V, HB>(const rana::Op<T>&, const T*, const T*, const T*, const T*,         \
                                               const Operand<T>&, const Operand<T>&, const int64_t*,               \
                                               const Output<T>&, const Output<T>&, T*, int);

#define RANA_CPU_EXTERN extern
RANA_CPU_KERNELS(RANA_CPU_EXTERN, float, rana::f32v, 4)
RANA_CPU_KERNELS(RANA_CPU_EXTERN, float, rana::f32v, 2)
RANA_CPU_KERNELS(RANA_CPU_EXTERN, float, rana::f32v, 1)
RANA_CPU_KERNELS(RANA_CPU_EXTERN, double, rana::f64v, 1)
RANA_CPU_KERNELS(RANA_CPU_EXTERN, float, float, 1)
RANA_CPU_KERNELS(RANA_CPU_EXTERN, double, double, 1)

}  // namespace rana_cpu
