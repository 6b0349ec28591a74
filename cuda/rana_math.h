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
constexpr int kMaxDim = 64;    // largest head dimension the kernels accept (compile-time sizes are faster)
constexpr int kGroup = 4;      // queries (or keys) of one pixel processed together: they share a neighbourhood

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

// s[g * sld + j] = scale * sum_c a[g][c] * Bt[c * ld + j], j < nr, for the G rows a[0..G): one block of
// logits for G queries (or keys) against transposed operands. Each loaded vector of Bt serves all G rows,
// and the G accumulators are independent FMA chains. a is a local copy (see gather_rows): reading the rows
// through an array of pointers made the compiler reload the pointers in the inner loop.

// a[g][c] = src[g][c]: the G rows a group works on, copied next to each other.
template <typename T, int D, int G>
RANA_HD void gather_rows(const T* const* src, int d, T (*a)[D > 0 ? D : kMaxDim]) {
  const int nd = D > 0 ? D : d;
  for (int g = 0; g < G; ++g)
    for (int c = 0; c < nd; ++c) a[g][c] = src[g][c];
}

template <typename T, int D, int G>
RANA_HD void dot_group(const T (*__restrict__ a)[D > 0 ? D : kMaxDim], const T* __restrict__ Bt, int64_t ld, int d,
                       T scale, int nr, T* __restrict__ s, int sld) {
  const int nd = D > 0 ? D : d;
  for (int jb = 0; jb < nr; jb += kLanes) {
    T acc[G][kLanes];
    for (int g = 0; g < G; ++g) {
      RANA_SIMD
      for (int u = 0; u < kLanes; ++u) acc[g][u] = T(0);
    }
    for (int c = 0; c < nd; ++c) {
      const T* __restrict__ b = Bt + c * ld + jb;
      for (int g = 0; g < G; ++g) {
        const T ac = a[g][c];
        RANA_SIMD
        for (int u = 0; u < kLanes; ++u) acc[g][u] += ac * b[u];
      }
    }
    for (int g = 0; g < G; ++g) {
      RANA_SIMD
      for (int u = 0; u < kLanes; ++u) s[g * sld + jb + u] = acc[g][u] * scale;
    }
  }
}

// acc[g][c] += sum_j w[g * wld + j] * rows[j * stride + c] for the G rows of weights: each loaded row serves
// all G accumulators; small groups split the sum over P partial accumulators to keep FMA chains independent.
template <typename T, int D, int G>
RANA_HD void weighted_rows_group(const T* __restrict__ w, int wld, int n, const T* __restrict__ rows, int64_t stride,
                                 int d, T (*acc)[D > 0 ? D : kMaxDim]) {
  constexpr int DM = D > 0 ? D : kMaxDim;
  constexpr int P = G >= 3 ? 1 : (G == 2 ? 2 : 4);  // partial sums so that small groups have 4+ FMA chains
  const int nd = D > 0 ? D : d;
  T part[G][P][DM];
  for (int g = 0; g < G; ++g)
    for (int p = 0; p < P; ++p) {
      RANA_SIMD
      for (int c = 0; c < nd; ++c) part[g][p][c] = T(0);
    }
  int j = 0;
  for (; j + P <= n; j += P) {
    for (int p = 0; p < P; ++p) {
      const T* __restrict__ r = rows + (j + p) * stride;
      for (int g = 0; g < G; ++g) {
        const T wj = w[g * wld + j + p];
        RANA_SIMD
        for (int c = 0; c < nd; ++c) part[g][p][c] += wj * r[c];
      }
    }
  }
  for (; j < n; ++j) {
    const T* __restrict__ r = rows + j * stride;
    for (int g = 0; g < G; ++g) {
      const T wj = w[g * wld + j];
      RANA_SIMD
      for (int c = 0; c < nd; ++c) part[g][0][c] += wj * r[c];
    }
  }
  for (int g = 0; g < G; ++g)
    for (int p = 0; p < P; ++p) {
      RANA_SIMD
      for (int c = 0; c < nd; ++c) acc[g][c] += part[g][p][c];
    }
}

// max over s[0..n) (s padded to nr with finite values), -inf when n == 0
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

