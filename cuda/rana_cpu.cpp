// CPU (OpenMP) kernels of the RaNA operator and their torch bindings.
//
// Work is organised in blocks (rana_math.h): up to L entries of one grid row on at most kMaxSpan + 1 consecutive
// pixels, one per SIMD lane (L = 16 floats, 8 doubles), so every key visited serves L queries at once.
// Forward: online softmax per query block, saving the log-sum-exp.
// Backward (FlashAttention-2 style, probabilities recomputed from the log-sum-exp):
//   pass 1, per query block: dQ;
//   pass 2, per key block: dK and dV from the reverse neighbourhood (queries sorted by centre pixel), plus the
//           bias gradient, summed per fixed chunk of key blocks.
// Every output element is summed by one task in a fixed order and the bias gradient is reduced over the chunks
// in order, so results do not depend on the number of threads or the schedule.
// Head dimensions are compiled in (d in 8, 16, 32, 64 for q/k; 3, 8, 16, 32, 64 for v): other sizes are padded
// with zero channels, which changes no logit and no output.
#include <torch/extension.h>

#include <omp.h>

#include <type_traits>
#include <vector>

#include "rana_math.h"

namespace {

using rana::Block;
using rana::DiscRows;
using rana::Grid;

template <typename T>
struct VecFor;
template <>
struct VecFor<float> {
  using V = rana::f32x16;
};
template <>
struct VecFor<double> {
  using V = rana::f64x8;
};

constexpr int kBuffer = 256;               // keys (or queries) buffered per softmax step
constexpr int64_t kBlocksPerChunk = 64;    // key blocks per bias-gradient partial sum

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

int threads() { return at::get_num_threads(); }

// Compiled head dimensions: the smallest that holds d. float (the model) gets the sizes it uses; double is for
// gradient checks only and gets few sizes, to keep the first build short.
int64_t padded_dk(int64_t d, bool is_double) {
  if (is_double) return d <= 16 ? 16 : 64;
  return d <= 8 ? 8 : d <= 16 ? 16 : d <= 32 ? 32 : 64;
}
int64_t padded_dv(int64_t d, bool is_double) {
  if (is_double) return d <= 3 ? 3 : d <= 16 ? 16 : 64;
  return d <= 3 ? 3 : d <= 8 ? 8 : d <= 16 ? 16 : d <= 32 ? 32 : 64;
}

torch::Tensor pad_channels(const torch::Tensor& x, int64_t d) {
  if (x.size(2) == d) return x;
  return torch::constant_pad_nd(x, {0, d - x.size(2)}, 0).contiguous();
}

torch::Tensor unpad_channels(const torch::Tensor& x, int64_t d) {
  return x.size(2) == d ? x : x.narrow(2, 0, d).contiguous();
}

// One lane per block (V = T): the bodies exactly as a GPU thread runs them, compiled for d <= 16 only (tests).
constexpr int64_t kScalarLaneDim = 16;

// Calls f.template operator()<DK, DV>() with the compiled dimensions of scalar type T (see padded_dk/dv).
template <typename T, typename F>
void dispatch_dims(int64_t dk, int64_t dv, F&& f) {
  if constexpr (std::is_same_v<T, double>) {
    auto with_dv = [&]<int DK>() {
      switch (dv) {
        case 3: return f.template operator()<DK, 3>();
        case 16: return f.template operator()<DK, 16>();
        default: return f.template operator()<DK, 64>();
      }
    };
    return dk == 16 ? with_dv.template operator()<16>() : with_dv.template operator()<64>();
  } else {
    auto with_dv = [&]<int DK>() {
      switch (dv) {
        case 3: return f.template operator()<DK, 3>();
        case 8: return f.template operator()<DK, 8>();
        case 16: return f.template operator()<DK, 16>();
        case 32: return f.template operator()<DK, 32>();
        default: return f.template operator()<DK, 64>();
      }
    };
    switch (dk) {
      case 8: return with_dv.template operator()<8>();
      case 16: return with_dv.template operator()<16>();
      case 32: return with_dv.template operator()<32>();
      default: return with_dv.template operator()<64>();
    }
  }
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
  for (int64_t i = 0; i < nq; ++i) {
    TORCH_CHECK(qpix[2 * i] >= 0 && qpix[2 * i] < g.Hk && qpix[2 * i + 1] >= 0 && qpix[2 * i + 1] < g.Wk,
                "q_pixels outside the key grid");
    qi.ptr[qpix[2 * i] * g.Wk + qpix[2 * i + 1] + 1]++;
  }
  for (int64_t p = 0; p < npix; ++p) qi.ptr[p + 1] += qi.ptr[p];
  std::vector<int64_t> fill(qi.ptr.begin(), qi.ptr.end() - 1);
  for (int64_t i = 0; i < nq; ++i) order[fill[qpix[2 * i] * g.Wk + qpix[2 * i + 1]]++] = i;
  for (int64_t i = 0; i < nq && qi.identity; ++i) qi.identity = order[i] == i;
  return qi;
}

// A block before its lanes are filled in: entries first..first+n-1 of a CSR, on grid row y, pixels x0..x0+span.
struct BlockSpan {
  int64_t first, y, x0;
  int32_t n, span;
};

// Cuts the entries of a CSR over the grid (ptr [Hk*Wk+1]) into blocks, row by row, in entry order.
std::vector<BlockSpan> make_blocks(const int64_t* ptr, int64_t Hk, int64_t Wk, int L) {
  std::vector<std::vector<BlockSpan>> per_row(Hk);
#pragma omp parallel for schedule(static) num_threads(threads())
  for (int64_t y = 0; y < Hk; ++y) {
    const int64_t* rp = ptr + y * Wk;
    auto& out = per_row[y];
    int64_t x = 0;
    for (int64_t e = rp[0]; e < rp[Wk];) {
      while (rp[x + 1] <= e) ++x;  // pixel of entry e
      const int64_t xl = std::min(Wk - 1, x + rana::kMaxSpan);
      const int64_t stop = std::min(e + L, rp[xl + 1]);
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

// The lanes of a block: operand row (entry, or order[entry] when the entries are sorted queries) and pixel.
template <int L>
Block<L> fill_block(const BlockSpan& s, const int64_t* ptr, int64_t Wk, const int64_t* order) {
  Block<L> b;
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
  for (int i = s.n; i < L; ++i) {
    b.id[i] = 0;
    b.rel[i] = 0;
  }
  return b;
}

// The key pixels of a query block's discs.
template <typename T, int L>
rana::PixelWalk key_walk(const rana::Op<T>& op, const Block<L>& b) {
  return rana::PixelWalk{op.g, op.rows, op.g.offsets, 1, b.y, b.x0, b.span};
}

template <typename T>
struct Tables {
  std::vector<T> tab;
  rana::Op<T> op;
};

template <typename T>
Tables<T> make_op(int64_t H, int64_t dk, int64_t dv, const torch::Tensor& k_offsets, int64_t Hk, int64_t Wk,
                  const torch::Tensor& rows_dy, const torch::Tensor& rows_dx0, const torch::Tensor& rows_dx1,
                  int64_t R, const T* bias, T scale) {
  Tables<T> t;
  const DiscRows rows{int(rows_dy.numel()), int(R), rows_dy.data_ptr<int32_t>(), rows_dx0.data_ptr<int32_t>(),
                      rows_dx1.data_ptr<int32_t>()};
  TORCH_CHECK(rows.n > 0, "empty disc");
  t.tab.resize((H * rows.n + 1) * rana::table_width(rows.R));
  rana::fill_table(rows, bias, int(H), t.tab.data());
  t.op = rana::Op<T>{Grid{k_offsets.data_ptr<int64_t>(), Hk, Wk}, rows, t.tab.data(), int(H), int(dk), int(dv),
                     scale};
  return t;
}

template <typename T, typename V, int DK, int DV>
void forward_impl(const rana::Op<T>& op, const T* q, const T* k, const T* v, const QueryIndex& qi, T* out, T* lse) {
  constexpr int L = rana::Lanes<V>::L;
  const auto blocks = make_blocks(qi.ptr.data(), op.g.Hk, op.g.Wk, L);
  const int64_t* order = qi.identity ? nullptr : qi.order.data_ptr<int64_t>();
#pragma omp parallel num_threads(threads())
  {
    std::vector<rana::PixelRun> runs(rana::max_runs(op.rows));
#pragma omp for schedule(dynamic, 16)
    for (size_t i = 0; i < blocks.size(); ++i) {
      const Block<L> b = fill_block<L>(blocks[i], qi.ptr.data(), op.g.Wk, order);
      const auto lt = rana::lane_table(b, op.rows, op.H, 1);
      const int n = rana::record_runs(key_walk(op, b), runs.data());
      for (int h = 0; h < op.H; ++h)
        rana::forward_block_head<V, DK, DV, kBuffer>(op, b, lt, rana::RunWalk{runs.data(), n}, h, q, k, v, out, lse);
    }
  }
}

template <typename T, typename V, int DK, int DV>
void backward_impl(const rana::Op<T>& op, const torch::Tensor& q_t, const torch::Tensor& k_t,
                   const torch::Tensor& v_t, const torch::Tensor& dout_t, const torch::Tensor& lse_t,
                   const torch::Tensor& delta_t, const QueryIndex& qi, T* dq, T* dk_out, T* dv_out, T* dbias) {
  constexpr int L = rana::Lanes<V>::L;
  const int H = op.H;
  // queries with an empty disc: lse +inf gives them probability 0 everywhere below
  auto lse_pos = torch::where(torch::isinf(lse_t), torch::full_like(lse_t, INFINITY), lse_t).contiguous();
  const T* k = k_t.data_ptr<T>();
  const T* v = v_t.data_ptr<T>();

  // pass 1: dQ per query block
  {
    const auto blocks = make_blocks(qi.ptr.data(), op.g.Hk, op.g.Wk, L);
    const int64_t* order = qi.identity ? nullptr : qi.order.data_ptr<int64_t>();
    const T* q = q_t.data_ptr<T>();
    const T* dout = dout_t.data_ptr<T>();
    const T* lse = lse_pos.data_ptr<T>();
    const T* delta = delta_t.data_ptr<T>();
#pragma omp parallel num_threads(threads())
    {
      std::vector<rana::PixelRun> runs(rana::max_runs(op.rows));
#pragma omp for schedule(dynamic, 16)
      for (size_t i = 0; i < blocks.size(); ++i) {
        const Block<L> b = fill_block<L>(blocks[i], qi.ptr.data(), op.g.Wk, order);
        const auto lt = rana::lane_table(b, op.rows, H, 1);
        const int n = rana::record_runs(key_walk(op, b), runs.data());
        for (int h = 0; h < H; ++h)
          rana::backward_dq_block_head<V, DK, DV, kBuffer>(op, b, lt, rana::RunWalk{runs.data(), n}, h, q, dout, lse,
                                                           delta, k, v, dq);
      }
    }
  }

  // pass 2: dK, dV per key block; the queries' operands in pixel order
  auto sorted = [&](const torch::Tensor& x) -> torch::Tensor { return qi.identity ? x : x.index_select(0, qi.order).contiguous(); };
  const torch::Tensor qs_t = sorted(q_t), dos_t = sorted(dout_t), lse_s_t = sorted(lse_pos), delta_s_t = sorted(delta_t);
  const T* qs = qs_t.data_ptr<T>();
  const T* dos = dos_t.data_ptr<T>();
  const T* lse_s = lse_s_t.data_ptr<T>();
  const T* delta_s = delta_s_t.data_ptr<T>();
  const auto blocks = make_blocks(op.g.offsets, op.g.Hk, op.g.Wk, L);
  const int n_rows = op.rows.n, R = op.rows.R, side = 2 * R + 1;
  const int tw = rana::table_width(R), o = rana::table_centre(R);
  const int64_t bias_size = int64_t(H) * side * side, lane_size = int64_t(L) * n_rows * tw;
  const int64_t nchunks = (int64_t(blocks.size()) + kBlocksPerChunk - 1) / kBlocksPerChunk;
  std::vector<T> partial(dbias ? nchunks * bias_size : 0, T(0));
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads())
  for (int64_t c = 0; c < nchunks; ++c) {
    std::vector<T> lanes(dbias ? H * lane_size : 0, T(0));
    std::vector<rana::PixelRun> runs(rana::max_runs(op.rows));
    const int64_t be = std::min<int64_t>(blocks.size(), (c + 1) * kBlocksPerChunk);
    for (int64_t i = c * kBlocksPerChunk; i < be; ++i) {
      const Block<L> b = fill_block<L>(blocks[i], op.g.offsets, op.g.Wk, nullptr);
      const auto lt = rana::lane_table(b, op.rows, H, -1);
      const int n = rana::record_runs(rana::PixelWalk{op.g, op.rows, qi.ptr.data(), -1, b.y, b.x0, b.span},
                                      runs.data());
      for (int h = 0; h < H; ++h)
        rana::backward_dkdv_block_head<V, DK, DV, kBuffer>(op, b, lt, rana::RunWalk{runs.data(), n}, h, qs, dos,
                                                           lse_s, delta_s, k, v, dk_out, dv_out,
                                                           dbias ? lanes.data() + h * lane_size : nullptr);
    }
    if (dbias) {  // per-lane tables -> this chunk's [H, side, side], in a fixed order
      T* part = partial.data() + c * bias_size;
      for (int h = 0; h < H; ++h)
        for (int u = 0; u < L; ++u)
          for (int r = 0; r < n_rows; ++r)
            for (int dx = op.rows.dx0[r]; dx <= op.rows.dx1[r]; ++dx)
              part[(int64_t(h) * side + op.rows.dy[r] + R) * side + dx + R] +=
                  lanes[h * lane_size + (int64_t(u) * n_rows + r) * tw + o + dx];
    }
  }
  if (dbias) {
    for (int64_t e = 0; e < bias_size; ++e) dbias[e] = T(0);
    for (int64_t c = 0; c < nchunks; ++c)
      for (int64_t e = 0; e < bias_size; ++e) dbias[e] += partial[c * bias_size + e];
  }
}

std::vector<torch::Tensor> rana_forward(torch::Tensor q, torch::Tensor k, torch::Tensor v, torch::Tensor q_pixels,
                                        torch::Tensor k_offsets, int64_t Hk, int64_t Wk, torch::Tensor rows_dy,
                                        torch::Tensor rows_dx0, torch::Tensor rows_dx1, int64_t R,
                                        c10::optional<torch::Tensor> bias, double scale, bool scalar_lanes) {
  check_inputs(q, k, v, q_pixels, k_offsets, Hk, Wk);
  const int64_t nq = q.size(0), H = q.size(1), dv = v.size(2);
  const bool dbl = q.scalar_type() == torch::kDouble;
  int64_t DKp = padded_dk(q.size(2), dbl), DVp = padded_dv(dv, dbl);
  if (scalar_lanes) {
    TORCH_CHECK(q.size(2) <= kScalarLaneDim && dv <= kScalarLaneDim, "scalar lanes: head dimensions up to 16");
    DKp = DVp = kScalarLaneDim;
  }
  const Grid grid{k_offsets.data_ptr<int64_t>(), Hk, Wk};
  const QueryIndex qi = index_queries(q_pixels, grid);
  const auto qp = pad_channels(q, DKp), kp = pad_channels(k, DKp), vp = pad_channels(v, DVp);
  auto out = torch::empty({nq, H, DVp}, q.options());
  auto lse = torch::empty({nq, H}, q.options());
  AT_DISPATCH_FLOATING_TYPES(q.scalar_type(), "rana_forward", [&] {
    const scalar_t* b = bias.has_value() ? bias->data_ptr<scalar_t>() : nullptr;
    const auto t = make_op<scalar_t>(H, DKp, DVp, k_offsets, Hk, Wk, rows_dy, rows_dx0, rows_dx1, R, b,
                                     scalar_t(scale));
    auto run = [&]<typename V, int DK, int DV>() {
      forward_impl<scalar_t, V, DK, DV>(t.op, qp.data_ptr<scalar_t>(), kp.data_ptr<scalar_t>(),
                                        vp.data_ptr<scalar_t>(), qi, out.data_ptr<scalar_t>(),
                                        lse.data_ptr<scalar_t>());
    };
    if (scalar_lanes)
      run.template operator()<scalar_t, kScalarLaneDim, kScalarLaneDim>();
    else
      dispatch_dims<scalar_t>(DKp, DVp, [&]<int DK, int DV>() {
        run.template operator()<typename VecFor<scalar_t>::V, DK, DV>();
      });
  });
  return {unpad_channels(out, dv), lse};
}

std::vector<torch::Tensor> rana_backward(torch::Tensor dout, torch::Tensor q, torch::Tensor k, torch::Tensor v,
                                         torch::Tensor lse, torch::Tensor delta, torch::Tensor q_pixels,
                                         torch::Tensor k_offsets, int64_t Hk, int64_t Wk, torch::Tensor rows_dy,
                                         torch::Tensor rows_dx0, torch::Tensor rows_dx1, int64_t R,
                                         c10::optional<torch::Tensor> bias, double scale, bool need_dbias,
                                         bool scalar_lanes) {
  check_inputs(q, k, v, q_pixels, k_offsets, Hk, Wk);
  TORCH_CHECK(dout.is_contiguous() && lse.is_contiguous() && delta.is_contiguous(), "grads must be contiguous");
  const int64_t H = q.size(1), dk = q.size(2), dv = v.size(2);
  const bool dbl = q.scalar_type() == torch::kDouble;
  int64_t DKp = padded_dk(dk, dbl), DVp = padded_dv(dv, dbl);
  if (scalar_lanes) {
    TORCH_CHECK(dk <= kScalarLaneDim && dv <= kScalarLaneDim, "scalar lanes: head dimensions up to 16");
    DKp = DVp = kScalarLaneDim;
  }
  const Grid grid{k_offsets.data_ptr<int64_t>(), Hk, Wk};
  const QueryIndex qi = index_queries(q_pixels, grid);
  const auto qp = pad_channels(q, DKp), kp = pad_channels(k, DKp), vp = pad_channels(v, DVp),
             dop = pad_channels(dout, DVp);
  auto dq = torch::empty_like(qp);
  auto dk_t = torch::empty_like(kp);
  auto dv_t = torch::empty_like(vp);
  const int64_t side = 2 * R + 1;
  auto dbias = need_dbias ? torch::empty({H, side, side}, q.options()) : torch::Tensor();
  AT_DISPATCH_FLOATING_TYPES(q.scalar_type(), "rana_backward", [&] {
    const scalar_t* b = bias.has_value() ? bias->data_ptr<scalar_t>() : nullptr;
    const auto t = make_op<scalar_t>(H, DKp, DVp, k_offsets, Hk, Wk, rows_dy, rows_dx0, rows_dx1, R, b,
                                     scalar_t(scale));
    auto run = [&]<typename V, int DK, int DV>() {
      backward_impl<scalar_t, V, DK, DV>(t.op, qp, kp, vp, dop, lse, delta, qi, dq.data_ptr<scalar_t>(),
                                         dk_t.data_ptr<scalar_t>(), dv_t.data_ptr<scalar_t>(),
                                         need_dbias ? dbias.data_ptr<scalar_t>() : nullptr);
    };
    if (scalar_lanes)
      run.template operator()<scalar_t, kScalarLaneDim, kScalarLaneDim>();
    else
      dispatch_dims<scalar_t>(DKp, DVp, [&]<int DK, int DV>() {
        run.template operator()<typename VecFor<scalar_t>::V, DK, DV>();
      });
  });
  return {unpad_channels(dq, dk), unpad_channels(dk_t, dk), unpad_channels(dv_t, dv), dbias};
}

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("forward", &rana_forward, "RaNA forward (CPU): returns (out, lse)");  // NOLINT
  m.def("backward", &rana_backward, "RaNA backward (CPU): returns (dq, dk, dv, dbias)");
}
