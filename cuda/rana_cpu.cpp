// Torch bindings of the CPU RaNA kernels (rana_cpu_kernels.h): checks, padding to the compiled sizes, the
// head-grouped copies of the operands the kernels stream, and the queries' pixel order.
#include <torch/extension.h>

#include <vector>

#include "rana_binding.h"
#include "rana_cpu_buffers.h"
#include "rana_cpu_kernels.h"
#include "composite_cpu.h"
#include "rows_cpu.h"

namespace {

using namespace rana_binding;

template <typename T>
struct VecFor;
template <>
struct VecFor<float> {
  using V = rana::f32v;
};
template <>
struct VecFor<double> {
  using V = rana::f64v;
};

int threads() { return at::get_num_threads(); }

// [N, H, d] -> head-grouped storage [N, H / G, d, G] (rana::Streamed, G = the kernel's HB): channel c of a group's
// heads side by side, so one load serves a block's heads. With G = H it is channel-major [N, d, H], free for a
// channel-major view (as the model's projections write); with G = 1 it is the natural layout. Otherwise one parallel
// pass over entries (torch's strided copy of the transposed view took ~40 ms per 200 MB operand).
torch::Tensor head_grouped(const torch::Tensor& x, int64_t G) {
  const int64_t n = x.size(0), H = x.size(1), d = x.size(2);
  if (G == H && is_channel_major(x)) return x.transpose(1, 2);
  if (G == 1 || H == 1) return x.contiguous();
  const auto xc = x.contiguous();
  auto out = rana_cpu_buffers::empty({n, H / G, d, G}, x.options());
  AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "head_grouped", [&] {
    const scalar_t* src = xc.data_ptr<scalar_t>();
    scalar_t* dst = out.data_ptr<scalar_t>();
    at::parallel_for(0, n, 4096, [&](int64_t b, int64_t e) {
      for (int64_t j = b; j < e; ++j)
        for (int64_t h = 0; h < H; ++h)
          for (int64_t c = 0; c < d; ++c) dst[((j * (H / G) + h / G) * d + c) * G + h % G] = src[(j * H + h) * d + c];
    });
  });
  return out;
}

// pad_to, then head_grouped, in one pass: [N, h, c] (any strides) -> [N, H / G, d, G] with zero heads and channels
// appended. The forward's values are rarely of a compiled size (a reconstruction's 6 or 1 channels, padded to 8 or
// 3): padding then grouping made two copies of the operand, and torch's padding a third of its contiguous().
torch::Tensor grouped_padded(const torch::Tensor& x, int64_t H, int64_t d, int64_t G) {
  if (x.size(1) == H && x.size(2) == d) return head_grouped(x, G);
  const int64_t n = x.size(0), h0 = x.size(1), c0 = x.size(2);
  auto out = rana_cpu_buffers::empty({n, H / G, d, G}, x.options());
  AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "grouped_padded", [&] {
    const scalar_t* src = x.data_ptr<scalar_t>();
    const int64_t sN = x.stride(0), sH = x.stride(1), sC = x.stride(2);
    scalar_t* dst = out.data_ptr<scalar_t>();
    at::parallel_for(0, n, 4096, [&](int64_t b, int64_t e) {
      for (int64_t j = b; j < e; ++j) {
        scalar_t* row = dst + j * H * d;
        for (int64_t h = 0; h < H; ++h)
          for (int64_t c = 0; c < d; ++c)
            row[((h / G) * d + c) * G + h % G] = h < h0 && c < c0 ? src[j * sN + h * sH + c * sC] : scalar_t(0);
      }
    });
  });
  return out;
}

// Queries sorted by centre pixel: CSR over the key grid and the order (see rana_cpu::QueryIndex).
struct QueryOrder {
  std::vector<int64_t> ptr;
  torch::Tensor order;
  bool identity;
  rana_cpu::QueryIndex index() const {
    return rana_cpu::QueryIndex{ptr.data(), identity ? nullptr : order.data_ptr<int64_t>()};
  }
};