// Adds each pixel's relative-position bias to its entries of a block in G rows of logits (row stride sld).
// Entries of pixel p are ptr[p] - start .. ptr[p+1] - start (ptr: key offsets, or the query CSR); the block
// covers [start, start + n), n <= kTile; dx of pixel p is dx_first + sign * (p - p0). The bias is laid out
// once per block as a vector, then added to every row with whole-vector adds.
template <typename T, int G>
RANA_HD void add_block_bias(T* s, int sld, const T* bias, int h, int R, int dy, int64_t p0, int64_t p1,
                            int64_t dx_first, int sign, const int64_t* ptr, int64_t start, int n) {
  if (!bias) return;
  T bvec[kTile + kLanes];
  const int nr = round_up(n);
  for (int64_t p = p0; p <= p1; ++p) {
    int64_t a = ptr[p] - start, b = ptr[p + 1] - start;
    if (b <= 0 || a >= n) continue;
    a = a < 0 ? 0 : a;
    b = b > n ? n : b;
    const T bv = bias_at(bias, h, R, dy, int(dx_first + sign * (p - p0)));
    for (int64_t j = a; j < b; ++j) bvec[j] = bv;
  }
  for (int j = n; j < nr; ++j) bvec[j] = T(0);
  for (int g = 0; g < G; ++g) {
    RANA_SIMD
    for (int j = 0; j < nr; ++j) s[g * sld + j] += bvec[j];
  }
}

// ---- per group of queries (or keys) of one pixel, per head -----------------------------------------
// The kernels stream the disc's row blocks into one buffer of logits per group member (kBuffer entries) and
// run the softmax step once per full buffer rather than once per row, which keeps the fixed cost per block
// (reductions, rescaling) small against the work. Each block remembers where its entries sit in the buffer.
// A GPU kernel built on these runs them with G = 1 (one thread per query or key).
constexpr int kBuffer = 256;                // entries buffered per flush
constexpr int kStride = kBuffer + kLanes;   // row stride of the per-member buffers (room for padding)
constexpr int kMaxSegments = 64;            // row blocks per flush

struct Segment {
  int64_t start;  // first key (or query) of the block
  int n;          // entries
  int off;        // position in the buffer
  int dy;         // disc row
  int64_t p0, p1; // first and last pixel of the row span
};

// Calls visit(start, n, dy, p0, p1, dx_first) for every block of keys in the disc around (y, x): each disc
// row's contiguous key range [offsets[p0], offsets[p1 + 1]), cut at tile boundaries; dx_first is the dx of
// pixel p0 (dx grows with p).
template <typename F>
RANA_HD void for_each_key_block(const Grid& g, const DiscRows& rows, int64_t y, int64_t x, F&& visit) {
  for (int r = 0; r < rows.n; ++r) {
    int64_t p0, p1;
    if (!row_span(g, rows, r, y, x, &p0, &p1)) continue;
    const int dy = rows.dy[r];
    const int64_t dx_first = p0 - (y + dy) * g.Wk - x;
    for (int64_t kb = g.offsets[p0], ke = g.offsets[p1 + 1], n; kb < ke; kb += n) {
      n = tile_block(kb, ke - kb);
      visit(kb, int(n), dy, p0, p1, dx_first);
    }
  }
}

// The mirror image: calls visit(start, n, dy, p0, p1, dx_first) for every block of queries (sorted by centre
// pixel, CSR q_ptr) whose disc contains key pixel (ky, kx); a query at qx sees the key at dx = kx - qx, so
// dx_first is the dx of pixel p0 and dx falls as p grows.
template <typename F>
RANA_HD void for_each_query_block(const Grid& g, const DiscRows& rows, const int64_t* q_ptr, int64_t ky, int64_t kx,
                                  F&& visit) {
  for (int r = 0; r < rows.n; ++r) {
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
      visit(qb, int(n), dy, p0, p1, kx - a);
    }
  }
}

