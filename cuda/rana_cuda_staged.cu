// The staged CUDA RaNA kernels: a block of neighbouring entries shares the rows it streams through shared memory.
//
// Why: the one-thread-per-(entry, head) kernels of rana_cuda_kernels.cu read every key row from global memory
// once per query (the 32 threads of a warp each fetching their own scattered 4-byte channels), and keep a
// 32-key softmax buffer and, for the bias gradient, a table of up to 435 scalars per thread in local memory
// (register spills). Here a block holds QB consecutive entries x H heads (thread t: entry t / H, head t % H). For
// each run of its entries on one grid row and each disc row, the rows its discs reach there form ONE contiguous
// range of the streamed operand (the layout stores a grid row's bins in pixel order), so the block copies that
// range into shared memory in chunks (coalesced: an entry's [d, H] channel-major row is contiguous), each thread
// then reads the rows of its own disc from there. The softmax is online per key (no buffer), and the bias gradient
// goes to a per-thread column of a shared-memory table. Same maths as rana_math.h's bodies (base-2 logits,
// FlashAttention-2 backward), summed in a fixed order: deterministic.
#include <cuda_runtime.h>

#include <algorithm>
#include <stdexcept>
#include <string>

#include "rana_cuda_kernels.h"

namespace rana_cuda {

namespace {

void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess)
    throw std::runtime_error(std::string("RaNA CUDA (staged) ") + what + ": " + cudaGetErrorString(e));
}

__device__ __forceinline__ float exp2_dev(float x) { return exp2f(x); }
__device__ __forceinline__ double exp2_dev(double x) { return exp2(x); }
__device__ __forceinline__ float log2_dev(float x) { return log2f(x); }
__device__ __forceinline__ double log2_dev(double x) { return log2(x); }

// The block's entries grouped into runs of consecutive entries with the same grid row (entries in layout order give
// one or two runs; any order stays correct, only slower). Filled by thread 0.
struct Runs {
  int n;
  int first[kStagedMaxEntries + 1];  // entry (block-local) where run i starts; first[n] = entries in the block
  int64_t y[kStagedMaxEntries], xmin[kStagedMaxEntries], xmax[kStagedMaxEntries];
};

// Loads the block's entry pixels and groups them into runs. pix [N, 2] (y, x); e0: the block's first entry.
__device__ void find_runs(const int64_t* pix, int64_t e0, int qb, int64_t n, Runs& runs, int64_t* s_y,
                          int64_t* s_x) {
  const int cnt = int(min(int64_t(qb), n - e0));
  for (int i = threadIdx.x; i < cnt; i += blockDim.x) {
    s_y[i] = pix[2 * (e0 + i)];
    s_x[i] = pix[2 * (e0 + i) + 1];
  }
  __syncthreads();
  if (threadIdx.x == 0) {
    int k = -1;
    for (int i = 0; i < cnt; ++i) {
      if (k < 0 || s_y[i] != runs.y[k]) {
        ++k;
        runs.first[k] = i;
        runs.y[k] = s_y[i];
        runs.xmin[k] = runs.xmax[k] = s_x[i];
      } else {
        runs.xmin[k] = min(runs.xmin[k], s_x[i]);
        runs.xmax[k] = max(runs.xmax[k], s_x[i]);
      }
    }
    runs.n = k + 1;
    runs.first[k + 1] = cnt;
  }
  __syncthreads();
}

// Copies streamed rows [c0, c0 + n) of x ([N, d, H] channel-major, w = d H scalars per row) to shared memory with a
// row stride of w + 1 scalars (odd: threads reading different rows at the same channel hit different banks).
template <typename T>
__device__ __forceinline__ void stage_rows(const T* __restrict__ x, int64_t c0, int n, int w, T* dst) {
  const T* src = x + c0 * w;
  for (int i = threadIdx.x; i < n * w; i += blockDim.x) dst[(i / w) * (w + 1) + i % w] = src[i];
}

// Pixel x of each staged row: rows of pixel p are ptr[row + p] .. ptr[row + p + 1] (pixels a..b of the grid row).
__device__ __forceinline__ void stage_pixels(const int64_t* ptr, int64_t row, int64_t a, int64_t b, int64_t c0, int n,
                                             int32_t* dst) {
  for (int64_t p = a + threadIdx.x; p <= b; p += blockDim.x) {
    const int64_t f = max(ptr[row + p], c0), l = min(ptr[row + p + 1], c0 + n);
    for (int64_t j = f; j < l; ++j) dst[j - c0] = int32_t(p);
  }
}