QueryOrder order_queries(const torch::Tensor& qpix_t, int64_t Hk, int64_t Wk) {
  const int64_t nq = qpix_t.size(0), npix = Hk * Wk;
  const int64_t* qpix = qpix_t.data_ptr<int64_t>();
  QueryOrder qo{std::vector<int64_t>(npix + 1, 0), torch::empty({nq}, qpix_t.options()), true};
  int64_t* order = qo.order.data_ptr<int64_t>();
  for (int64_t i = 0; i < nq; ++i) {
    TORCH_CHECK(qpix[2 * i] >= 0 && qpix[2 * i] < Hk && qpix[2 * i + 1] >= 0 && qpix[2 * i + 1] < Wk,
                "q_pixels outside the key grid");
    qo.ptr[qpix[2 * i] * Wk + qpix[2 * i + 1] + 1]++;
  }
  for (int64_t p = 0; p < npix; ++p) qo.ptr[p + 1] += qo.ptr[p];
  std::vector<int64_t> fill(qo.ptr.begin(), qo.ptr.end() - 1);
  for (int64_t i = 0; i < nq; ++i) order[fill[qpix[2 * i] * Wk + qpix[2 * i + 1]]++] = i;
  for (int64_t i = 0; i < nq && qo.identity; ++i) qo.identity = order[i] == i;
  return qo;
}

// The op's geometry and its mask-and-bias table (kept alive alongside the Op that points into it).
template <typename T>
struct OpWithTable {
  std::vector<T> tab, ptab, tab4;
  rana::Op<T> op;
};

template <typename T>
OpWithTable<T> make_op(const Plan& pl, const torch::Tensor& k_offsets, int64_t Hk, int64_t Wk,
                       const torch::Tensor& rows_dy, const torch::Tensor& rows_dx0, const torch::Tensor& rows_dx1,
                       int64_t R, const c10::optional<torch::Tensor>& bias, double scale) {
  OpWithTable<T> t;
  const rana::DiscRows rows{int(rows_dy.numel()), int(R), rows_dy.data_ptr<int32_t>(),
                            rows_dx0.data_ptr<int32_t>(), rows_dx1.data_ptr<int32_t>()};
  TORCH_CHECK(rows.n > 0, "empty disc");
  torch::Tensor b;  // bias padded to the padded heads with zeros
  if (bias.has_value()) b = torch::constant_pad_nd(*bias, {0, 0, 0, 0, 0, pl.H - bias->size(0)}, 0).contiguous();
  t.tab.resize((pl.H * rows.n + 1) * rana::table_width(rows.R));
  rana::fill_table(rows, bias.has_value() ? b.data_ptr<T>() : static_cast<const T*>(nullptr), int(pl.H),
                   t.tab.data());
  t.op = rana::Op<T>{rana::Grid{k_offsets.data_ptr<int64_t>(), Hk, Wk}, rows, t.tab.data(), int(pl.H), int(pl.dk),
                     int(pl.dv), T(scale)};
  if (std::is_same_v<T, float> && !pl.scalar && pl.HB == 4 && rows.R <= 3) {  // permute tables (rana_math.h)
    t.ptab.resize(pl.H / 4 * rows.n * 32);
    rana::fill_permute_table(rows, bias.has_value() ? b.data_ptr<T>() : static_cast<const T*>(nullptr), int(pl.H),
                             t.ptab.data());
    t.op.ptab = t.ptab.data();
    t.op.has_bias = bias.has_value();
  }
  if (std::is_same_v<T, float> && !pl.scalar && pl.HB == 4 && rana::Lanes<rana::f32v>::L == 8) {
    t.tab4.resize(4 * t.tab.size());
    rana::fill_interleaved_table(rows, t.tab.data(), int(pl.H), t.tab4.data());
    t.op.tab4 = t.tab4.data();
  }
  return t;
}

