// The one-thread CUDA RaNA kernels, and the entry points that pick them or the staged kernels (rana_cuda_staged.cu,
// used where they support the case). The one-thread kernels: the block bodies of rana_math.h with one lane per
// thread (L = 1), i.e. exactly the code the
// CPU tests run with `backend="cpu-scalar"`. One thread per (entry, head): blockIdx.y is the head, so the threads of
// a CUDA block share a head and walk neighbouring discs (entries in layout order are neighbouring pixels).
// Backward: dQ per query thread; dK/dV per key thread from the reverse neighbourhood, no atomics; the bias gradient
// through per-thread tables reduced in a fixed order (deterministic).
#include <cuda_runtime.h>

#include <stdexcept>
#include <string>

#include "rana_cuda_kernels.h"

namespace rana_cuda {

namespace {

void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess) throw std::runtime_error(std::string("RaNA CUDA ") + what + ": " + cudaGetErrorString(e));
}

__device__ rana::Block<1> one_entry(const int64_t* pix, int64_t e) {
  rana::Block<1> b;
  b.y = pix[2 * e];
  b.x0 = pix[2 * e + 1];
  b.span = 0;
  b.n = 1;
  b.id[0] = e;
  b.rel[0] = 0;
  return b;
}

template <typename T, int DK, int DV>
__global__ void __launch_bounds__(kThreads) forward_kernel(rana::Op<T> op, rana::Operand<T> q, const T* kt,
                                                            const T* vt, const int64_t* qpix, int64_t nq, T* out,
                                                            T* lse) {
  const int64_t e = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const int h = blockIdx.y;
  if (e >= nq) return;
  const rana::Block<1> b = one_entry(qpix, e);
  const rana::LaneTable<1> lt = rana::lane_table<1, 1>(b, op.rows, op.H, h, 1);
  rana::forward_block<T, 1, DK, DV, kBuffer, 0>(op, b, lt, rana::PixelWalk{op.g, op.rows, op.g.offsets, 1, b.y, b.x0, 0},
                                              h, q, kt, vt, out, lse);
}

template <typename T, int DK, int DV>
__global__ void __launch_bounds__(kThreads) dq_kernel(rana::Op<T> op, rana::Operand<T> q, rana::Operand<T> dout,
                                                       const T* lse, const T* delta, const T* kt, const T* vt,
                                                       const int64_t* qpix, int64_t nq, rana::Output<T> dq) {
  const int64_t e = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const int h = blockIdx.y;
  if (e >= nq) return;
  const rana::Block<1> b = one_entry(qpix, e);
  const rana::LaneTable<1> lt = rana::lane_table<1, 1>(b, op.rows, op.H, h, 1);
  rana::backward_dq_block<T, 1, DK, DV, kBuffer, 0>(op, b, lt,
                                                  rana::PixelWalk{op.g, op.rows, op.g.offsets, 1, b.y, b.x0, 0}, h,
                                                  q, dout, lse, delta, kt, vt, dq);
}

template <typename T, int DK, int DV, bool BIAS>
__global__ void __launch_bounds__(kThreads) dkdv_kernel(rana::Op<T> op, const T* qst, const T* dost, const T* lse_s,
                                                         const T* delta_s, rana::Operand<T> k, rana::Operand<T> v,
                                                         const int64_t* q_ptr, const int64_t* kpix, int64_t nk,
                                                         rana::Output<T> dk, rana::Output<T> dv, T* partial) {
  const int64_t j = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const int h = blockIdx.y;
  const int tw = rana::table_width(op.rows.R), o = rana::table_centre(op.rows.R);
  T tab[BIAS ? kMaxTable : 1];
  if (BIAS)
    for (int i = 0; i < op.rows.n * tw; ++i) tab[i] = T(0);
  if (j < nk) {
    const rana::Block<1> b = one_entry(kpix, j);
    const rana::LaneTable<1> lt = rana::lane_table<1, 1>(b, op.rows, op.H, h, -1);
    rana::backward_dkdv_block<T, 1, DK, DV, kBuffer, 0>(op, b, lt, rana::PixelWalk{op.g, op.rows, q_ptr, -1, b.y, b.x0, 0},
                                                      h, qst, dost, lse_s, delta_s, k, v, dk, dv,
                                                      BIAS ? tab : nullptr);
  }
  if constexpr (BIAS) {  // every table entry: a fixed-order tree over the block's threads
    __shared__ T red[kThreads];
    const int side = 2 * op.rows.R + 1;
    T* part = partial + (int64_t(h) * gridDim.x + blockIdx.x) * side * side;
    for (int r = 0; r < op.rows.n; ++r)
      for (int dx = op.rows.dx0[r]; dx <= op.rows.dx1[r]; ++dx) {
        red[threadIdx.x] = tab[r * tw + o + dx];
        __syncthreads();
        for (int s = kThreads / 2; s > 0; s >>= 1) {
          if (threadIdx.x < s) red[threadIdx.x] += red[threadIdx.x + s];
          __syncthreads();
        }
        if (threadIdx.x == 0) part[(op.rows.dy[r] + op.rows.R) * side + dx + op.rows.R] = red[0];
        __syncthreads();
      }
  }
}

// dbias[h, e] = sum over blocks of partial[h, block, e], blocks in order. Entries outside the disc stay 0.
template <typename T>
__global__ void sum_partials(const T* partial, int64_t blocks, int H, int side2, T* dbias) {
  const int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= int64_t(H) * side2) return;
  const int h = int(i / side2), e = int(i % side2);
  T acc = T(0);
  for (int64_t b = 0; b < blocks; ++b) acc += partial[(int64_t(h) * blocks + b) * side2 + e];
  dbias[i] = acc;
}

