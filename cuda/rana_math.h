// RaNA (ragged neighbourhood attention) maths shared by the CPU and CUDA kernels.
//
// Everything here is a plain inline function over raw pointers, marked RANA_HD so that it compiles as host
// code (the C++/OpenMP kernels in rana_cpu.cpp) and as device code (CUDA kernels). The CPU tests therefore
// exercise the exact per-query and per-key bodies a GPU kernel built on them runs.
//
// Layout (ranad's ragged convention): keys/values are bins of an Hk x Wk grid; bins of key pixel p are
// rows offsets[p]..offsets[p+1]. The neighbourhood of a query centred at (y, x) is every key bin of every
// pixel (y + dy, x + dx) with dy^2 + dx^2 <= r^2 (paper Eq. 2), stored as "disc rows" (dy, dx0..dx1): the
// bins of one row of pixels are ONE contiguous key range, so a row is processed as a block.
//
// Vectorisation: the kernels read keys (and, in the dK/dV pass, queries) TRANSPOSED in tiles of kTile
// entries, [N / kTile + 1][H][d][kTile]: a block's logits are then sum_c q[c] * Kt[c][kb..kb+n), a
// broadcast-FMA over consecutive keys with no horizontal reductions, and one head's tile is one 4 KB page
// (a plain [H][d][N] layout made every channel a separate page: 16+ TLB entries per block). Blocks never
// cross a tile and are rounded up to kLanes entries (the padding's results are masked; reads past a tile
// land in the next channel's row or the padding tile), so the compiler emits whole-vector loops.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

#if defined(__CUDACC__)
#define RANA_HD __host__ __device__ __forceinline__
#define RANA_SIMD
#else
#define RANA_HD inline __attribute__((always_inline))
#define RANA_PRAGMA(x) _Pragma(#x)
#define RANA_SIMD RANA_PRAGMA(omp simd)
#endif

namespace rana {

constexpr int kLanes = 16;     // blocks are padded to a multiple of this (one AVX-512 float vector)
constexpr int kTile = 64;      // entries per tile of the transposed operands

// Pointer to entry idx of head h in a tiled transposed operand [N / kTile + 1][H][d][kTile]; channel c of
// the following entries is at ptr + c * kTile.
template <typename T>
RANA_HD const T* tile_ptr(const T* base, int64_t idx, int h, int H, int d) {
  return base + ((idx / kTile) * H + h) * int64_t(d) * kTile + idx % kTile;
}

// entries of a block starting at idx (at most `left`), never crossing a tile boundary
RANA_HD int tile_block(int64_t idx, int64_t left) {
  const int64_t room = kTile - idx % kTile;
  return int(left < room ? left : room);
}

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

RANA_HD int round_up(int n) { return (n + kLanes - 1) / kLanes * kLanes; }

// exp for float, branch-free and vectorisable (Cephes-style range reduction + degree-6 polynomial,
// ~2 ulp); inputs below -87 give exactly 0 (so masked logits of -inf vanish). double uses std::exp.
RANA_HD float fast_exp(float x) {
  const float lo = -87.0f, hi = 88.0f;
  const bool under = x < lo;
  x = x < lo ? lo : (x > hi ? hi : x);
  const float n = std::floor(x * 1.44269504088896341f + 0.5f);
  float r = x - n * 0.693359375f;
  r = r + n * 2.12194440e-4f;
  float p = 1.9875691500e-4f;
  p = p * r + 1.3981999507e-3f;
  p = p * r + 8.3334519073e-3f;
  p = p * r + 4.1665795894e-2f;
  p = p * r + 1.6666665459e-1f;
  p = p * r + 5.0000001201e-1f;
  p = p * r * r + r + 1.0f;
  int32_t bits = (int32_t(n) + 127) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof(scale));
  return under ? 0.0f : p * scale;
}
RANA_HD double fast_exp(double x) { return std::exp(x); }

template <typename T>
RANA_HD T neg_inf() { return -INFINITY; }

// Clip one disc row, centred at (y, x), to the grid: false when outside; else the first and last pixel.
RANA_HD bool row_span(const Grid& g, const DiscRows& rows, int r, int64_t y, int64_t x, int64_t* p0, int64_t* p1) {
  const int64_t py = y + rows.dy[r];
  if (py < 0 || py >= g.Hk) return false;
  int64_t a = x + rows.dx0[r], b = x + rows.dx1[r];
  if (a < 0) a = 0;
  if (b > g.Wk - 1) b = g.Wk - 1;
  if (a > b) return false;
  *p0 = py * g.Wk + a;
  *p1 = py * g.Wk + b;
  return true;
}