// Forward for G queries centred on pixel (y, x): out_g[g][DV] and lse_g[g] (-inf and zeros when the disc
// holds no key bins). Kt: tiled transposed keys; v: values [Nk, H, dv]. s: scratch [G][kStride],
// seg: scratch of kMaxSegments.
template <typename T, int DK, int DV, int G>
RANA_HD void forward_group_head(const T* const* q_g, const T* __restrict__ Kt, const T* __restrict__ v,
                                const Grid& g, const DiscRows& rows, const T* bias, int64_t y, int64_t x, int h,
                                int H, int dk, int dv, T scale, T* const* out_g, T* lse_g, T* __restrict__ s,
                                Segment* seg) {
  constexpr int DM = DV > 0 ? DV : kMaxDim;
  const int nv = DV > 0 ? DV : dv;
  T acc[G][DM];
  T m[G], l[G];
  for (int gi = 0; gi < G; ++gi) {
    m[gi] = neg_inf<T>();
    l[gi] = T(0);
    for (int c = 0; c < nv; ++c) acc[gi][c] = T(0);
  }
  T qa[G][DK > 0 ? DK : kMaxDim];
  gather_rows<T, DK, G>(q_g, dk, qa);
  int off = 0, ns = 0;
  auto flush = [&]() {
    if (off == 0) return;
    const int nr = round_up(off);
    for (int gi = 0; gi < G; ++gi) {
      T* sg = s + gi * kStride;
      const T bm = block_max(sg, off, nr);
      const T mb = bm > m[gi] ? bm : m[gi];
      const T corr = (m[gi] == neg_inf<T>()) ? T(0) : fast_exp(m[gi] - mb);
      const T sum = block_exp(sg, off, nr, mb);
      if (corr != T(1)) {
        RANA_SIMD
        for (int c = 0; c < nv; ++c) acc[gi][c] *= corr;
      }
      l[gi] = l[gi] * corr + sum;
      m[gi] = mb;
    }
    for (int i = 0; i < ns; ++i)
      weighted_rows_group<T, DV, G>(s + seg[i].off, kStride, seg[i].n, v + (seg[i].start * H + h) * nv,
                                    int64_t(H) * nv, nv, acc);
    off = ns = 0;
  };
  for_each_key_block(g, rows, y, x, [&](int64_t kb, int n, int dy, int64_t p0, int64_t p1, int64_t dx_first) {
    if (off + round_up(n) > kBuffer || ns == kMaxSegments) flush();
    dot_group<T, DK, G>(qa, tile_ptr(Kt, kb, h, H, dk), kTile, dk, scale, round_up(n), s + off, kStride);
    add_block_bias<T, G>(s + off, kStride, bias, h, rows.R, dy, p0, p1, dx_first, 1, g.offsets, kb, n);
    seg[ns++] = Segment{kb, n, off, dy, p0, p1};
    off += n;
  });
  flush();
  for (int gi = 0; gi < G; ++gi) {
    if (m[gi] == neg_inf<T>()) {
      for (int c = 0; c < nv; ++c) out_g[gi][c] = T(0);
      lse_g[gi] = m[gi];
      continue;
    }
    const T inv = T(1) / l[gi];
    for (int c = 0; c < nv; ++c) out_g[gi][c] = acc[gi][c] * inv;
    lse_g[gi] = m[gi] + std::log(l[gi]);
  }
}