dim3 grid_for(int64_t n, int H) { return dim3(unsigned((n + kThreads - 1) / kThreads), unsigned(H)); }

}  // namespace

template <typename T>
void forward(const rana::Op<T>& op, const rana::Operand<T>& q, const T* kt, const T* vt, const int64_t* qpix,
             int64_t nq, T* out, T* lse, void* stream) {
  if (staged_options().enabled && staged_forward(op, q, kt, vt, qpix, nq, out, lse, stream)) return;
  if (nq == 0) return;
  rana::dispatch_head_dims<T>(op.dk, op.dv, [&]<int DK, int DV>() {
    forward_kernel<T, DK, DV><<<grid_for(nq, op.H), kThreads, 0, cudaStream_t(stream)>>>(op, q, kt, vt, qpix, nq,
                                                                                          out, lse);
  });
  check(cudaGetLastError(), "forward launch");
}

template <typename T>
void backward_dq(const rana::Op<T>& op, const rana::Operand<T>& q, const rana::Operand<T>& dout, const T* lse,
                 const T* delta, const T* kt, const T* vt, const int64_t* qpix, int64_t nq,
                 const rana::Output<T>& dq, void* stream) {
  if (staged_options().enabled && staged_backward_dq(op, q, dout, lse, delta, kt, vt, qpix, nq, dq, stream)) return;
  if (nq == 0) return;
  rana::dispatch_head_dims<T>(op.dk, op.dv, [&]<int DK, int DV>() {
    dq_kernel<T, DK, DV><<<grid_for(nq, op.H), kThreads, 0, cudaStream_t(stream)>>>(op, q, dout, lse, delta, kt, vt,
                                                                                     qpix, nq, dq);
  });
  check(cudaGetLastError(), "dQ launch");
}

template <typename T>
void backward_dkdv(const rana::Op<T>& op, const T* qst, const T* dost, const T* lse_s, const T* delta_s,
                   const rana::Operand<T>& k, const rana::Operand<T>& v, const int64_t* q_ptr, const int64_t* kpix,
                   int64_t nk, const rana::Output<T>& dk, const rana::Output<T>& dv, T* dbias, T* partial,
                   void* stream) {
  if (staged_options().enabled &&
      staged_backward_dkdv(op, qst, dost, lse_s, delta_s, k, v, q_ptr, kpix, nk, dk, dv, dbias, partial, stream))
    return;
  const int side = 2 * op.rows.R + 1;
  if (dbias && op.rows.R > kMaxRadius)
    throw std::invalid_argument("RaNA CUDA: the bias gradient supports radii below 8");
  if (nk == 0) {
    if (dbias) check(cudaMemsetAsync(dbias, 0, sizeof(T) * op.H * side * side, cudaStream_t(stream)), "memset");
    return;
  }
  const dim3 grid = grid_for(nk, op.H);
  if (dbias) check(cudaMemsetAsync(partial, 0, sizeof(T) * partial_size(nk, op.H, op.rows.R), cudaStream_t(stream)),
                   "memset");
  rana::dispatch_head_dims<T>(op.dk, op.dv, [&]<int DK, int DV>() {
    if (dbias)
      dkdv_kernel<T, DK, DV, true><<<grid, kThreads, 0, cudaStream_t(stream)>>>(op, qst, dost, lse_s, delta_s, k, v,
                                                                                q_ptr, kpix, nk, dk, dv, partial);
    else
      dkdv_kernel<T, DK, DV, false><<<grid, kThreads, 0, cudaStream_t(stream)>>>(op, qst, dost, lse_s, delta_s, k, v,
                                                                                 q_ptr, kpix, nk, dk, dv, partial);
  });
  check(cudaGetLastError(), "dK/dV launch");
  if (dbias) sum_bias_partials(partial, grid.x, op.H, side * side, dbias, stream);
}

template <typename T>
void sum_bias_partials(const T* partial, int64_t blocks, int H, int side2, T* dbias, void* stream) {
  const int64_t n = int64_t(H) * side2;
  sum_partials<T><<<unsigned((n + 255) / 256), 256, 0, cudaStream_t(stream)>>>(partial, blocks, H, side2, dbias);
  check(cudaGetLastError(), "bias-gradient reduction launch");
}

#define RANA_CUDA_INSTANTIATE(T)                                                                                   \
  template void forward<T>(const rana::Op<T>&, const rana::Operand<T>&, const T*, const T*, const int64_t*,       \
                           int64_t, T*, T*, void*);                                                               \
  template void backward_dq<T>(const rana::Op<T>&, const rana::Operand<T>&, const rana::Operand<T>&, const T*,    \
                               const T*, const T*, const T*, const int64_t*, int64_t, const rana::Output<T>&,     \
                               void*);                                                                            \
  template void backward_dkdv<T>(const rana::Op<T>&, const T*, const T*, const T*, const T*,                      \
                                 const rana::Operand<T>&, const rana::Operand<T>&, const int64_t*, const int64_t*, \
                                 int64_t, const rana::Output<T>&, const rana::Output<T>&, T*, T*, void*);       \
  template void sum_bias_partials<T>(const T*, int64_t, int, int, T*, void*);

RANA_CUDA_INSTANTIATE(float)
RANA_CUDA_INSTANTIATE(double)

}  // namespace rana_cuda