template <typename T>
RANA_HD T bias_at(const T* bias, int h, int R, int dy, int dx) {
  const int side = 2 * R + 1;
  return bias ? bias[(h * side + (dy + R)) * side + (dx + R)] : T(0);
}

// s[j] = scale * sum_c a[c] * Bt[c * ld + j] for j < nr: one row of logits against transposed operands.
// Chunks of kLanes outputs are accumulated in a fixed-size local array (one vector register on the CPU).
template <typename T, int D>
RANA_HD void block_dot(const T* __restrict__ a, const T* __restrict__ Bt, int64_t ld, int d, T scale, int nr,
                       T* __restrict__ s) {
  const int nd = D > 0 ? D : d;
  for (int jb = 0; jb < nr; jb += kLanes) {
    T acc[kLanes];
    RANA_SIMD
    for (int u = 0; u < kLanes; ++u) acc[u] = T(0);
    for (int c = 0; c < nd; ++c) {
      const T ac = a[c];
      const T* __restrict__ b = Bt + c * ld + jb;
      RANA_SIMD
      for (int u = 0; u < kLanes; ++u) acc[u] += ac * b[u];
    }
    RANA_SIMD
    for (int u = 0; u < kLanes; ++u) s[jb + u] = acc[u] * scale;
  }
}

// max over s[0..n) (s padded to nr), -inf when n == 0
template <typename T>
RANA_HD T block_max(const T* __restrict__ s, int n, int nr) {
  T mx[kLanes];
  RANA_SIMD
  for (int u = 0; u < kLanes; ++u) mx[u] = neg_inf<T>();
  for (int jb = 0; jb < nr; jb += kLanes) {
    RANA_SIMD
    for (int u = 0; u < kLanes; ++u) {
      const T x = s[jb + u];  // padding holds finite values: load unconditionally, then mask
      mx[u] = (jb + u < n && x > mx[u]) ? x : mx[u];
    }
  }
  T m = mx[0];
  for (int u = 1; u < kLanes; ++u) m = mx[u] > m ? mx[u] : m;
  return m;
}

// s[j] = exp(s[j] - sub) for j < n, 0 for the padding; returns the sum.
template <typename T>
RANA_HD T block_exp(T* __restrict__ s, int n, int nr, T sub) {
  T sum[kLanes];
  RANA_SIMD
  for (int u = 0; u < kLanes; ++u) sum[u] = T(0);
  for (int jb = 0; jb < nr; jb += kLanes) {
    RANA_SIMD
    for (int u = 0; u < kLanes; ++u) {
      const T e = fast_exp(s[jb + u] - sub);
      const T p = jb + u < n ? e : T(0);
      s[jb + u] = p;
      sum[u] += p;
    }
  }
  T total = T(0);
  for (int u = 0; u < kLanes; ++u) total += sum[u];
  return total;
}

// acc[c] += sum_j w[j] * rows[j * stride + c]: weighted sum of n rows (values, keys or queries).
template <typename T, int D>
RANA_HD void block_weighted_rows(const T* __restrict__ w, int n, const T* __restrict__ rows, int64_t stride, int d,
                                 T* __restrict__ acc) {
  const int nd = D > 0 ? D : d;
  for (int j = 0; j < n; ++j) {
    const T wj = w[j];
    const T* __restrict__ r = rows + j * stride;
    RANA_SIMD
    for (int c = 0; c < nd; ++c) acc[c] += wj * r[c];
  }
}

// Online softmax (FlashAttention): fold one block of logits s[0..n) (padded to nr) with value rows into
// the running max m, sum l and accumulator acc[DV]. s is overwritten with the block's probabilities.
template <typename T, int DV>
RANA_HD void softmax_fold(T* __restrict__ s, int n, int nr, const T* __restrict__ v_rows, int64_t v_stride, int dv,
                          T* m, T* l, T* __restrict__ acc) {
  const T bm = block_max(s, n, nr);
  const T mb = bm > *m ? bm : *m;
  if (mb == neg_inf<T>()) return;
  const T corr = (*m == neg_inf<T>()) ? T(0) : fast_exp(*m - mb);
  const T sum = block_exp(s, n, nr, mb);
  const int nv = DV > 0 ? DV : dv;
  if (corr != T(1)) {
    RANA_SIMD
    for (int c = 0; c < nv; ++c) acc[c] *= corr;
  }
  block_weighted_rows<T, DV>(s, n, v_rows, v_stride, nv, acc);
  *l = *l * corr + sum;
  *m = mb;
}

