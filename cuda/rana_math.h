// RaNA (ragged neighbourhood attention) maths shared by the CPU and CUDA kernels.
//
// Everything here is a plain inline function over raw pointers, marked RANA_HD so that it compiles as
// host code (the C++/OpenMP kernels in rana_cpu.cpp) and as device code (the CUDA kernels). The CPU tests
// therefore exercise the exact per-query and per-key bodies that the GPU runs.
//
// Layout (ranad's ragged convention): keys/values are bins of a Hk x Wk grid, k_offsets[p]..k_offsets[p+1]
// are the bins of key pixel p (row-major). q [Nq, H, DK], k [Nk, H, DK], v [Nk, H, DV], out [Nq, H, DV],
// lse [Nq, H]. The neighbourhood of a query centred at (y, x) is every key bin of every pixel
// (y + dy, x + dx) with dy^2 + dx^2 <= r^2 (the paper's Eq. 2), described by "disc rows": for each dy a
// contiguous span [dx0, dx1], so the bins of one row are one contiguous range of keys.
#pragma once

#include <cmath>
#include <cstdint>

#if defined(__CUDACC__)
#define RANA_HD __host__ __device__ __forceinline__
#else
#define RANA_HD inline __attribute__((always_inline))
#endif

namespace rana {

// Keys are fed to the online softmax in blocks of this many (logits buffered in registers/L1).
constexpr int kKeyBlock = 32;

struct DiscRows {
  int n;              // number of rows
  int R;              // floor(radius): bias is [H, 2R+1, 2R+1]
  const int32_t* dy;  // [n]
  const int32_t* dx0; // [n]
  const int32_t* dx1; // [n]
};

struct Grid {
  const int64_t* offsets;  // [Hk*Wk+1]
  int64_t Hk, Wk;
};

template <typename T>
RANA_HD T neg_inf() { return -INFINITY; }

template <typename T, int D>
RANA_HD T dot(const T* __restrict__ a, const T* __restrict__ b, int d) {
  const int n = D > 0 ? D : d;
  T s = T(0);
#if !defined(__CUDACC__)
#pragma omp simd reduction(+ : s)
#endif
  for (int c = 0; c < n; ++c) s += a[c] * b[c];
  return s;
}

// acc = acc * alpha + beta * x
template <typename T, int D>
RANA_HD void scale_axpy(T* __restrict__ acc, T alpha, T beta, const T* __restrict__ x, int d) {
  const int n = D > 0 ? D : d;
#if !defined(__CUDACC__)
#pragma omp simd
#endif
  for (int c = 0; c < n; ++c) acc[c] = acc[c] * alpha + beta * x[c];
}

// acc += beta * x
template <typename T, int D>
RANA_HD void axpy(T* __restrict__ acc, T beta, const T* __restrict__ x, int d) {
  const int n = D > 0 ? D : d;
#if !defined(__CUDACC__)
#pragma omp simd
#endif
  for (int c = 0; c < n; ++c) acc[c] += beta * x[c];
}

// Clip one disc row to the grid: returns false when the row is outside; otherwise the key-bin range
// [kb, ke) and the first pixel column px0 of the clipped span.
RANA_HD bool row_span(const Grid& g, const DiscRows& rows, int r, int64_t y, int64_t x, int64_t* px0,
                      int64_t* px1) {
  const int64_t py = y + rows.dy[r];
  if (py < 0 || py >= g.Hk) return false;
  int64_t a = x + rows.dx0[r], b = x + rows.dx1[r];
  if (a < 0) a = 0;
  if (b > g.Wk - 1) b = g.Wk - 1;
  if (a > b) return false;
  *px0 = py * g.Wk + a;
  *px1 = py * g.Wk + b;
  return true;
}

template <typename T>
RANA_HD T bias_at(const T* bias, int h, int R, int dy, int dx) {
  const int side = 2 * R + 1;
  return bias ? bias[(h * side + (dy + R)) * side + (dx + R)] : T(0);
}

// Online-softmax state of one query and head: running max m, running sum l, accumulator acc[DV].
template <typename T, int DV>
struct SoftmaxAcc {
  T m, l;
  T* acc;
  int dv;