// Shared memory of a chunk of kc streamed rows: two operands of widths w1, w2 (+1 padding each), then pixel x.
template <typename T>
size_t chunk_bytes(int kc, int w1, int w2, int extra_scalars) {
  return size_t(kc) * (sizeof(T) * (w1 + 1 + w2 + 1 + extra_scalars) + sizeof(int32_t));
}

// Blocks per multiprocessor the register budget aims at: the per-thread operands (2 (DK + DV) scalars in the
// dK/dV pass, about as many in the forward and dQ with their unrolled loops) plus ~64 registers of indices, out of
// 64K registers. Unbounded, ptxas used up to 1.4x that and left 3 blocks (384 threads) per multiprocessor.
template <typename T, int DK, int DV>
constexpr int min_blocks() {
  const int regs = (sizeof(T) / 4) * 2 * (DK + DV) + 64;
  const int b = 65536 / (kThreads * regs);
  return b < 1 ? 1 : b > 8 ? 8 : b;
}

// ---- forward and dQ: the keys of a query block ----------------------------------------------------------
// DQ = false: forward (online softmax; out [Nq, H, DV], lse [Nq, H] natural units, -inf for an empty disc).
// DQ = true: dQ (p = exp(s - lse), ds = p (dO.v - delta), dq = scale sum ds k; lse +inf for an empty disc).
template <typename T, int DK, int DV, bool DQ>
__global__ void __launch_bounds__(kThreads, min_blocks<T, DK, DV>())
    query_kernel(rana::Op<T> op, rana::Operand<T> q, rana::Operand<T> dout, const T* lse_in, const T* delta,
                 const T* __restrict__ kt, const T* __restrict__ vt, const int64_t* qpix, int64_t nq, int kc, T* out,
                 T* lse_out, rana::Output<T> dq) {
  extern __shared__ __align__(16) unsigned char smem_raw[];
  __shared__ Runs runs;
  __shared__ int64_t s_y[kStagedMaxEntries], s_x[kStagedMaxEntries];
  const int H = op.H, qb = kThreads / H, wk = DK * H, wv = DV * H;
  T* ks = reinterpret_cast<T*>(smem_raw);
  T* vs = ks + size_t(kc) * (wk + 1);
  int32_t* kx = reinterpret_cast<int32_t*>(vs + size_t(kc) * (wv + 1));
  const int64_t e0 = int64_t(blockIdx.x) * qb;
  find_runs(qpix, e0, qb, nq, runs, s_y, s_x);

  const int el = threadIdx.x / H, h = threadIdx.x % H;
  const int64_t e = e0 + el;
  const bool active = el < qb && e < nq;
  const int64_t W = op.g.Wk;
  const int tw = rana::table_width(op.rows.R), o = rana::table_centre(op.rows.R);
  T qr[DK], acc[DQ ? DK : DV], dr[DQ ? DV : 1];
  T m = -INFINITY, l = T(0), Lg = T(0), D = T(0);
  const T qmul = op.logit_scale();
#pragma unroll
  for (int c = 0; c < DK; ++c) qr[c] = active ? q.p[e * q.sN + h * q.sH + c * q.sC] * qmul : T(0);
#pragma unroll
  for (int c = 0; c < (DQ ? DK : DV); ++c) acc[c] = T(0);
  if constexpr (DQ) {
#pragma unroll
    for (int c = 0; c < DV; ++c) dr[c] = active ? dout.p[e * dout.sN + h * dout.sH + c * dout.sC] : T(0);
    if (active) {
      Lg = lse_in[e * H + h] * T(rana::kLog2e);
      D = delta[e * H + h];
    }
  }
  const int64_t my_x = active ? s_x[el] : 0;

  for (int ru = 0; ru < runs.n; ++ru) {
    const bool mine = active && el >= runs.first[ru] && el < runs.first[ru + 1];
    for (int r = 0; r < op.rows.n; ++r) {
      const int64_t yk = runs.y[ru] + op.rows.dy[r];
      if (yk < 0 || yk >= op.g.Hk) continue;
      const int64_t a = max(int64_t(0), runs.xmin[ru] + op.rows.dx0[r]);
      const int64_t b = min(W - 1, runs.xmax[ru] + op.rows.dx1[r]);
      if (a > b) continue;
      const int64_t row = yk * W;
      const int64_t kf = op.g.offsets[row + a], kl = op.g.offsets[row + b + 1];
      int64_t my_f = 0, my_l = 0;
      if (mine) {
        const int64_t pa = max(int64_t(0), my_x + op.rows.dx0[r]), pb = min(W - 1, my_x + op.rows.dx1[r]);
        if (pa <= pb) {
          my_f = op.g.offsets[row + pa];
          my_l = op.g.offsets[row + pb + 1];
        }
      }
      const T* bias_row = op.tab + (int64_t(h) * op.rows.n + r) * tw + o - my_x;
      for (int64_t c0 = kf; c0 < kl; c0 += kc) {
        const int n = int(min(int64_t(kc), kl - c0));
        __syncthreads();  // the previous chunk has been read
        stage_rows(kt, c0, n, wk, ks);
        stage_rows(vt, c0, n, wv, vs);
        stage_pixels(op.g.offsets, row, a, b, c0, n, kx);
        __syncthreads();
        const int j1 = int(max(my_f, c0) - c0), j2 = int(min(my_l, c0 + n) - c0);
        for (int j = j1; j < j2; ++j) {
          const T* kr = ks + j * (wk + 1) + h;
          const T* vr = vs + j * (wv + 1) + h;
          T s0 = T(0), s1 = T(0);
#pragma unroll
          for (int c = 0; c < DK; c += 2) {
            s0 += qr[c] * kr[c * H];
            if (c + 1 < DK) s1 += qr[c + 1] * kr[(c + 1) * H];
          }
          const T s = s0 + s1 + bias_row[kx[j]];
          if constexpr (DQ) {
            const T p = exp2_dev(s - Lg);
            T dp = T(0);
#pragma unroll
            for (int c = 0; c < DV; ++c) dp += dr[c] * vr[c * H];
            const T ds = p * (dp - D);
#pragma unroll
            for (int c = 0; c < DK; ++c) acc[c] += ds * kr[c * H];
          } else {
            if (s > m) {  // a new maximum: rescale what was summed
              const T corr = exp2_dev(m - s);
              l *= corr;
#pragma unroll
              for (int c = 0; c < DV; ++c) acc[c] *= corr;
              m = s;
            }
            const T p = exp2_dev(s - m);
            l += p;
#pragma unroll
            for (int c = 0; c < DV; ++c) acc[c] += p * vr[c * H];
          }
        }
      }
    }
  }
  if (!active) return;
  if constexpr (DQ) {
#pragma unroll
    for (int c = 0; c < DK; ++c) dq.p[e * dq.sN + h * dq.sH + c * dq.sC] = acc[c] * op.scale;
  } else {
    const T inv = l == T(0) ? T(0) : T(1) / l;
    T* o_row = out + (e * H + h) * DV;
#pragma unroll
    for (int c = 0; c < DV; ++c) o_row[c] = acc[c] * inv;
    lse_out[e * H + h] = l == T(0) ? T(-INFINITY) : (m + log2_dev(l)) * T(rana::kLn2);
  }
}