// Adds each pixel's relative-position bias to its segment of a row block of logits.
// Keys of pixel p occupy s[offsets[p] - kb ...]; the block covers keys [kb, kb + n).
template <typename T>
RANA_HD void add_row_bias(T* s, const T* bias, int h, int R, int dy, int64_t p0, int64_t p1, int64_t first_dx,
                          const int64_t* offsets, int64_t kb, int n) {
  if (!bias) return;
  for (int64_t p = p0; p <= p1; ++p) {
    int64_t a = offsets[p] - kb, b = offsets[p + 1] - kb;
    if (b <= 0 || a >= n) continue;
    a = a < 0 ? 0 : a;
    b = b > n ? n : b;
    const T bv = bias_at(bias, h, R, dy, int(first_dx + (p - p0)));
    for (int64_t j = a; j < b; ++j) s[j] += bv;
  }
}

// ---- per query and head -----------------------------------------------------------------------------
// The kernels stream the disc's row blocks into one logit buffer (kBuffer entries) and run the softmax
// step once per full buffer rather than once per row, which keeps the fixed cost per block (reductions,
// rescaling) small against the work. Each block remembers where its entries sit in the buffer.
constexpr int kBuffer = 256;      // logits buffered per flush (plus kLanes of padding)
constexpr int kMaxSegments = 64;  // row blocks per flush

struct Segment {
  int64_t start;  // first key (or query) of the block
  int n;          // entries
  int off;        // position in the buffer
  int dy;         // disc row
  int64_t p0, p1; // first and last pixel of the row span
};

// Forward: out_h[DV] and the returned log-sum-exp (-inf and zeros when the disc holds no key bins).
// Kt: tiled transposed keys; v: values [Nk, H, dv]. s: scratch of kBuffer + kLanes entries,
// seg: scratch of kMaxSegments segments.
template <typename T, int DK, int DV>
RANA_HD T forward_query_head(const T* __restrict__ q_h, const T* __restrict__ Kt, const T* __restrict__ v, const Grid& g, const DiscRows& rows, const T* bias,
                             int64_t y, int64_t x, int h, int H, int dk, int dv, T scale, T* __restrict__ out_h,
                             T* __restrict__ s, Segment* seg) {
  const int nv = DV > 0 ? DV : dv;
  for (int c = 0; c < nv; ++c) out_h[c] = T(0);
  T m = neg_inf<T>(), l = T(0);
  int off = 0, ns = 0;
  auto flush = [&]() {
    if (off == 0) return;
    const int nr = round_up(off);
    const T bm = block_max(s, off, nr);
    const T mb = bm > m ? bm : m;
    const T corr = (m == neg_inf<T>()) ? T(0) : fast_exp(m - mb);
    const T sum = block_exp(s, off, nr, mb);
    if (corr != T(1)) {
      RANA_SIMD
      for (int c = 0; c < nv; ++c) out_h[c] *= corr;
    }
    for (int i = 0; i < ns; ++i)
      block_weighted_rows<T, DV>(s + seg[i].off, seg[i].n, v + (seg[i].start * H + h) * nv, int64_t(H) * nv, nv,
                                 out_h);
    l = l * corr + sum;
    m = mb;
    off = ns = 0;
  };
  for (int r = 0; r < rows.n; ++r) {
    int64_t p0, p1;
    if (!row_span(g, rows, r, y, x, &p0, &p1)) continue;
    const int dy = rows.dy[r];
    const int64_t first_dx = p0 - (y + dy) * g.Wk - x;
    for (int64_t kb = g.offsets[p0], ke = g.offsets[p1 + 1], n; kb < ke; kb += n) {
      n = tile_block(kb, ke - kb);
      if (off + round_up(n) > kBuffer || ns == kMaxSegments) flush();
      block_dot<T, DK>(q_h, tile_ptr(Kt, kb, h, H, dk), kTile, dk, scale, round_up(n), s + off);
      add_row_bias(s + off, bias, h, rows.R, dy, p0, p1, first_dx, g.offsets, kb, n);
      seg[ns++] = Segment{kb, int(n), off, dy, p0, p1};
      off += n;
    }
  }
  flush();
  if (m == neg_inf<T>()) return m;
  const T inv = T(1) / l;
  for (int c = 0; c < nv; ++c) out_h[c] *= inv;
  return m + std::log(l);
}