// Calls f.template operator()<V, HB>() for the plan.
template <typename T, typename F>
void with_kernel(const Plan& pl, F&& f) {
  if (pl.scalar) return f.template operator()<T, 1>();
  if constexpr (std::is_same_v<T, float>) {
    if (pl.HB == 4) return f.template operator()<rana::f32v, 4>();
    if (pl.HB == 2) return f.template operator()<rana::f32v, 2>();
  }
  return f.template operator()<typename VecFor<T>::V, 1>();
}

std::vector<torch::Tensor> rana_forward(torch::Tensor q, torch::Tensor k, torch::Tensor v, torch::Tensor q_pixels,
                                        torch::Tensor k_offsets, int64_t Hk, int64_t Wk, torch::Tensor rows_dy,
                                        torch::Tensor rows_dx0, torch::Tensor rows_dx1, int64_t R,
                                        c10::optional<torch::Tensor> bias, double scale, bool scalar_lanes) {
  check_inputs(q, k, v, q_pixels, k_offsets, Hk, Wk);
  const int64_t nq = q.size(0), H = q.size(1), dv = v.size(2);
  const Plan pl = plan_for(H, q.size(2), dv, q.scalar_type() == torch::kDouble, scalar_lanes);
  const QueryOrder qo = order_queries(q_pixels, Hk, Wk);
  const auto qp = pad_to(q, pl.H, pl.dk);
  const auto kt = grouped_padded(k, pl.H, pl.dk, pl.HB), vt = grouped_padded(v, pl.H, pl.dv, pl.HB);
  auto out = rana_cpu_buffers::empty({nq, pl.H, pl.dv}, q.options());
  auto lse = torch::empty({nq, pl.H}, q.options());
  AT_DISPATCH_FLOATING_TYPES(q.scalar_type(), "rana_forward", [&] {
    using T = scalar_t;
    const auto t = make_op<T>(pl, k_offsets, Hk, Wk, rows_dy, rows_dx0, rows_dx1, R, bias, scale);
    with_kernel<T>(pl, [&]<typename V, int HB>() {
      rana_cpu::forward<T, V, HB>(t.op, operand<T>(qp), kt.data_ptr<T>(), vt.data_ptr<T>(), qo.index(),
                                  out.data_ptr<T>(), lse.data_ptr<T>(), threads());
    });
  });
  return {unpad(out, H, dv), pl.H == H ? lse : lse.narrow(1, 0, H).contiguous()};
}