// ---- dK and dV: the queries whose discs hold a key block -------------------------------------------------
// Queries sorted by centre pixel: qst [Nq, dk, H], dost [Nq, dv, H] (channel-major), lse_s, delta_s [Nq, H]
// (lse +inf for an empty disc), q_ptr their CSR over the key grid. A key at pixel kx of grid row ky is in disc row
// r of the queries at pixels kx - dx1_r .. kx - dx0_r of grid row ky - dy_r. With BIAS, ds is summed per thread
// into its column of a shared [side^2][kThreads] table, then per head over the block's entries in order into
// partial[h][block][side^2] (sum_partials adds the blocks in order).
template <typename T, int DK, int DV, bool BIAS>
__global__ void __launch_bounds__(kThreads, min_blocks<T, DK, DV>())
    key_kernel(rana::Op<T> op, const T* __restrict__ qst, const T* __restrict__ dost, const T* lse_s,
               const T* delta_s, rana::Operand<T> k, rana::Operand<T> v, const int64_t* q_ptr, const int64_t* kpix,
               int64_t nk, int kc, rana::Output<T> dk, rana::Output<T> dv, T* partial) {
  extern __shared__ __align__(16) unsigned char smem_raw[];
  __shared__ Runs runs;
  __shared__ int64_t s_y[kStagedMaxEntries], s_x[kStagedMaxEntries];
  const int H = op.H, qb = kThreads / H, wq = DK * H, wd = DV * H;
  const int R = op.rows.R, side = 2 * R + 1;
  T* tab = reinterpret_cast<T*>(smem_raw);  // [side^2][kThreads] with BIAS
  T* qs = tab + (BIAS ? size_t(side) * side * kThreads : 0);
  T* ds_ = qs + size_t(kc) * (wq + 1);
  T* ls = ds_ + size_t(kc) * (wd + 1);  // lse * log2(e), then delta: [kc][H] each
  T* dls = ls + size_t(kc) * H;
  int32_t* qx = reinterpret_cast<int32_t*>(dls + size_t(kc) * H);
  const int64_t e0 = int64_t(blockIdx.x) * qb;
  if (BIAS)
    for (int i = threadIdx.x; i < side * side * kThreads; i += blockDim.x) tab[i] = T(0);
  find_runs(kpix, e0, qb, nk, runs, s_y, s_x);  // (its barrier also orders the zeroing above)

  const int el = threadIdx.x / H, h = threadIdx.x % H;
  const int64_t e = e0 + el;
  const bool active = el < qb && e < nk;
  const int64_t W = op.g.Wk;
  const int tw = rana::table_width(R), o = rana::table_centre(R);
  T kr[DK], vr[DV], acc_k[DK], acc_v[DV];
  const T kmul = op.logit_scale();
#pragma unroll
  for (int c = 0; c < DK; ++c) {
    kr[c] = active ? k.p[e * k.sN + h * k.sH + c * k.sC] * kmul : T(0);
    acc_k[c] = T(0);
  }
#pragma unroll
  for (int c = 0; c < DV; ++c) {
    vr[c] = active ? v.p[e * v.sN + h * v.sH + c * v.sC] : T(0);
    acc_v[c] = T(0);
  }
  const int64_t my_x = active ? s_x[el] : 0;

  for (int ru = 0; ru < runs.n; ++ru) {
    const bool mine = active && el >= runs.first[ru] && el < runs.first[ru + 1];
    for (int r = 0; r < op.rows.n; ++r) {
      const int64_t yq = runs.y[ru] - op.rows.dy[r];
      if (yq < 0 || yq >= op.g.Hk) continue;
      const int64_t a = max(int64_t(0), runs.xmin[ru] - op.rows.dx1[r]);
      const int64_t b = min(W - 1, runs.xmax[ru] - op.rows.dx0[r]);
      if (a > b) continue;
      const int64_t row = yq * W;
      const int64_t qf = q_ptr[row + a], ql = q_ptr[row + b + 1];
      int64_t my_f = 0, my_l = 0;
      if (mine) {
        const int64_t pa = max(int64_t(0), my_x - op.rows.dx1[r]), pb = min(W - 1, my_x - op.rows.dx0[r]);
        if (pa <= pb) {
          my_f = q_ptr[row + pa];
          my_l = q_ptr[row + pb + 1];
        }
      }
      // the logit's bias: dx = key pixel - query pixel
      const T* bias_row = op.tab + (int64_t(h) * op.rows.n + r) * tw + o + my_x;
      T* tab_row = tab + int64_t((op.rows.dy[r] + R) * side + R + my_x) * kThreads + threadIdx.x;
      for (int64_t c0 = qf; c0 < ql; c0 += kc) {
        const int n = int(min(int64_t(kc), ql - c0));
        __syncthreads();
        stage_rows(qst, c0, n, wq, qs);
        stage_rows(dost, c0, n, wd, ds_);
        for (int i = threadIdx.x; i < n * H; i += blockDim.x) {
          ls[i] = lse_s[c0 * H + i] * T(rana::kLog2e);
          dls[i] = delta_s[c0 * H + i];
        }
        stage_pixels(q_ptr, row, a, b, c0, n, qx);
        __syncthreads();
        const int j1 = int(max(my_f, c0) - c0), j2 = int(min(my_l, c0 + n) - c0);
        int32_t cur = -1;  // the query pixel whose ds sum is open (BIAS)
        T sum = T(0);
        for (int j = j1; j < j2; ++j) {
          const T* qrow = qs + j * (wq + 1) + h;
          const T* drow = ds_ + j * (wd + 1) + h;
          T s0 = T(0), s1 = T(0), d0 = T(0), d1 = T(0);
#pragma unroll
          for (int c = 0; c < DK; c += 2) {
            s0 += kr[c] * qrow[c * H];
            if (c + 1 < DK) s1 += kr[c + 1] * qrow[(c + 1) * H];
          }
#pragma unroll
          for (int c = 0; c < DV; c += 2) {
            d0 += vr[c] * drow[c * H];
            if (c + 1 < DV) d1 += vr[c + 1] * drow[(c + 1) * H];
          }
          const int32_t px = qx[j];
          const T p = exp2_dev(s0 + s1 + bias_row[-px] - ls[j * H + h]);
          const T ds = p * (d0 + d1 - dls[j * H + h]);
#pragma unroll
          for (int c = 0; c < DV; ++c) acc_v[c] += p * drow[c * H];
#pragma unroll
          for (int c = 0; c < DK; ++c) acc_k[c] += ds * qrow[c * H];
          if constexpr (BIAS) {
            if (px != cur) {
              if (cur >= 0) tab_row[-int64_t(cur) * kThreads] += sum;
              cur = px;
              sum = T(0);
            }
            sum += ds;
          }
        }
        if (BIAS && cur >= 0) tab_row[-int64_t(cur) * kThreads] += sum;
      }
    }
  }
  if (active) {
#pragma unroll
    for (int c = 0; c < DK; ++c) dk.p[e * dk.sN + h * dk.sH + c * dk.sC] = acc_k[c] * op.scale;
#pragma unroll
    for (int c = 0; c < DV; ++c) dv.p[e * dv.sN + h * dv.sH + c * dv.sC] = acc_v[c];
  }
  if constexpr (BIAS) {  // per head and table entry: the block's entries in order
    __syncthreads();
    const int s2 = side * side;
    for (int i = threadIdx.x; i < H * s2; i += blockDim.x) {
      const int hh = i / s2, slot = i % s2;
      T acc = T(0);
      for (int en = 0; en < qb; ++en) acc += tab[int64_t(slot) * kThreads + en * H + hh];
      partial[(int64_t(hh) * gridDim.x + blockIdx.x) * s2 + slot] = acc;
    }
  }
}