// dQ for one query and head (FlashAttention-2: p = exp(s - lse), ds = p (dO.v - delta), dq = scale ds k).
// Kt, Vt: tiled transposed keys and values; k: keys [Nk, H, dk]. s, t: scratch of kBuffer + kLanes.
template <typename T, int DK, int DV>
RANA_HD void backward_dq_head(const T* __restrict__ q_h, const T* __restrict__ Kt, const T* __restrict__ Vt,
                              const T* __restrict__ k, const T* __restrict__ do_h, T lse, T delta,
                              const Grid& g, const DiscRows& rows, const T* bias, int64_t y, int64_t x, int h, int H,
                              int dk, int dv, T scale, T* __restrict__ dq_h, T* __restrict__ s, T* __restrict__ t,
                              Segment* seg) {
  const int nk = DK > 0 ? DK : dk;
  for (int c = 0; c < nk; ++c) dq_h[c] = T(0);
  if (lse == neg_inf<T>()) return;
  int off = 0, ns = 0;
  auto flush = [&]() {
    if (off == 0) return;
    const int nr = round_up(off);
    for (int jb = 0; jb < nr; jb += kLanes) {
      RANA_SIMD
      for (int u = 0; u < kLanes; ++u) {
        const int j = jb + u;
        const T e = fast_exp(s[j] - lse) * (t[j] - delta) * scale;
        s[j] = j < off ? e : T(0);
      }
    }
    for (int i = 0; i < ns; ++i)
      block_weighted_rows<T, DK>(s + seg[i].off, seg[i].n, k + (seg[i].start * H + h) * nk, int64_t(H) * nk, nk,
                                 dq_h);
    off = ns = 0;
  };
  for (int r = 0; r < rows.n; ++r) {
    int64_t p0, p1;
    if (!row_span(g, rows, r, y, x, &p0, &p1)) continue;
    const int dy = rows.dy[r];
    const int64_t first_dx = p0 - (y + dy) * g.Wk - x;
    for (int64_t kb = g.offsets[p0], ke = g.offsets[p1 + 1], n; kb < ke; kb += n) {
      n = tile_block(kb, ke - kb);
      if (off + round_up(n) > kBuffer || ns == kMaxSegments) flush();
      block_dot<T, DK>(q_h, tile_ptr(Kt, kb, h, H, dk), kTile, dk, scale, round_up(n), s + off);
      add_row_bias(s + off, bias, h, rows.R, dy, p0, p1, first_dx, g.offsets, kb, n);
      block_dot<T, DV>(do_h, tile_ptr(Vt, kb, h, H, dv), kTile, dv, T(1), round_up(n), t + off);
      seg[ns++] = Segment{kb, int(n), off, dy, p0, p1};
      off += n;
    }
  }
  flush();
}