std::vector<torch::Tensor> rana_backward(torch::Tensor dout, torch::Tensor q, torch::Tensor k, torch::Tensor v,
                                         torch::Tensor out, torch::Tensor lse, torch::Tensor q_pixels,
                                         torch::Tensor k_offsets, int64_t Hk, int64_t Wk, torch::Tensor rows_dy,
                                         torch::Tensor rows_dx0, torch::Tensor rows_dx1, int64_t R,
                                         c10::optional<torch::Tensor> bias, double scale, bool need_dbias,
                                         bool scalar_lanes) {
  check_inputs(q, k, v, q_pixels, k_offsets, Hk, Wk);
  TORCH_CHECK(dout.is_contiguous() && lse.is_contiguous(), "grads must be contiguous");
  const int64_t H = q.size(1), dk = q.size(2), dv = v.size(2);
  const Plan pl = plan_for(H, dk, dv, q.scalar_type() == torch::kDouble, scalar_lanes);
  const QueryOrder qo = order_queries(q_pixels, Hk, Wk);
  const auto qp = pad_to(q, pl.H, pl.dk), kp = pad_to(k, pl.H, pl.dk), vp = pad_to(v, pl.H, pl.dv),
             dop = pad_to(dout, pl.H, pl.dv);
  const int64_t nq = q.size(0);
  // the kernels read lse and out with the padded heads (and out's padded channels); the dQ pass turns lse into
  // lse_pos (+inf for empty discs and padding heads) and computes delta = dout . out, both for the dK/dV pass
  const auto outp = pad_to(out, pl.H, pl.dv), lse_p = pad_heads(lse, pl.H, -INFINITY);
  auto lse_pos = rana_cpu_buffers::empty({nq, pl.H}, q.options()),
       delta = rana_cpu_buffers::empty({nq, pl.H}, q.options());
  const auto cached = [](at::IntArrayRef s, const torch::TensorOptions& o) { return rana_cpu_buffers::empty(s, o); };
  auto dq = empty_like_layout(qp, qp.size(0), pl.H, pl.dk, cached);
  auto dk_t = empty_like_layout(kp, kp.size(0), pl.H, pl.dk, cached);
  auto dv_t = empty_like_layout(vp, vp.size(0), pl.H, pl.dv, cached);
  const int64_t side = 2 * R + 1;
  auto dbias = need_dbias ? torch::empty({pl.H, side, side}, q.options()) : torch::Tensor();
  AT_DISPATCH_FLOATING_TYPES(q.scalar_type(), "rana_backward", [&] {
    using T = scalar_t;
    const auto t = make_op<T>(pl, k_offsets, Hk, Wk, rows_dy, rows_dx0, rows_dx1, R, bias, scale);
    with_kernel<T>(pl, [&]<typename V, int HB>() {
      {  // pass 1: dQ per query block
        const auto kt = head_grouped(kp, pl.HB), vt = head_grouped(vp, pl.HB);
        rana_cpu::backward_dq<T, V, HB>(t.op, operand<T>(qp), operand<T>(dop), operand<T>(outp),
                                        lse_p.data_ptr<T>(), lse_pos.data_ptr<T>(), delta.data_ptr<T>(),
                                        kt.data_ptr<T>(), vt.data_ptr<T>(), qo.index(), output<T>(dq), threads());
      }
      // pass 2: dK, dV per key block; the queries' operands in pixel order
      auto sorted = [&](const torch::Tensor& x) -> torch::Tensor {  // keeps a channel-major view's layout
        return qo.identity ? x : x.index_select(0, qo.order);
      };
      const torch::Tensor qst = head_grouped(sorted(qp), pl.HB), dost = head_grouped(sorted(dop), pl.HB),
                          lse_s = sorted(lse_pos).contiguous(), delta_s = sorted(delta).contiguous();
      rana_cpu::backward_dkdv<T, V, HB>(t.op, qst.data_ptr<T>(), dost.data_ptr<T>(), lse_s.data_ptr<T>(),
                                        delta_s.data_ptr<T>(), operand<T>(kp), operand<T>(vp), qo.ptr.data(),
                                        output<T>(dk_t), output<T>(dv_t),
                                        need_dbias ? dbias.data_ptr<T>() : nullptr, threads());
    });
  });
  return {unpad(dq, H, dk), unpad(dk_t, H, dk), unpad(dv_t, H, dv),
          need_dbias && pl.H != H ? dbias.narrow(0, 0, H).contiguous() : dbias};
}

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("forward", &rana_forward, "RaNA forward (CPU): returns (out, lse)");
  m.def("backward", &rana_backward, "RaNA backward (CPU): returns (dq, dk, dv, dbias)");
  m.def("rows_ln_linear", &rows_ln_linear, "fused [LayerNorm] + linear, split into column blocks (inference)");
  m.def("rows_linear_residual", &rows_linear_residual, "fused residual + linear(s) (inference)");
  m.def("rows_mlp", &rows_mlp, "fused [LayerNorm] + linear + ReLU + linear [+ residual] (inference)");
  m.def("rows_wide_operand", &rows_wide_operand, "a reconstruction kernel's wide q/k operand in one pass (inference)");
  m.def("rows_scale_mix", &rows_scale_mix, "a reconstruction's scale mixer: linear, softmax, mix (inference)");
  m.def("rows_concat", &rows_concat, "torch.cat(parts, 1) of contiguous float32 rows in one pass");
  m.def("rows_pair_features", &rows_pair_features, "the matching step's pair features [|a - b|, a * b] (inference)");
  m.def("rows_pair_sum", &rows_pair_sum, "the matching step's weighted sum over each query's pairs (inference)");
  m.def("composite_blocks", &composite_blocks, "front-to-back over composite of sorted bins per pixel (inference)");
}