int max_dynamic_smem() {
  int dev = 0, bytes = 0;
  check(cudaGetDevice(&dev), "device query");
  check(cudaDeviceGetAttribute(&bytes, cudaDevAttrMaxSharedMemoryPerBlockOptin, dev), "shared-memory query");
  return bytes - int(sizeof(Runs) + 2 * kStagedMaxEntries * sizeof(int64_t)) - 1024;
}

// Rows per chunk: as many as fit (at most staged_options().max_chunk), given the fixed part of the shared memory;
// 0 if fewer than kStagedMinChunk fit (the caller then uses the one-thread kernels).
template <typename T>
int chunk_rows(int w1, int w2, int extra_scalars, size_t fixed) {
  const long avail = long(max_dynamic_smem()) - long(fixed);
  const long per_row = long(chunk_bytes<T>(1, w1, w2, extra_scalars));
  const int kc = int(std::min<long>(staged_options().max_chunk, avail > 0 ? avail / per_row : 0));
  return kc >= kStagedMinChunk ? kc : 0;
}

template <typename K>
void allow_smem(K kernel, size_t bytes) {
  check(cudaFuncSetAttribute(kernel, cudaFuncAttributeMaxDynamicSharedMemorySize, int(bytes)), "shared-memory size");
}

}  // namespace