// dK, dV (and the bias gradient) for one key bin and head from its reverse neighbourhood: the queries whose
// disc contains the key's pixel. Queries are sorted by centre pixel (q_ptr: CSR over the grid), and their
// operands are given in that order: Qt/dOt tiled transposed, qs/dos natural [Nq, H, d], lse_h/delta_h
// [Nq + kLanes] (lse = +inf for queries with an empty disc, so their probabilities are 0). Sums run in a fixed
// order without atomics. dbias_h (may be null) accumulates ds per relative offset.
// s, t, L, D: scratch of kBuffer + kLanes entries; seg: kMaxSegments.
template <typename T, int DK, int DV>
RANA_HD void backward_dkdv_head(const T* __restrict__ k_jh, const T* __restrict__ v_jh, const T* __restrict__ Qt,
                                const T* __restrict__ dOt, const T* __restrict__ qs,
                                const T* __restrict__ dos, const T* __restrict__ lse_h, const T* __restrict__ delta_h,
                                const int64_t* q_ptr, const Grid& g, const DiscRows& rows, const T* bias, int64_t ky,
                                int64_t kx, int h, int H, int dk, int dv, T scale, T* __restrict__ dk_jh,
                                T* __restrict__ dv_jh, T* dbias_h, T* __restrict__ s, T* __restrict__ t,
                                T* __restrict__ L, T* __restrict__ D, Segment* seg) {
  const int nk = DK > 0 ? DK : dk, nv = DV > 0 ? DV : dv;
  const int side = 2 * rows.R + 1;
  for (int c = 0; c < nk; ++c) dk_jh[c] = T(0);
  for (int c = 0; c < nv; ++c) dv_jh[c] = T(0);
  int off = 0, ns = 0;
  auto flush = [&]() {
    if (off == 0) return;
    const int nr = round_up(off);
    for (int jb = 0; jb < nr; jb += kLanes) {
      RANA_SIMD
      for (int u = 0; u < kLanes; ++u) {
        const int j = jb + u;
        const T e = fast_exp(s[j] - L[j]);
        const T p = j < off ? e : T(0);
        s[j] = p;                   // probabilities
        t[j] = p * (t[j] - D[j]);   // ds
      }
    }
    for (int i = 0; i < ns; ++i) {
      const Segment& sg = seg[i];
      block_weighted_rows<T, DV>(s + sg.off, sg.n, dos + (sg.start * H + h) * nv, int64_t(H) * nv, nv, dv_jh);
      if (dbias_h) {  // ds summed per query pixel of the row: each pixel is one relative offset
        const int64_t qy = ky - sg.dy;
        for (int64_t p = sg.p0; p <= sg.p1; ++p) {
          int64_t a = q_ptr[p] - sg.start, b = q_ptr[p + 1] - sg.start;
          if (b <= 0 || a >= sg.n) continue;
          a = a < 0 ? 0 : a;
          b = b > sg.n ? sg.n : b;
          T sum = T(0);
          for (int64_t j = a; j < b; ++j) sum += t[sg.off + j];
          const int dx = int(kx - (p - qy * g.Wk));
          dbias_h[(sg.dy + rows.R) * side + (dx + rows.R)] += sum;
        }
      }
    }
    for (int jb = 0; jb < nr; jb += kLanes) {
      RANA_SIMD
      for (int u = 0; u < kLanes; ++u) t[jb + u] *= scale;
    }
    for (int i = 0; i < ns; ++i)
      block_weighted_rows<T, DK>(t + seg[i].off, seg[i].n, qs + (seg[i].start * H + h) * nk, int64_t(H) * nk, nk,
                                 dk_jh);
    off = ns = 0;
  };
  for (int r = 0; r < rows.n; ++r) {
    // queries of the row at qy = ky - dy see this key at offset (dy, kx - qx): mirror the span
    const int dy = rows.dy[r];
    const int64_t qy = ky - dy;
    if (qy < 0 || qy >= g.Hk) continue;
    int64_t a = kx - rows.dx1[r], b = kx - rows.dx0[r];
    if (a < 0) a = 0;
    if (b > g.Wk - 1) b = g.Wk - 1;
    if (a > b) continue;
    const int64_t p0 = qy * g.Wk + a, p1 = qy * g.Wk + b;
    for (int64_t qb = q_ptr[p0], qe = q_ptr[p1 + 1], n; qb < qe; qb += n) {
      n = tile_block(qb, qe - qb);
      if (off + round_up(n) > kBuffer || ns == kMaxSegments) flush();
      const int nr = round_up(n);
      block_dot<T, DK>(k_jh, tile_ptr(Qt, qb, h, H, dk), kTile, dk, scale, nr, s + off);
      if (bias) {
        for (int64_t p = p0; p <= p1; ++p) {
          int64_t sa = q_ptr[p] - qb, sb = q_ptr[p + 1] - qb;
          if (sb <= 0 || sa >= n) continue;
          sa = sa < 0 ? 0 : sa;
          sb = sb > n ? n : sb;
          const T bv = bias_at(bias, h, rows.R, dy, int(kx - (p - qy * g.Wk)));
          for (int64_t j = sa; j < sb; ++j) s[off + j] += bv;
        }
      }
      block_dot<T, DV>(v_jh, tile_ptr(dOt, qb, h, H, dv), kTile, dv, T(1), nr, t + off);
      for (int j = 0; j < nr; ++j) {  // padded operands: lse +inf, delta 0 beyond the last query
        L[off + j] = lse_h[qb + j];
        D[off + j] = delta_h[qb + j];
      }
      seg[ns++] = Segment{qb, int(n), off, dy, p0, p1};
      off += n;
    }
  }
  flush();
}

}  // namespace rana