  // Fold a block of n logits s[] with value rows v_rows[j] into the state (FlashAttention's rescale).
  RANA_HD void fold(const T* s, const T* const* v_rows, int n) {
    T mb = m;
    for (int j = 0; j < n; ++j) mb = s[j] > mb ? s[j] : mb;
    if (mb == neg_inf<T>()) return;
    const T corr = (m == neg_inf<T>()) ? T(0) : std::exp(m - mb);
    l *= corr;
    bool first = true;
    for (int j = 0; j < n; ++j) {
      const T p = std::exp(s[j] - mb);
      l += p;
      if (first) {
        scale_axpy<T, DV>(acc, corr, p, v_rows[j], dv);
        first = false;
      } else {
        axpy<T, DV>(acc, p, v_rows[j], dv);
      }
    }
    m = mb;
  }
};

// Forward for one query and one head: out_h[DV] (written) and the log-sum-exp (returned; -inf when the
// disc holds no key bins, and then out_h is zero).
template <typename T, int DK, int DV>
RANA_HD T forward_query_head(const T* __restrict__ q_h, const T* __restrict__ k, const T* __restrict__ v,
                             const Grid& g, const DiscRows& rows, const T* bias, int64_t y, int64_t x, int h,
                             int H, int dk, int dv, T scale, T* __restrict__ out_h) {
  const int nk = DK > 0 ? DK : dk, nv = DV > 0 ? DV : dv;
  for (int c = 0; c < nv; ++c) out_h[c] = T(0);
  SoftmaxAcc<T, DV> st{neg_inf<T>(), T(0), out_h, nv};
  T s[kKeyBlock];
  const T* vr[kKeyBlock];
  int n = 0;
  for (int r = 0; r < rows.n; ++r) {
    int64_t p0, p1;
    if (!row_span(g, rows, r, y, x, &p0, &p1)) continue;
    const int dy = rows.dy[r];
    for (int64_t p = p0; p <= p1; ++p) {
      const int dx = int(p - (y + dy) * g.Wk - x);
      const T b = bias_at(bias, h, rows.R, dy, dx);
      for (int64_t j = g.offsets[p]; j < g.offsets[p + 1]; ++j) {
        s[n] = dot<T, DK>(q_h, k + (j * H + h) * nk, nk) * scale + b;
        vr[n] = v + (j * H + h) * nv;
        if (++n == kKeyBlock) {
          st.fold(s, vr, n);
          n = 0;
        }
      }
    }
  }
  if (n) st.fold(s, vr, n);
  if (st.m == neg_inf<T>()) return neg_inf<T>();
  const T inv = T(1) / st.l;
  for (int c = 0; c < nv; ++c) out_h[c] *= inv;
  return st.m + std::log(st.l);
}

// dQ for one query and head (FlashAttention-2 recomputation from the saved log-sum-exp):
// p = exp(s - lse), ds = p * (dO.v - delta), dq += scale * ds * k. delta = dO.O for this query/head.
template <typename T, int DK, int DV>
RANA_HD void backward_dq_head(const T* __restrict__ q_h, const T* __restrict__ k, const T* __restrict__ v,
                              const T* __restrict__ do_h, T lse, T delta, const Grid& g, const DiscRows& rows,
                              const T* bias, int64_t y, int64_t x, int h, int H, int dk, int dv, T scale,
                              T* __restrict__ dq_h) {
  const int nk = DK > 0 ? DK : dk, nv = DV > 0 ? DV : dv;
  for (int c = 0; c < nk; ++c) dq_h[c] = T(0);
  if (lse == neg_inf<T>()) return;
  for (int r = 0; r < rows.n; ++r) {
    int64_t p0, p1;
    if (!row_span(g, rows, r, y, x, &p0, &p1)) continue;
    const int dy = rows.dy[r];
    for (int64_t p = p0; p <= p1; ++p) {
      const int dx = int(p - (y + dy) * g.Wk - x);
      const T b = bias_at(bias, h, rows.R, dy, dx);
      for (int64_t j = g.offsets[p]; j < g.offsets[p + 1]; ++j) {
        const T* k_j = k + (j * H + h) * nk;
        const T pr = std::exp(dot<T, DK>(q_h, k_j, nk) * scale + b - lse);
        const T ds = pr * (dot<T, DV>(do_h, v + (j * H + h) * nv, nv) - delta);
        axpy<T, DK>(dq_h, ds * scale, k_j, nk);
      }
    }
  }
}

// dK, dV (and the bias gradient) for one key bin and head, visiting the key's reverse neighbourhood:
// every query whose disc contains the key's pixel. Queries are indexed by centre pixel in CSR form
// (q_ptr over the key grid, q_idx the query ids in ascending order), so the sum runs in a fixed order
// without atomics. dbias_h (may be null) accumulates ds per relative offset for this head.
template <typename T, int DK, int DV>
RANA_HD void backward_dkdv_head(const T* __restrict__ q, const T* __restrict__ k_jh, const T* __restrict__ v_jh,
                                const T* __restrict__ dout, const T* __restrict__ lse, const T* __restrict__ delta,
                                const int64_t* q_ptr, const int64_t* q_idx, const Grid& g, const DiscRows& rows,
                                const T* bias, int64_t ky, int64_t kx, int h, int H, int dk, int dv, T scale,
                                T* __restrict__ dk_jh, T* __restrict__ dv_jh, T* dbias_h) {
  const int nk = DK > 0 ? DK : dk, nv = DV > 0 ? DV : dv;
  const int side = 2 * rows.R + 1;
  for (int c = 0; c < nk; ++c) dk_jh[c] = T(0);
  for (int c = 0; c < nv; ++c) dv_jh[c] = T(0);
  for (int r = 0; r < rows.n; ++r) {
    // a query at (ky - dy, kx - dx) sees this key at offset (dy, dx)
    const int dy = rows.dy[r];
    const int64_t qy = ky - dy;
    if (qy < 0 || qy >= g.Hk) continue;
    for (int dx = rows.dx0[r]; dx <= rows.dx1[r]; ++dx) {
      const int64_t qx = kx - dx;
      if (qx < 0 || qx >= g.Wk) continue;
      const int64_t qp = qy * g.Wk + qx;
      const T b = bias_at(bias, h, rows.R, dy, dx);
      T dsum = T(0);
      for (int64_t t = q_ptr[qp]; t < q_ptr[qp + 1]; ++t) {
        const int64_t i = q_idx[t];
        const T l = lse[i * H + h];
        if (l == neg_inf<T>()) continue;
        const T* q_ih = q + (i * H + h) * nk;
        const T* do_ih = dout + (i * H + h) * nv;
        const T pr = std::exp(dot<T, DK>(q_ih, k_jh, nk) * scale + b - l);
        axpy<T, DV>(dv_jh, pr, do_ih, nv);
        const T ds = pr * (dot<T, DV>(do_ih, v_jh, nv) - delta[i * H + h]);
        axpy<T, DK>(dk_jh, ds * scale, q_ih, nk);
        dsum += ds;
      }
      if (dbias_h) dbias_h[(dy + rows.R) * side + (dx + rows.R)] += dsum;
    }
  }
}

}  // namespace rana