StagedOptions& staged_options() {
  static StagedOptions options;
  return options;
}

bool staged_supported(int H) { return H >= 1 && H <= kThreads; }  // kThreads / H entries per block, >= 1

namespace {

// The forward (DQ = false: q, kt, vt -> out, lse) and the dQ pass (DQ = true: also dout, lse, delta -> dq) share
// their launch: the same blocks, chunk size and shared memory. False where the staged kernel does not fit.
template <typename T, bool DQ>
bool launch_query(const rana::Op<T>& op, const rana::Operand<T>& q, const rana::Operand<T>& dout, const T* lse_in,
                  const T* delta, const T* kt, const T* vt, const int64_t* qpix, int64_t nq, T* out, T* lse_out,
                  const rana::Output<T>& dq, void* stream) {
  if (!staged_supported(op.H)) return false;
  const int kc = chunk_rows<T>(op.dk * op.H, op.dv * op.H, 0, 0);
  if (kc == 0) return false;
  if (nq == 0) return true;
  const int qb = kThreads / op.H;
  const size_t bytes = chunk_bytes<T>(kc, op.dk * op.H, op.dv * op.H, 0);
  const unsigned blocks = unsigned((nq + qb - 1) / qb);
  rana::dispatch_head_dims<T>(op.dk, op.dv, [&]<int DK, int DV>() {
    auto kern = query_kernel<T, DK, DV, DQ>;
    allow_smem(kern, bytes);
    kern<<<blocks, kThreads, bytes, cudaStream_t(stream)>>>(op, q, dout, lse_in, delta, kt, vt, qpix, nq, kc, out,
                                                            lse_out, dq);
  });
  check(cudaGetLastError(), DQ ? "dQ launch" : "forward launch");
  return true;
}

}  // namespace