// dQ for G queries centred on (y, x) (FlashAttention-2: p = exp(s - lse), ds = p (dO.v - delta),
// dq = scale sum ds k). lse_g must be +inf (not -inf) for queries with an empty disc, giving p = 0.
// Kt, Vt: tiled transposed keys and values; k: keys [Nk, H, dk]. s, t: scratch [G][kStride].
template <typename T, int DK, int DV, int G>
RANA_HD void backward_dq_group_head(const T* const* q_g, const T* const* do_g, const T* lse_g, const T* delta_g,
                                    const T* __restrict__ Kt, const T* __restrict__ Vt, const T* __restrict__ k,
                                    const Grid& g, const DiscRows& rows, const T* bias, int64_t y, int64_t x, int h,
                                    int H, int dk, int dv, T scale, T* const* dq_g, T* __restrict__ s,
                                    T* __restrict__ t, Segment* seg) {
  constexpr int DM = DK > 0 ? DK : kMaxDim;
  const int nk = DK > 0 ? DK : dk;
  T acc[G][DM];
  for (int gi = 0; gi < G; ++gi)
    for (int c = 0; c < nk; ++c) acc[gi][c] = T(0);
  T qa[G][DK > 0 ? DK : kMaxDim];
  T da[G][DV > 0 ? DV : kMaxDim];
  gather_rows<T, DK, G>(q_g, dk, qa);
  gather_rows<T, DV, G>(do_g, dv, da);
  int off = 0, ns = 0;
  auto flush = [&]() {
    if (off == 0) return;
    const int nr = round_up(off);
    for (int gi = 0; gi < G; ++gi) {
      T* __restrict__ sg = s + gi * kStride;
      const T* __restrict__ tg = t + gi * kStride;
      const T lse = lse_g[gi], delta = delta_g[gi];
      for (int jb = 0; jb < nr; jb += kLanes) {
        RANA_SIMD
        for (int u = 0; u < kLanes; ++u) {
          const int j = jb + u;
          const T e = fast_exp(sg[j] - lse) * (tg[j] - delta) * scale;
          sg[j] = j < off ? e : T(0);
        }
      }
    }
    for (int i = 0; i < ns; ++i)
      weighted_rows_group<T, DK, G>(s + seg[i].off, kStride, seg[i].n, k + (seg[i].start * H + h) * nk,
                                    int64_t(H) * nk, nk, acc);
    off = ns = 0;
  };
  for_each_key_block(g, rows, y, x, [&](int64_t kb, int n, int dy, int64_t p0, int64_t p1, int64_t dx_first) {
    if (off + round_up(n) > kBuffer || ns == kMaxSegments) flush();
    const int nr = round_up(n);
    dot_group<T, DK, G>(qa, tile_ptr(Kt, kb, h, H, dk), kTile, dk, scale, nr, s + off, kStride);
    add_block_bias<T, G>(s + off, kStride, bias, h, rows.R, dy, p0, p1, dx_first, 1, g.offsets, kb, n);
    dot_group<T, DV, G>(da, tile_ptr(Vt, kb, h, H, dv), kTile, dv, T(1), nr, t + off, kStride);
    seg[ns++] = Segment{kb, n, off, dy, p0, p1};
    off += n;
  });
  flush();
  for (int gi = 0; gi < G; ++gi)
    for (int c = 0; c < nk; ++c) dq_g[gi][c] = acc[gi][c];
}

