// Torch bindings of the CUDA RaNA kernels (rana_cuda_kernels.cu): the same checks, padding and layouts as the CPU
// binding (rana_binding.h), with the queries' pixel order, the channel-major copies and the mask-and-bias table
// made by ATen ops on the GPU. Only CPU-side headers: the caller passes the current CUDA stream as an integer
// (torch.cuda.current_stream().cuda_stream), so this file compiles with g++ against a CPU build of torch (CI).
#include <torch/extension.h>

#include <vector>

#include "rana_binding.h"
#include "rana_cuda_kernels.h"

namespace {

using namespace rana_binding;

// [N, H, d] -> [N, d, H] storage (free for a channel-major view).
torch::Tensor channel_major(const torch::Tensor& x) {
  if (is_channel_major(x)) return x.transpose(1, 2);
  return x.transpose(1, 2).contiguous();
}

// Queries sorted by centre pixel (stable): the order and the CSR over the key grid, on the GPU.
struct QueryOrder {
  torch::Tensor order, ptr;
};

QueryOrder order_queries(const torch::Tensor& qpix, int64_t Hk, int64_t Wk) {
  const auto pix = qpix.select(1, 0) * Wk + qpix.select(1, 1);
  // the stable overload named in full: a bare `true` converts to the int64 `dim` of the other overload (dim 1)
  const auto order = std::get<1>(torch::sort(pix, c10::optional<bool>(true), /*dim=*/0, /*descending=*/false));
  const auto counts = torch::bincount(pix, {}, Hk * Wk);
  const auto ptr = torch::cat({torch::zeros({1}, counts.options()), torch::cumsum(counts, 0)});
  return QueryOrder{order, ptr.to(torch::kInt64).contiguous()};
}

// Each key bin's (y, x) from the grid's offsets.
torch::Tensor key_pixels(const torch::Tensor& k_offsets, int64_t Hk, int64_t Wk, int64_t nk) {
  const auto counts = k_offsets.narrow(0, 1, Hk * Wk) - k_offsets.narrow(0, 0, Hk * Wk);
  const auto pix = torch::repeat_interleave(torch::arange(Hk * Wk, k_offsets.options()), counts, /*dim=*/0,
                                           /*output_size=*/nk);
  return torch::stack({torch::div(pix, Wk, "floor"), torch::remainder(pix, Wk)}, 1).contiguous();
}

// The op's geometry on the GPU: disc rows and the mask-and-bias table (filled on the host, as on the CPU, then
// copied), kept alive alongside the Op that points into them.
template <typename T>
struct DeviceOp {
  torch::Tensor dy, dx0, dx1, tab;
  rana::Op<T> op;
};

template <typename T>
DeviceOp<T> make_op(const Plan& pl, const torch::Tensor& k_offsets, int64_t Hk, int64_t Wk,
                    const torch::Tensor& rows_dy, const torch::Tensor& rows_dx0, const torch::Tensor& rows_dx1,
                    int64_t R, const c10::optional<torch::Tensor>& bias, double scale) {
  const auto dev = k_offsets.device();
  const auto dy_h = rows_dy.cpu().contiguous(), dx0_h = rows_dx0.cpu().contiguous(), dx1_h = rows_dx1.cpu().contiguous();
  const rana::DiscRows rows_h{int(dy_h.numel()), int(R), dy_h.data_ptr<int32_t>(), dx0_h.data_ptr<int32_t>(),
                              dx1_h.data_ptr<int32_t>()};
  TORCH_CHECK(rows_h.n > 0, "empty disc");
  torch::Tensor b;
  if (bias.has_value())
    b = torch::constant_pad_nd(bias->cpu(), {0, 0, 0, 0, 0, pl.H - bias->size(0)}, 0).contiguous();
  torch::Tensor tab_h = torch::empty({(pl.H * rows_h.n + 1) * rana::table_width(rows_h.R)},
                            torch::TensorOptions().dtype(c10::CppTypeToScalarType<T>::value));
  rana::fill_table(rows_h, bias.has_value() ? b.data_ptr<T>() : static_cast<const T*>(nullptr), int(pl.H),
                   tab_h.data_ptr<T>());
  const torch::Tensor dy = dy_h.to(dev), dx0 = dx0_h.to(dev), dx1 = dx1_h.to(dev), tab = tab_h.to(dev);
  const rana::DiscRows rows{rows_h.n, rows_h.R, dy.data_ptr<int32_t>(), dx0.data_ptr<int32_t>(),
                            dx1.data_ptr<int32_t>()};
  const rana::Op<T> op{rana::Grid{k_offsets.data_ptr<int64_t>(), Hk, Wk}, rows, tab.data_ptr<T>(), int(pl.H),
                       int(pl.dk), int(pl.dv), T(scale)};
  return DeviceOp<T>{dy, dx0, dx1, tab, op};
}

void* as_stream(int64_t stream) { return reinterpret_cast<void*>(stream); }

std::vector<torch::Tensor> rana_forward(torch::Tensor q, torch::Tensor k, torch::Tensor v, torch::Tensor q_pixels,
                                        torch::Tensor k_offsets, int64_t Hk, int64_t Wk, torch::Tensor rows_dy,
                                        torch::Tensor rows_dx0, torch::Tensor rows_dx1, int64_t R,
                                        c10::optional<torch::Tensor> bias, double scale, int64_t stream) {
  check_inputs(q, k, v, q_pixels, k_offsets, Hk, Wk);
  TORCH_CHECK(q.is_cuda(), "the CUDA kernels need CUDA tensors");
  const int64_t nq = q.size(0), H = q.size(1), dv = v.size(2);
  // one lane per thread: no head blocks, so no head padding (HB = 1)
  Plan pl = plan_for(H, q.size(2), dv, q.scalar_type() == torch::kDouble, false);
  pl.HB = 1;
  pl.H = H;
  const auto qp = pad_to(q, pl.H, pl.dk);
  const auto kt = channel_major(pad_to(k, pl.H, pl.dk)), vt = channel_major(pad_to(v, pl.H, pl.dv));
  auto out = torch::empty({nq, pl.H, pl.dv}, q.options());
  auto lse = torch::empty({nq, pl.H}, q.options());
  AT_DISPATCH_FLOATING_TYPES(q.scalar_type(), "rana_forward_cuda", [&] {
    using T = scalar_t;
    const auto d = make_op<T>(pl, k_offsets, Hk, Wk, rows_dy, rows_dx0, rows_dx1, R, bias, scale);
    rana_cuda::forward<T>(d.op, operand<T>(qp), kt.data_ptr<T>(), vt.data_ptr<T>(), q_pixels.data_ptr<int64_t>(), nq,
                          out.data_ptr<T>(), lse.data_ptr<T>(), as_stream(stream));
  });
  return {unpad(out, H, dv), lse};
}

std::vector<torch::Tensor> rana_backward(torch::Tensor dout, torch::Tensor q, torch::Tensor k, torch::Tensor v,
                                         torch::Tensor lse, torch::Tensor delta, torch::Tensor q_pixels,
                                         torch::Tensor k_offsets, int64_t Hk, int64_t Wk, torch::Tensor rows_dy,
                                         torch::Tensor rows_dx0, torch::Tensor rows_dx1, int64_t R,
                                         c10::optional<torch::Tensor> bias, double scale, bool need_dbias,
                                         int64_t stream) {
  check_inputs(q, k, v, q_pixels, k_offsets, Hk, Wk);
  TORCH_CHECK(q.is_cuda(), "the CUDA kernels need CUDA tensors");
  TORCH_CHECK(dout.is_contiguous() && lse.is_contiguous() && delta.is_contiguous(), "grads must be contiguous");
  const int64_t H = q.size(1), dk = q.size(2), dv = v.size(2), nk = k.size(0);
  Plan pl = plan_for(H, dk, dv, q.scalar_type() == torch::kDouble, false);
  pl.HB = 1;
  pl.H = H;
  const auto qp = pad_to(q, pl.H, pl.dk), kp = pad_to(k, pl.H, pl.dk), vp = pad_to(v, pl.H, pl.dv),
             dop = pad_to(dout, pl.H, pl.dv);
  const auto lse_pos = torch::where(torch::isinf(lse), torch::full_like(lse, INFINITY), lse).contiguous();
  auto dq = empty_like_layout(qp, qp.size(0), pl.H, pl.dk);
  auto dk_t = empty_like_layout(kp, nk, pl.H, pl.dk);
  auto dv_t = empty_like_layout(vp, nk, pl.H, pl.dv);
  const int64_t side = 2 * R + 1;
  auto dbias = need_dbias ? torch::empty({pl.H, side, side}, q.options()) : torch::Tensor();
  const QueryOrder qo = order_queries(q_pixels, Hk, Wk);
  const auto kpix = key_pixels(k_offsets, Hk, Wk, nk);
  AT_DISPATCH_FLOATING_TYPES(q.scalar_type(), "rana_backward_cuda", [&] {
    using T = scalar_t;
    const auto d = make_op<T>(pl, k_offsets, Hk, Wk, rows_dy, rows_dx0, rows_dx1, R, bias, scale);
    {
      const auto kt = channel_major(kp), vt = channel_major(vp);
      rana_cuda::backward_dq<T>(d.op, operand<T>(qp), operand<T>(dop), lse_pos.data_ptr<T>(), delta.data_ptr<T>(),
                                kt.data_ptr<T>(), vt.data_ptr<T>(), q_pixels.data_ptr<int64_t>(), qp.size(0),
                                output<T>(dq), as_stream(stream));
    }
    const auto qst = channel_major(qp.index_select(0, qo.order)), dost = channel_major(dop.index_select(0, qo.order));
    const auto lse_s = lse_pos.index_select(0, qo.order).contiguous(),
               delta_s = delta.index_select(0, qo.order).contiguous();
    torch::Tensor partial;
    if (need_dbias) partial = torch::empty({rana_cuda::partial_size(nk, pl.H, int(R))}, q.options());
    rana_cuda::backward_dkdv<T>(d.op, qst.data_ptr<T>(), dost.data_ptr<T>(), lse_s.data_ptr<T>(),
                                delta_s.data_ptr<T>(), operand<T>(kp), operand<T>(vp), qo.ptr.data_ptr<int64_t>(),
                                kpix.data_ptr<int64_t>(), nk, output<T>(dk_t), output<T>(dv_t),
                                need_dbias ? dbias.data_ptr<T>() : nullptr,
                                need_dbias ? partial.data_ptr<T>() : nullptr, as_stream(stream));
  });
  return {unpad(dq, H, dk), unpad(dk_t, H, dk), unpad(dv_t, H, dv), dbias};
}

// The process-wide choice between the staged and the one-thread kernels (benchmarks and tests compare them in one
// process); max_chunk <= 0 leaves the chunk size. Returns the options now in force.
std::tuple<bool, int64_t> configure(bool staged, int64_t max_chunk) {
  auto& o = rana_cuda::staged_options();
  o.enabled = staged;
  if (max_chunk > 0) o.max_chunk = int(max_chunk);
  return {o.enabled, o.max_chunk};
}

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("configure", &configure, "staged kernels on or off, and their rows per shared-memory chunk",
        pybind11::arg("staged") = true, pybind11::arg("max_chunk") = 0);
  m.def("forward", &rana_forward, "RaNA forward (CUDA): returns (out, lse)");
  m.def("backward", &rana_backward, "RaNA backward (CUDA): returns (dq, dk, dv, dbias)");
}