template <typename T>
bool staged_forward(const rana::Op<T>& op, const rana::Operand<T>& q, const T* kt, const T* vt, const int64_t* qpix,
                    int64_t nq, T* out, T* lse, void* stream) {
  return launch_query<T, false>(op, q, rana::Operand<T>{}, nullptr, nullptr, kt, vt, qpix, nq, out, lse,
                                rana::Output<T>{}, stream);
}

template <typename T>
bool staged_backward_dq(const rana::Op<T>& op, const rana::Operand<T>& q, const rana::Operand<T>& dout, const T* lse,
                        const T* delta, const T* kt, const T* vt, const int64_t* qpix, int64_t nq,
                        const rana::Output<T>& dq, void* stream) {
  return launch_query<T, true>(op, q, dout, lse, delta, kt, vt, qpix, nq, nullptr, nullptr, dq, stream);
}

template <typename T>
bool staged_backward_dkdv(const rana::Op<T>& op, const T* qst, const T* dost, const T* lse_s, const T* delta_s,
                          const rana::Operand<T>& k, const rana::Operand<T>& v, const int64_t* q_ptr,
                          const int64_t* kpix, int64_t nk, const rana::Output<T>& dk, const rana::Output<T>& dv,
                          T* dbias, T* partial, void* stream) {
  if (!staged_supported(op.H)) return false;
  const int side = 2 * op.rows.R + 1;
  const size_t table = dbias ? sizeof(T) * size_t(side) * side * kThreads : 0;
  const int kc = chunk_rows<T>(op.dk * op.H, op.dv * op.H, 2 * op.H, table);
  if (kc == 0) return false;
  if (nk == 0) {
    if (dbias) check(cudaMemsetAsync(dbias, 0, sizeof(T) * op.H * side * side, cudaStream_t(stream)), "memset");
    return true;
  }
  const int qb = kThreads / op.H;
  const size_t bytes = table + chunk_bytes<T>(kc, op.dk * op.H, op.dv * op.H, 2 * op.H);
  const unsigned blocks = unsigned((nk + qb - 1) / qb);
  rana::dispatch_head_dims<T>(op.dk, op.dv, [&]<int DK, int DV>() {
    if (dbias) {
      auto kern = key_kernel<T, DK, DV, true>;
      allow_smem(kern, bytes);
      kern<<<blocks, kThreads, bytes, cudaStream_t(stream)>>>(op, qst, dost, lse_s, delta_s, k, v, q_ptr, kpix, nk,
                                                              kc, dk, dv, partial);
    } else {
      auto kern = key_kernel<T, DK, DV, false>;
      allow_smem(kern, bytes);
      kern<<<blocks, kThreads, bytes, cudaStream_t(stream)>>>(op, qst, dost, lse_s, delta_s, k, v, q_ptr, kpix, nk,
                                                              kc, dk, dv, partial);
    }
  });
  check(cudaGetLastError(), "dK/dV launch");
  if (dbias) sum_bias_partials(partial, int64_t(blocks), op.H, side * side, dbias, stream);
  return true;
}

#define RANA_STAGED_INSTANTIATE(T)                                                                                 \
  template bool staged_forward<T>(const rana::Op<T>&, const rana::Operand<T>&, const T*, const T*, const int64_t*, \
                                  int64_t, T*, T*, void*);                                                         \
  template bool staged_backward_dq<T>(const rana::Op<T>&, const rana::Operand<T>&, const rana::Operand<T>&,        \
                                      const T*, const T*, const T*, const T*, const int64_t*, int64_t,             \
                                      const rana::Output<T>&, void*);                                              \
  template bool staged_backward_dkdv<T>(const rana::Op<T>&, const T*, const T*, const T*, const T*,                \
                                        const rana::Operand<T>&, const rana::Operand<T>&, const int64_t*,          \
                                        const int64_t*, int64_t, const rana::Output<T>&, const rana::Output<T>&,   \
                                        T*, T*, void*);

RANA_STAGED_INSTANTIATE(float)
RANA_STAGED_INSTANTIATE(double)

}  // namespace rana_cuda