// dK, dV (and the bias gradient) for G keys of the key pixel (ky, kx) from their reverse neighbourhood: the
// queries whose disc contains the pixel. Queries are sorted by centre pixel (q_ptr: CSR over the grid) and
// their operands given in that order: Qt/dOt tiled transposed, qs/dos natural [Nq, H, d], lse_h/delta_h
// [Nq + kLanes] (lse = +inf for queries with an empty disc and for the padding, so their probabilities are
// 0). Sums run in a fixed order without atomics. dbias_h (may be null) accumulates ds per relative offset.
// s, t: scratch [G][kStride]; L, D: scratch [kStride]; seg: kMaxSegments.
template <typename T, int DK, int DV, int G>
RANA_HD void backward_dkdv_group_head(const T* const* k_g, const T* const* v_g, const T* __restrict__ Qt,
                                      const T* __restrict__ dOt, const T* __restrict__ qs, const T* __restrict__ dos,
                                      const T* __restrict__ lse_h, const T* __restrict__ delta_h, const int64_t* q_ptr,
                                      const Grid& g, const DiscRows& rows, const T* bias, int64_t ky, int64_t kx,
                                      int h, int H, int dk, int dv, T scale, T* const* dk_g, T* const* dv_g,
                                      T* dbias_h, T* __restrict__ s, T* __restrict__ t, T* __restrict__ L,
                                      T* __restrict__ D, Segment* seg) {
  constexpr int DKM = DK > 0 ? DK : kMaxDim;
  constexpr int DVM = DV > 0 ? DV : kMaxDim;
  const int nk = DK > 0 ? DK : dk, nv = DV > 0 ? DV : dv;
  const int side = 2 * rows.R + 1;
  T acc_k[G][DKM], acc_v[G][DVM];
  for (int gi = 0; gi < G; ++gi) {
    for (int c = 0; c < nk; ++c) acc_k[gi][c] = T(0);
    for (int c = 0; c < nv; ++c) acc_v[gi][c] = T(0);
  }
  T ka[G][DKM], va[G][DVM];
  gather_rows<T, DK, G>(k_g, dk, ka);
  gather_rows<T, DV, G>(v_g, dv, va);
  int off = 0, ns = 0;
  auto flush = [&]() {
    if (off == 0) return;
    const int nr = round_up(off);
    for (int gi = 0; gi < G; ++gi) {
      T* __restrict__ sg = s + gi * kStride;
      T* __restrict__ tg = t + gi * kStride;
      for (int jb = 0; jb < nr; jb += kLanes) {
        RANA_SIMD
        for (int u = 0; u < kLanes; ++u) {
          const int j = jb + u;
          const T e = fast_exp(sg[j] - L[j]);
          const T p = j < off ? e : T(0);
          sg[j] = p;                   // probabilities
          tg[j] = p * (tg[j] - D[j]);  // ds
        }
      }
    }
    for (int i = 0; i < ns; ++i) {
      const Segment& sg = seg[i];
      weighted_rows_group<T, DV, G>(s + sg.off, kStride, sg.n, dos + (sg.start * H + h) * nv, int64_t(H) * nv, nv,
                                    acc_v);
      if (dbias_h) {  // ds summed over the group, then per query pixel of the row (one relative offset each)
        T tsum[kTile + kLanes];
        const int nr_seg = round_up(sg.n);
        RANA_SIMD
        for (int j = 0; j < nr_seg; ++j) tsum[j] = T(0);
        for (int gi = 0; gi < G; ++gi) {
          RANA_SIMD
          for (int j = 0; j < nr_seg; ++j) tsum[j] += t[gi * kStride + sg.off + j];
        }
        const int64_t qy = ky - sg.dy;
        for (int64_t p = sg.p0; p <= sg.p1; ++p) {
          int64_t a = q_ptr[p] - sg.start, b = q_ptr[p + 1] - sg.start;
          if (b <= 0 || a >= sg.n) continue;
          a = a < 0 ? 0 : a;
          b = b > sg.n ? sg.n : b;
          T sum = T(0);
          for (int64_t j = a; j < b; ++j) sum += tsum[j];
          const int dx = int(kx - (p - qy * g.Wk));
          dbias_h[(sg.dy + rows.R) * side + (dx + rows.R)] += sum;
        }
      }
    }
    for (int gi = 0; gi < G; ++gi)
      for (int jb = 0; jb < nr; jb += kLanes) {
        RANA_SIMD
        for (int u = 0; u < kLanes; ++u) t[gi * kStride + jb + u] *= scale;
      }
    for (int i = 0; i < ns; ++i)
      weighted_rows_group<T, DK, G>(t + seg[i].off, kStride, seg[i].n, qs + (seg[i].start * H + h) * nk,
                                    int64_t(H) * nk, nk, acc_k);
    off = ns = 0;
  };
  for_each_query_block(g, rows, q_ptr, ky, kx, [&](int64_t qb, int n, int dy, int64_t p0, int64_t p1,
                                                   int64_t dx_first) {
    if (off + round_up(n) > kBuffer || ns == kMaxSegments) flush();
    const int nr = round_up(n);
    dot_group<T, DK, G>(ka, tile_ptr(Qt, qb, h, H, dk), kTile, dk, scale, nr, s + off, kStride);
    add_block_bias<T, G>(s + off, kStride, bias, h, rows.R, dy, p0, p1, dx_first, -1, q_ptr, qb, n);
    dot_group<T, DV, G>(va, tile_ptr(dOt, qb, h, H, dv), kTile, dv, T(1), nr, t + off, kStride);
    for (int j = 0; j < nr; ++j) {  // padded operands: lse +inf, delta 0 beyond the last query
      L[off + j] = lse_h[qb + j];
      D[off + j] = delta_h[qb + j];
    }
    seg[ns++] = Segment{qb, n, off, dy, p0, p1};
    off += n;
  });
  flush();
  for (int gi = 0; gi < G; ++gi) {
    for (int c = 0; c < nk; ++c) dk_g[gi][c] = acc_k[gi][c];
    for (int c = 0; c < nv; ++c) dv_g[gi][c] = acc_v[gi][c];
  }
}

// Calls f.template operator()<G>() with G = n for 1 <= n <= kGroup (the size of a partial group).
template <typename F>
RANA_HD void with_group_size(int n, F&& f) {
  switch (n) {
    case 1: f.template operator()<1>(); break;
    case 2: f.template operator()<2>(); break;
    case 3: f.template operator()<3>(); break;
    default: f.template operator()<4>(); break;
  }
}

}  // namespace rana
