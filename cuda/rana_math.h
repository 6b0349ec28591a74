// RaNA (ragged neighbourhood attention) maths shared by the CPU and CUDA kernels.
//
// Everything here is a plain inline function, marked RANA_HD so that it compiles as host code (the C++/OpenMP
// kernels in rana_cpu.cpp) and as device code (CUDA kernels). The CPU tests therefore exercise the exact
// per-query and per-key bodies a GPU kernel built on them runs.
//
// Layout (ranad's ragged convention): keys/values are bins of an Hk x Wk grid; bins of key pixel p are
// rows offsets[p]..offsets[p+1]. The neighbourhood of a query centred at (y, x) is every key bin of every
// pixel (y + dy, x + dx) with dy^2 + dx^2 <= r^2 (paper Eq. 2), stored as "disc rows" (dy, dx0..dx1).
//
// Lanes. The bodies work on a BLOCK of L entries (queries, or keys in the dK/dV pass) that lie on at most
// kMaxSpan + 1 consecutive pixels of one grid row, one entry per SIMD lane: V is a vector of L scalars (a GCC
// vector of the machine's register width on the CPU, see f32v; the scalar itself, L = 1, on the GPU where each thread is one lane). The
// block's operand rows sit in registers (q[c] for c < d is d vectors), every key of the union of the lanes'
// discs is visited once and serves all lanes with d broadcast-FMAs, and each lane masks the keys outside its
// own disc. The mask and the relative-position bias are one table lookup per (lane, key pixel): a table per
// head and disc row holds the bias inside the row's dx range and -inf outside it, so exp() sends masked
// logits to exactly 0. Lanes beyond the block's entries read a row of -inf.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <type_traits>

#if defined(__CUDACC__)
#define RANA_HD __host__ __device__ __forceinline__
#define RANA_UNROLL _Pragma("unroll")
#define RANA_NOINLINE
#define RANA_PREFETCH(p)
#else
// Rows the buffer step will read are requested while the buffer fills (they stay in L1 until then).
#define RANA_PREFETCH(p) __builtin_prefetch(p)
// The buffer steps are called out of line: inlined, their registers pushed the block's operand registers out of
// the hot loop that fills the buffer.
#define RANA_NOINLINE __attribute__((noinline))
#define RANA_HD inline __attribute__((always_inline))
#define RANA_UNROLL _Pragma("GCC unroll 64")
#if defined(__AVX512F__) || defined(__AVX2__)
#include <immintrin.h>
#endif
#endif

namespace rana {

constexpr int kMaxDim = 64;   // largest head dimension the kernels accept
constexpr int kScalarLaneDim = 16;  // the one head size compiled for one-lane blocks on the CPU (tests)
constexpr int kMaxSpan = 7;   // a block's entries lie on at most kMaxSpan + 1 consecutive pixels of a row

// ---- lane vectors ------------------------------------------------------------------------------------
#if !defined(__CUDACC__)
typedef float f32x16 __attribute__((vector_size(64)));
typedef float f32x8 __attribute__((vector_size(32)));
typedef double f64x8 __attribute__((vector_size(64)));
typedef double f64x4 __attribute__((vector_size(32)));
typedef int32_t i32x16 __attribute__((vector_size(64)));
typedef int32_t i32x8 __attribute__((vector_size(32)));
// The float lane vector of the CPU kernels: the machine's register width. 16 lanes (one zmm) with AVX-512, else 8
// (one ymm): GCC splits a 64-byte vector into pairs of 32-byte ones badly (lane shuffles through the stack for
// selects, conversions and gathers), which made the kernels 10x slower on an AVX2-only CPU.
#if defined(__AVX512F__)
typedef f32x16 f32v;
typedef f64x8 f64v;  // double: gradient checks only
#else
typedef f32x8 f32v;
typedef f64x4 f64v;
#endif
#endif

template <typename V>
struct Lanes {  // the scalar itself: one lane (GPU threads, and the tests of the L = 1 bodies on the CPU)
  using T = V;
  static constexpr int L = 1;
};
#if !defined(__CUDACC__)
template <>
struct Lanes<f32x16> {
  using T = float;
  static constexpr int L = 16;
};
template <>
struct Lanes<f32x8> {
  using T = float;
  static constexpr int L = 8;
};
template <>
struct Lanes<f64x8> {
  using T = double;
  static constexpr int L = 8;
};
template <>
struct Lanes<f64x4> {
  using T = double;
  static constexpr int L = 4;
};
#endif

// Lane i of v. (Subscripting a GCC vector does not take its address, so v can stay in a register.)
template <typename V>
RANA_HD typename Lanes<V>::T lane(const V& v, int i) {
  if constexpr (Lanes<V>::L == 1) {
    return v;
  } else {
    return v[i];
  }
}

// The vector of L scalars at p.
template <typename V>
RANA_HD V load_vector(const typename Lanes<V>::T* p) {
  if constexpr (Lanes<V>::L == 1) {
    return *p;
  } else {
    V v;
    std::memcpy(&v, p, sizeof(V));
    return v;
  }
}

template <typename V>
RANA_HD V splat(typename Lanes<V>::T x) {
  if constexpr (Lanes<V>::L == 1) {
    return x;
  } else {
    return V{} + x;
  }
}

template <typename V>
RANA_HD V vmax(V a, V b) {
  return a > b ? a : b;
}

// Logits are kept in base-2 units (q scaled by scale * log2(e), the bias table by log2(e)), so the softmax needs
// exp2, which has no range-reduction multiply and an exact reduction: n = round(x), f = x - n, 2^f by a degree-5
// polynomial on [-1/2, 1/2] (relative error 2.3e-7 in float), then scaled by 2^n. Inputs below -125 give exactly 0,
// so masked logits of -inf vanish (and no result is subnormal). double uses std::exp2 (gradient checks only).
constexpr double kLog2e = 1.4426950408889634074;
constexpr double kLn2 = 0.6931471805599453094;
#define RANA_EXP2_POLY(f)                                                                                      \
  ((((((1.3266970636323094e-3f) * (f) + 9.675459936261177e-3f) * (f) + 5.550742521882057e-2f) * (f) +         \
     2.4022121727466583e-1f) * (f) + 6.931469440460205e-1f) * (f) + 1.0000001192092896f)
RANA_HD float fast_exp2(float x) {
#if defined(__CUDA_ARCH__)
  return x < -125.0f ? 0.0f : exp2f(x);
#else
  const bool under = x < -125.0f;
  x = under ? -125.0f : x;
  const float n = std::floor(x + 0.5f), f = x - n;
  const float p = RANA_EXP2_POLY(f);
  int32_t bits = (int32_t(n) + 127) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof(scale));
  return under ? 0.0f : p * scale;
#endif
}
RANA_HD double fast_exp2(double x) { return std::exp2(x); }
#if !defined(__CUDACC__)
// The same steps on every lane of a float vector F (I: the int32 vector of as many lanes).
template <typename F, typename I>
inline F fast_exp2_lanes(F x) {
  const I under = x < -125.0f;
  x = under ? splat<F>(-125.0f) : x;
  F n;  // round(x)
#if defined(__AVX2__) && !defined(__AVX512F__)
  if constexpr (sizeof(F) == 32) {  // one vroundps
    const __m256 r = _mm256_round_ps(reinterpret_cast<const __m256&>(x), _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
    n = reinterpret_cast<const F&>(r);
  } else
#endif
  {
    const F y = x + 0.5f;
    n = __builtin_convertvector(__builtin_convertvector(y, I), F);  // truncation, then floor
    n = n > y ? n - 1.0f : n;
  }
  const F f = x - n;
  const F p = RANA_EXP2_POLY(f);
  const I bits = (__builtin_convertvector(n, I) + 127) << 23;
  const F e = p * reinterpret_cast<const F&>(bits);
  return under ? splat<F>(0.0f) : e;
}
inline f32x16 fast_exp2(f32x16 x) {  // the same steps on 16 lanes
#if defined(__AVX512F__) && defined(__AVX512DQ__)
  // AVX-512: vreduceps gives f = x - round(x) in one instruction, vscalefps the 2^n. The mask zeroes inputs below
  // -125 (an underflowing vscalefps would cost a microcode assist per instruction).
  const __m512 xv = reinterpret_cast<const __m512&>(x);
  const __mmask16 keep = _mm512_cmp_ps_mask(xv, _mm512_set1_ps(-125.0f), _CMP_GE_OQ);
  const __m512 v = _mm512_max_ps(xv, _mm512_set1_ps(-125.0f));
  const __m512 f = _mm512_reduce_ps(v, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
  const __m512 n = _mm512_sub_ps(v, f);
  const f32x16 p = RANA_EXP2_POLY(reinterpret_cast<const f32x16&>(f));  // five FMAs
  const __m512 e = _mm512_maskz_scalef_ps(keep, reinterpret_cast<const __m512&>(p), n);
  return reinterpret_cast<const f32x16&>(e);
#else
  return fast_exp2_lanes<f32x16, i32x16>(x);
#endif
}
inline f32x8 fast_exp2(f32x8 x) { return fast_exp2_lanes<f32x8, i32x8>(x); }
template <typename V>  // double lanes (gradient checks only): std::exp2 per lane
inline std::enable_if_t<std::is_same_v<V, f64x8> || std::is_same_v<V, f64x4>, V> fast_exp2(V x) {
  for (int i = 0; i < Lanes<V>::L; ++i) x[i] = std::exp2(x[i]);
  return x;
}
#endif

// log2 of positive lanes (the forward's log-sum-exp, once per block). AVX-512: exponent and mantissa in [3/4, 3/2)
// by vgetexp/vgetmant, then log2(m) = 2/ln2 atanh(t), t = (m - 1)/(m + 1) in (-1/7, 1/5], to t^9 (truncation
// error below 6e-9). Other float vectors: the same from the bits (fast_log2_lanes; positive normal inputs, which
// the log-sum-exp's sums are: at least 1).
#define RANA_LOG2_ATANH(t, t2)                                                                                 \
  ((((float(2 * kLog2e / 9) * (t2) + float(2 * kLog2e / 7)) * (t2) + float(2 * kLog2e / 5)) * (t2) +           \
    float(2 * kLog2e / 3)) * (t2) + float(2 * kLog2e)) * (t)
#if !defined(__CUDACC__)
// The same steps on every lane of a float vector F (I: the int32 vector of as many lanes), from the bits: exponent
// k and mantissa m in [1, 2), halved (k + 1) where m >= 3/2. Replaced a libm log2f call per lane on AVX2 (3.7% of
// the forward's time at 1.5 bins per pixel, one thread).
template <typename F, typename I>
inline F fast_log2_lanes(F x) {
  const I bits = reinterpret_cast<const I&>(x);
  I k = (bits >> 23) - 127;
  const I mbits = (bits & 0x007fffff) | 0x3f800000;
  F m = reinterpret_cast<const F&>(mbits);
  const I big = m >= 1.5f;   // -1 (all bits) where true
  m = big ? m * 0.5f : m;
  k -= big;
  const F t = (m - 1.0f) / (m + 1.0f), t2 = t * t;
  return RANA_LOG2_ATANH(t, t2) + __builtin_convertvector(k, F);
}
#endif
template <typename V>
RANA_HD V fast_log2(V x) {
  if constexpr (Lanes<V>::L == 1) {
    return std::log2(x);
  } else {
#if defined(__AVX512F__) && !defined(__CUDACC__)
    if constexpr (Lanes<V>::L == 16 && sizeof(typename Lanes<V>::T) == 4) {
      const __m512 v = reinterpret_cast<const __m512&>(x), one = _mm512_set1_ps(1.0f);
      const __m512 m = _mm512_getmant_ps(v, _MM_MANT_NORM_p75_1p5, _MM_MANT_SIGN_zero);
      __m512 k = _mm512_getexp_ps(v);
      k = _mm512_mask_add_ps(k, _mm512_cmp_ps_mask(m, one, _CMP_LT_OQ), k, one);  // m = mantissa / 2
      const __m512 t = _mm512_div_ps(_mm512_sub_ps(m, one), _mm512_add_ps(m, one)), t2 = _mm512_mul_ps(t, t);
      __m512 p = _mm512_set1_ps(float(2 * kLog2e / 9));
      p = _mm512_fmadd_ps(p, t2, _mm512_set1_ps(float(2 * kLog2e / 7)));
      p = _mm512_fmadd_ps(p, t2, _mm512_set1_ps(float(2 * kLog2e / 5)));
      p = _mm512_fmadd_ps(p, t2, _mm512_set1_ps(float(2 * kLog2e / 3)));
      p = _mm512_fmadd_ps(p, t2, _mm512_set1_ps(float(2 * kLog2e)));
      const __m512 r = _mm512_fmadd_ps(p, t, k);
      return reinterpret_cast<const V&>(r);
    }
#endif
#if !defined(__CUDACC__)
    if constexpr (std::is_same_v<V, f32x8>) return fast_log2_lanes<f32x8, i32x8>(x);
#endif
    for (int i = 0; i < Lanes<V>::L; ++i) x[i] = std::log2(x[i]);
    return x;
  }
}

// Makes the compiler keep an array in memory (its address escapes) so that it does not hold it in registers
// through a loop that needs them for something else; the accumulators are loaded once per buffer step.
template <typename V>
RANA_HD void keep_in_memory(V* p) {
#if defined(__CUDACC__)
  (void)p;
#else
  asm volatile("" : : "r"(p) : "memory");
#endif
}

template <typename T>
RANA_HD T neg_inf() {
  return -INFINITY;
}

// ---- geometry ----------------------------------------------------------------------------------------
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

// Width of one table row (dx from -(R + kMaxSpan) to R + kMaxSpan) and the index of dx = 0 in it.
RANA_HD int table_width(int R) { return 2 * (R + kMaxSpan) + 1; }
RANA_HD int table_centre(int R) { return R + kMaxSpan; }

// The mask-and-bias table: [H][rows.n][tw] then one row of -inf (for lanes past a block's end).
// Entry (h, r, centre + dx) is bias[h, dy_r + R, dx + R] * log2(e) (or 0 without bias) for dx0_r <= dx <= dx1_r,
// else -inf: logits are in base-2 units (see fast_exp2).
template <typename T>
RANA_HD void fill_table(const DiscRows& rows, const T* bias, int H, T* tab) {
  const int tw = table_width(rows.R), o = table_centre(rows.R), side = 2 * rows.R + 1;
  for (int h = 0; h <= H; ++h)
    for (int r = 0; r < (h < H ? rows.n : 1); ++r)
      for (int m = 0; m < tw; ++m) {
        const int dx = m - o;
        T val = neg_inf<T>();
        if (h < H && dx >= rows.dx0[r] && dx <= rows.dx1[r])
          val = bias ? T(bias[(h * side + rows.dy[r] + rows.R) * side + dx + rows.R] * kLog2e) : T(0);
        tab[(int64_t(h) * rows.n + r) * tw + m] = val;
      }
}

// A block: up to Q entries (queries, or keys) of grid row y on pixels x0 .. x0 + span. A block runs HB heads at
// once: lane l holds entry l / HB and head h0 + l % HB, so Q = L / HB. With several heads per block the entries'
// discs differ less (fewer pixels per block), so fewer lanes are masked: 4 heads x 4 queries spread over ~1.3
// pixels against 16 queries over ~5.3 pixels at 3 bins per pixel, which visits 1.8x fewer keys per query.
template <int Q>
struct Block {
  int64_t y, x0;
  int span;
  int n;           // entries in use (the lanes of entries n..Q-1 are padding)
  int64_t id[Q];   // operand row of each entry
  int32_t rel[Q];  // pixel of each entry minus x0
};

// Per-lane table indices for a block: lane l reads tab[base[l] + (row_offset & used[l]) + x] where row_offset is
// r * tw for disc row r and x is the key pixel minus x0 (queries) or minus the query pixel (keys, sign -1:
// dx = rel - x); padding lanes read the -inf row.
template <int L>
struct LaneTable {
  int32_t base[L];
  int32_t used[L];      // -1 (all bits) for lanes in use, 0 for padding
  int32_t rel_term[L];  // R - sign * rel (dx + R = rel_term + x); far out of range for padding lanes
  int32_t hoff[L];      // 8 * (head - h0): the lane's slot in a permute table (see lane_bias)
  int32_t group;        // h0 / 4
};

template <int L, int HB>
RANA_HD LaneTable<L> lane_table(const Block<L / HB>& b, const DiscRows& rows, int H, int h0, int sign) {
  LaneTable<L> lt;
  const int tw = table_width(rows.R), o = table_centre(rows.R);
  for (int l = 0; l < L; ++l) {
    const int e = l / HB, h = h0 + l % HB;
    const bool used = e < b.n;
    lt.used[l] = used ? -1 : 0;
    lt.base[l] = used ? (h * rows.n) * tw + o - sign * b.rel[e] : int32_t(int64_t(H) * rows.n * tw + o);
    lt.rel_term[l] = used ? rows.R - sign * b.rel[e] : -(1 << 20);
    lt.hoff[l] = 8 * (l % HB);
  }
  lt.group = h0 / 4;
  return lt;
}

// Permute tables for blocks of 4 heads with R <= 3 (side <= 8): [H / 4][rows.n][32], entry 8 * hl + dx + R of
// (group g, row r) = bias[4 g + hl, dy_r + R, dx + R] * log2(e) (0 without bias or beyond the side). One vpermt2ps then gives
// a key pixel's bias for all 16 lanes, and two compares give its mask, instead of a 16-lane gather per pixel.
template <typename T>
RANA_HD void fill_permute_table(const DiscRows& rows, const T* bias, int H, T* ptab) {
  const int side = 2 * rows.R + 1;
  for (int g = 0; g < H / 4; ++g)
    for (int r = 0; r < rows.n; ++r)
      for (int e = 0; e < 32; ++e) {
        const int h = 4 * g + e / 8, m = e % 8;
        ptab[(g * rows.n + r) * 32 + e] =
            bias && m < side ? T(bias[(h * side + rows.dy[r] + rows.R) * side + m] * kLog2e) : T(0);
      }
}

// The table with 4 heads interleaved, for blocks of 4 heads on 8 lanes (2 entries): tab4[4 i + hh] = tab[i + hh n tw]
// (n tw: one head's part of tab), -inf past the heads. An entry's 4 lanes read tab at i, i + n tw, ... (lane_bias, i
// from its first lane), which here is one 128-bit load: two loads give a key pixel's bias for the block instead of
// an 8-lane gather (microcoded on AMD's Zen 3; an A/B there measured the backward 2% faster, the forward unchanged).
// tab4 has 4 (H n + 1) tw entries (those of heads not a multiple of 4 are never read).
template <typename T>
RANA_HD void fill_interleaved_table(const DiscRows& rows, const T* tab, int H, T* tab4) {
  const int64_t head = int64_t(rows.n) * table_width(rows.R), size = (H * int64_t(rows.n) + 1) * table_width(rows.R);
  for (int64_t i = 0; i < size; ++i)
    for (int hh = 0; hh < 4; ++hh) tab4[4 * i + hh] = i + hh * head < H * head ? tab[i + hh * head] : neg_inf<T>();
}

// The L lanes' table entries for disc row r (row_offset = r * tw) at x: the bias and mask of one key pixel.
template <typename V>
RANA_HD V lane_bias(const typename Lanes<V>::T* tab, const LaneTable<Lanes<V>::L>& lt, int32_t row_offset, int32_t x) {
  constexpr int L = Lanes<V>::L;
  if constexpr (L == 1) {
    return tab[lt.base[0] + (row_offset & lt.used[0]) + x];
  } else {
#if defined(__AVX512F__) && !defined(__CUDACC__)
    if constexpr (L == 16 && sizeof(typename Lanes<V>::T) == 4) {
      const __m512i idx = _mm512_add_epi32(
          _mm512_add_epi32(_mm512_loadu_si512(lt.base),
                           _mm512_and_si512(_mm512_set1_epi32(row_offset), _mm512_loadu_si512(lt.used))),
          _mm512_set1_epi32(x));
      const __m512 g = _mm512_i32gather_ps(idx, tab, 4);
      return reinterpret_cast<const V&>(g);
    }
#endif
#if defined(__AVX2__) && !defined(__CUDACC__)
    if constexpr (L == 8 && sizeof(typename Lanes<V>::T) == 4) {
      const __m256i idx = _mm256_add_epi32(
          _mm256_add_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(lt.base)),
                           _mm256_and_si256(_mm256_set1_epi32(row_offset),
                                            _mm256_loadu_si256(reinterpret_cast<const __m256i*>(lt.used)))),
          _mm256_set1_epi32(x));
      const __m256 g = _mm256_i32gather_ps(tab, idx, 4);
      return reinterpret_cast<const V&>(g);
    }
#endif
    typename Lanes<V>::T out[L];
    for (int i = 0; i < L; ++i) out[i] = tab[lt.base[i] + (row_offset & lt.used[i]) + x];
    return load_vector<V>(out);
  }
}

// Walks the non-empty key pixels in the union of the discs of a query block on grid row y, pixels x0..x0+span:
// each step gives disc row r, the key pixel minus x0 (x) and its keys first..last-1. An iterator rather than a
// visitor callback: a lambda capturing the block's registers by reference made the compiler keep them in memory.
// With sign = -1 and ptr = the queries' CSR it walks the mirror image for a key block: every non-empty query
// pixel whose disc holds one of the block's pixels (x is then the query pixel minus x0).
struct PixelWalk {
  const Grid& g;
  const DiscRows& rows;
  const int64_t* ptr;  // CSR of the entries walked (key offsets, or the sorted queries' q_ptr)
  int sign;            // +1: key pixels of query discs; -1: query pixels whose discs hold the keys
  int64_t y, x0;
  int span;
  int r = -1;
  int64_t row = 0, px = 0, px_end = -1;  // grid row start (py * Wk), next pixel, last pixel of disc row r

  RANA_HD bool next(int& r_out, int32_t& x, int64_t& first, int64_t& last) {
    while (true) {
      while (px > px_end) {
        if (++r >= rows.n) return false;
        const int64_t py = y + sign * rows.dy[r];
        if (py < 0 || py >= g.Hk) continue;
        const int64_t a = sign > 0 ? x0 + rows.dx0[r] : x0 - rows.dx1[r];
        const int64_t b = sign > 0 ? x0 + span + rows.dx1[r] : x0 + span - rows.dx0[r];
        px = a < 0 ? 0 : a;
        px_end = b > g.Wk - 1 ? g.Wk - 1 : b;
        row = py * g.Wk;
      }
      const int64_t p = row + px;
      first = ptr[p];
      last = ptr[p + 1];
      x = int32_t(px - x0);
      ++px;
      if (first < last) {
        r_out = r;
        return true;
      }
    }
  }
};

// A walk recorded once per block (the CPU kernels replay it for every head rather than walk the grid again).
struct PixelRun {
  int32_t r, x;
  int64_t first, last;
};

// Most runs a walk of one block can produce: every disc row, its widest span of pixels.
RANA_HD int max_runs(const DiscRows& rows) { return rows.n * (2 * rows.R + 2 + kMaxSpan); }

// Records the walk's runs (the same runs, in the same order, as PixelWalk::next gives). Branch-free per pixel: each
// pixel's run is written and kept only when it is non-empty, as empty pixels come at random.
RANA_HD int record_runs(const PixelWalk& w, PixelRun* runs) {
  int n = 0;
  for (int r = 0; r < w.rows.n; ++r) {
    const int64_t py = w.y + w.sign * w.rows.dy[r];
    if (py < 0 || py >= w.g.Hk) continue;
    const int64_t a = w.sign > 0 ? w.x0 + w.rows.dx0[r] : w.x0 - w.rows.dx1[r];
    const int64_t b = w.sign > 0 ? w.x0 + w.span + w.rows.dx1[r] : w.x0 + w.span - w.rows.dx0[r];
    const int64_t px0 = a < 0 ? 0 : a, px1 = b > w.g.Wk - 1 ? w.g.Wk - 1 : b;
    const int64_t* row = w.ptr + py * w.g.Wk;
    int64_t first = px0 <= px1 ? row[px0] : 0;
    for (int64_t px = px0; px <= px1; ++px) {
      const int64_t last = row[px + 1];
      runs[n] = PixelRun{r, int32_t(px - w.x0), first, last};
      n += first < last;
      first = last;
    }
  }
  return n;
}

struct RunWalk {
  const PixelRun* runs;
  int n;
  int i = 0;

  RANA_HD bool next(int& r, int32_t& x, int64_t& first, int64_t& last) {
    if (i >= n) return false;
    const PixelRun& p = runs[i++];
    r = p.r;
    x = p.x;
    first = p.first;
    last = p.last;
    return true;
  }
};

// Everything the bodies share: geometry, table, sizes. H: heads of the operands (a multiple of the block's HB).
template <typename T>
struct Op {
  Grid g;
  DiscRows rows;
  const T* tab;  // fill_table
  int H, dk, dv;
  T scale;                  // the softmax scale, 1 / sqrt(d)
  const T* ptab = nullptr;  // fill_permute_table, for blocks of 4 heads (optional)
  const T* tab4 = nullptr;  // fill_interleaved_table, for blocks of 4 heads (optional)
  bool has_bias = false;
  // the factor applied to q (or k) for logits in base-2 units (see fast_exp2); gradients use scale itself
  RANA_HD T logit_scale() const { return T(scale * kLog2e); }
};

// A [N, H, d] operand read per entry (queries of a block, keys of a key block): element (n, h, c) at
// p[n * sN + h * sH + c * sC]. Natural layout: (H d, d, 1); channel-major ([N, d, H] storage): (d H, 1, H).
template <typename T>
struct Operand {
  const T* p;
  int64_t sN, sH, sC;
};

// An output in the same terms (gradients are written in their input's layout).
template <typename T>
struct Output {
  T* p;
  int64_t sN, sH, sC;
};

// The operands the bodies stream per key (kt, vt; qst, dost in the dK/dV pass) are stored head-grouped,
// [N, H / G, d, G]: element (n, h, c) at n d H + (h / G) d G + c G + h % G, so channel c of a block's HB heads is
// one chunk of consecutive scalars and the channels of a chunk lie G apart. G = 0 stands for channel-major
// [N, d, H] (G = H, known only at run time: the CUDA kernels). The CPU kernels use G = HB, a compile-time channel
// stride: with the run-time stride GCC kept the d channel offsets of a key on the stack and reloaded one per FMA.
template <int G>
struct Streamed {
  int H;
  RANA_HD int stride() const { return G ? G : H; }
  // the chunk of entry n, heads h0.., channel 0; d channels per head. With G > 0, h0 is a multiple of G (the
  // chunk starts a group)
  RANA_HD int64_t at(int64_t n, int d, int h0) const { return n * d * H + (G ? int64_t(h0) * d : h0); }
};

// The bias and mask of one key pixel for every lane: disc row r, x as for lane_bias. With a permute table (float,
// 16 lanes, AVX-512) a permute and two compares; with an interleaved table (float, 8 lanes of 4 heads) two loads;
// otherwise the gather of lane_bias.
template <typename V>
RANA_HD V key_pixel_bias(const Op<typename Lanes<V>::T>& op, const LaneTable<Lanes<V>::L>& lt, int r, int32_t x) {
#if defined(__AVX512F__) && !defined(__CUDACC__)
  if constexpr (Lanes<V>::L == 16 && sizeof(typename Lanes<V>::T) == 4) {
    if (op.ptab) {
      const __m512i t = _mm512_add_epi32(_mm512_loadu_si512(lt.rel_term), _mm512_set1_epi32(x));
      const __mmask16 ok = _mm512_cmpge_epi32_mask(t, _mm512_set1_epi32(op.rows.dx0[r] + op.rows.R)) &
                           _mm512_cmple_epi32_mask(t, _mm512_set1_epi32(op.rows.dx1[r] + op.rows.R));
      const __m512 ninf = _mm512_set1_ps(-INFINITY);
      __m512 v;
      if (op.has_bias) {
        const float* row = op.ptab + (lt.group * op.rows.n + r) * 32;
        const __m512i idx = _mm512_add_epi32(
            _mm512_loadu_si512(lt.hoff), _mm512_min_epi32(_mm512_max_epi32(t, _mm512_setzero_si512()),
                                                           _mm512_set1_epi32(7)));
        v = _mm512_mask_blend_ps(ok, ninf, _mm512_permutex2var_ps(_mm512_loadu_ps(row), idx, _mm512_loadu_ps(row + 16)));
      } else {
        v = _mm512_mask_blend_ps(ok, ninf, _mm512_setzero_ps());
      }
      return reinterpret_cast<const V&>(v);
    }
  }
#endif
#if defined(__AVX2__) && !defined(__AVX512F__) && !defined(__CUDACC__)
  if constexpr (Lanes<V>::L == 8 && sizeof(typename Lanes<V>::T) == 4) {
    if (op.tab4) {  // lanes 0-3: entry 0, lanes 4-7: entry 1 (blocks of 4 heads)
      const int32_t ro = r * table_width(op.rows.R);
      const float* a = op.tab4 + 4 * (lt.base[0] + (ro & lt.used[0]) + x);
      const float* b = op.tab4 + 4 * (lt.base[4] + (ro & lt.used[4]) + x);
      const __m256 v = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(a)), _mm_loadu_ps(b), 1);
      return reinterpret_cast<const V&>(v);
    }
  }
#endif
  return lane_bias<V>(op.tab, lt, r * table_width(op.rows.R), x);
}

// The HB scalars at p repeated over the L lanes (lane l gets p[l % HB]): one head-chunk of an operand stored
// [N, d, H], i.e. channel c of HB consecutive heads of one entry.
template <typename V, int HB>
RANA_HD V load_chunk(const typename Lanes<V>::T* p) {
  using T = typename Lanes<V>::T;
  constexpr int L = Lanes<V>::L;
  if constexpr (L == 1) {
    return *p;
  } else if constexpr (HB == 1) {
    return splat<V>(*p);
  } else {
#if defined(__AVX512F__) && !defined(__CUDACC__)
    if constexpr (L == 16 && HB == 4 && sizeof(T) == 4) {
      const __m512 c = _mm512_broadcast_f32x4(_mm_loadu_ps(p));
      return reinterpret_cast<const V&>(c);
    }
#endif
#if defined(__AVX512F__) && !defined(__CUDACC__)
    if constexpr (L == 16 && HB == 2 && sizeof(T) == 4) {  // the 2 floats as one double, broadcast
      double pair;
      std::memcpy(&pair, p, sizeof(pair));
      const __m512 c = _mm512_castpd_ps(_mm512_set1_pd(pair));
      return reinterpret_cast<const V&>(c);
    }
#endif
#if defined(__AVX2__) && !defined(__CUDACC__)
    if constexpr (L == 8 && HB == 2 && sizeof(T) == 4) {
      double pair;
      std::memcpy(&pair, p, sizeof(pair));
      const __m256 c = _mm256_castpd_ps(_mm256_set1_pd(pair));
      return reinterpret_cast<const V&>(c);
    }
    if constexpr (L == 8 && HB == 4 && sizeof(T) == 4) {  // one vbroadcastf128 from memory
      const __m256 c = _mm256_broadcast_ps(reinterpret_cast<const __m128*>(p));
      return reinterpret_cast<const V&>(c);
    }
#endif
    T tmp[L];
    for (int l = 0; l < L; ++l) tmp[l] = p[l % HB];
    return load_vector<V>(tmp);
  }
}

#if defined(__AVX512F__) && !defined(__CUDACC__)
// Four vectors of four 128-bit blocks, transposed as a 4 x 4 matrix of blocks: out[i] block j = in[j] block i.
inline void transpose_blocks4(const __m512* in, __m512* out) {
  const __m512 t0 = _mm512_shuffle_f32x4(in[0], in[1], 0x44), t1 = _mm512_shuffle_f32x4(in[0], in[1], 0xEE);
  const __m512 t2 = _mm512_shuffle_f32x4(in[2], in[3], 0x44), t3 = _mm512_shuffle_f32x4(in[2], in[3], 0xEE);
  out[0] = _mm512_shuffle_f32x4(t0, t2, 0x88);
  out[1] = _mm512_shuffle_f32x4(t0, t2, 0xDD);
  out[2] = _mm512_shuffle_f32x4(t1, t3, 0x88);
  out[3] = _mm512_shuffle_f32x4(t1, t3, 0xDD);
}
#endif

// Whether the dot products and weighted sums of a block run "by entry" (AVX-512, 16 lanes of 4 entries x 4 heads,
// rows head-grouped by 4, D a multiple of 4): a streamed row's channels 4g..4g+3 of the 4 heads are then one plain
// 16-float load, used by all 4 entries, instead of D broadcast-loads per row (see accumulate_rows_by_entry). The
// block's own operands (q in the forward, ...) are then held per entry: a[4 g + e] lane 4 cl + h = channel 4g + cl of
// entry e, head h (dot_operand_layout).
template <typename V, int HB, int D, int G>
RANA_HD constexpr bool by_entry() {
#if defined(__AVX512F__) && !defined(__CUDACC__)
  return Lanes<V>::L == 16 && sizeof(typename Lanes<V>::T) == 4 && HB == 4 && G == 4 && D % 4 == 0;
#else
  return false;
#endif
}

// Puts D lane vectors (lanes: entry, head) into the layout dot_rows reads (a no-op unless by_entry).
template <typename V, int HB, int D, int G>
RANA_HD void dot_operand_layout(V* a) {
#if defined(__AVX512F__) && !defined(__CUDACC__)
  if constexpr (by_entry<V, HB, D, G>()) {
    __m512* m = reinterpret_cast<__m512*>(a);
    RANA_UNROLL
    for (int g = 0; g < D / 4; ++g) {
      __m512 t[4];
      transpose_blocks4(m + 4 * g, t);
      RANA_UNROLL
      for (int e = 0; e < 4; ++e) m[4 * g + e] = t[e];
    }
  }
#else
  (void)a;
#endif
}

// sum_c a[c] * chunk(row + c * H) over D channels, in four independent FMA chains (channel c in chain c % 4): the
// logit of one key is a dependency chain of D / 4 FMAs plus two adds rather than D / 2 plus one, which the
// out-of-order core, holding only a few keys' worth of work, could not hide (the logit loops ran at the chains'
// latency). By entry (by_entry; a in dot_operand_layout): per entry a chain of D / 4 FMAs on plain loads of the row,
// then the four entries' (channel, head) partial sums transposed into (entry, head) lanes and added.
template <typename V, int HB, int D, int G>
RANA_HD V dot_rows(const V* a, const typename Lanes<V>::T* __restrict__ row, int H) {
#if defined(__AVX512F__) && !defined(__CUDACC__)
  if constexpr (by_entry<V, HB, D, G>()) {
    const __m512* m = reinterpret_cast<const __m512*>(a);
    __m512 p[4] = {_mm512_setzero_ps(), _mm512_setzero_ps(), _mm512_setzero_ps(), _mm512_setzero_ps()}, t[4];
    RANA_UNROLL
    for (int g = 0; g < D / 4; ++g) {
      const __m512 xv = _mm512_loadu_ps(row + 16 * g);
      RANA_UNROLL
      for (int e = 0; e < 4; ++e) p[e] = _mm512_fmadd_ps(m[4 * g + e], xv, p[e]);
    }
    transpose_blocks4(p, t);
    const __m512 r = _mm512_add_ps(_mm512_add_ps(t[0], t[1]), _mm512_add_ps(t[2], t[3]));
    return reinterpret_cast<const V&>(r);
  }
#endif
  V s[4] = {splat<V>(0), splat<V>(0), splat<V>(0), splat<V>(0)};
  RANA_UNROLL
  for (int c = 0; c < D; ++c) s[c % 4] += a[c] * load_chunk<V, HB>(row + c * H);
  return (s[0] + s[1]) + (s[2] + s[3]);
}

// acc[c] += w * chunk(row + c * H)
template <typename V, int HB, int D>
RANA_HD void axpy_rows(V* acc, V w, const typename Lanes<V>::T* __restrict__ row, int H) {
  RANA_UNROLL
  for (int c = 0; c < D; ++c) acc[c] += w * load_chunk<V, HB>(row + c * H);
}

#if defined(__AVX512F__) && !defined(__CUDACC__)
// accumulate_rows for 16 lanes of 4 entries x 4 heads over rows head-grouped by 4 (G = 4): a row's channels
// 4g..4g+3 of the 4 heads are one plain 16-float load, so each step multiplies that load by entry e's weights (its
// 128-bit block of w, repeated by one shuffle) into accumulators laid out (channel, head) per entry, and a key
// costs D / 4 loads, 4 shuffles and D FMAs instead of D broadcast-loads and D FMAs (the broadcasts made the
// accumulation ~a quarter of the forward). The accumulators are transposed into and out of that layout once per
// call (a 4 x 4 block transpose per 4 channels).
template <int D>
inline void accumulate_rows_by_entry(__m512* acc, const __m512* w, int nb, const float* __restrict__ x,
                                     const int64_t* idx, int64_t row_stride, int64_t head_offset) {
  __m512 r[D];  // r[4 g + e]: entry e, channels 4g.. (lane 4 cl + h: channel 4g + cl, head h)
  RANA_UNROLL
  for (int g = 0; g < D / 4; ++g) transpose_blocks4(acc + 4 * g, r + 4 * g);
  for (int i = 0; i < nb; ++i) {
    const float* row = x + idx[i] * row_stride + head_offset;
    const __m512 wi = w[i];
    const __m512 we[4] = {_mm512_shuffle_f32x4(wi, wi, 0x00), _mm512_shuffle_f32x4(wi, wi, 0x55),
                          _mm512_shuffle_f32x4(wi, wi, 0xAA), _mm512_shuffle_f32x4(wi, wi, 0xFF)};
    RANA_UNROLL
    for (int g = 0; g < D / 4; ++g) {
      const __m512 xv = _mm512_loadu_ps(row + 16 * g);
      RANA_UNROLL
      for (int e = 0; e < 4; ++e) r[4 * g + e] = _mm512_fmadd_ps(we[e], xv, r[4 * g + e]);
    }
  }
  RANA_UNROLL
  for (int g = 0; g < D / 4; ++g) transpose_blocks4(r + 4 * g, acc + 4 * g);
}
#endif

// acc[c] += w[i] * chunk(entry idx[i] of x, channel c) for i < nb, c < D: the weighted sum of nb streamed rows
// (heads h0.., layout st). acc lives in memory (keep_in_memory) and is held in registers through the loop. (In two
// passes of 8 channels, so that AVX2's 16 registers need not spill two of 16 accumulators, it measured no faster.)
template <typename V, int HB, int D, int G>
RANA_HD void accumulate_rows(V* acc, const V* w, int nb, const typename Lanes<V>::T* __restrict__ x,
                             const int64_t* idx, const Streamed<G>& st, int h0) {
#if defined(__AVX512F__) && !defined(__CUDACC__)
  if constexpr (by_entry<V, HB, D, G>()) {
    // st.at(n, D, h0) = n D H + h0 D for G > 0
    accumulate_rows_by_entry<D>(reinterpret_cast<__m512*>(acc), reinterpret_cast<const __m512*>(w), nb, x, idx,
                                int64_t(D) * st.H, int64_t(h0) * D);
    keep_in_memory(acc);
    return;
  }
#endif
  V r[D];
  RANA_UNROLL
  for (int c = 0; c < D; ++c) r[c] = acc[c];
  for (int i = 0; i < nb; ++i) axpy_rows<V, HB, D>(r, w[i], x + st.at(idx[i], D, h0), st.stride());
  RANA_UNROLL
  for (int c = 0; c < D; ++c) acc[c] = r[c];
  keep_in_memory(acc);
}

// Loads the block's rows of x (times mul) into D lane vectors (0 for padding lanes). Staged through a scalar
// array: writing single lanes of out[] would force the whole array into memory.
template <typename V, int HB, int D>
RANA_HD void load_lanes(const Operand<typename Lanes<V>::T>& x, const Block<Lanes<V>::L / HB>& b, int h0,
                        typename Lanes<V>::T mul, V* out) {
  using T = typename Lanes<V>::T;
  constexpr int L = Lanes<V>::L;
  T tmp[D * L];
  for (int l = 0; l < L; ++l) {
    const int e = l / HB;
    if (e < b.n) {
      const T* row = x.p + b.id[e] * x.sN + (h0 + l % HB) * x.sH;
      RANA_UNROLL
      for (int c = 0; c < D; ++c) tmp[c * L + l] = row[c * x.sC] * mul;
    } else {
      RANA_UNROLL
      for (int c = 0; c < D; ++c) tmp[c * L + l] = T(0);
    }
  }
  RANA_UNROLL
  for (int c = 0; c < D; ++c) out[c] = load_vector<V>(tmp + c * L);
}

// load_lanes, then dot_operand_layout. By entry, with a channel-major operand of exactly 4 heads (sH = 1, sC = 4: an
// entry's channel c of its 4 heads are 4 consecutive scalars), an entry's vectors are plain loads of its row rather
// than scalars staged through memory and transposed.
template <typename V, int HB, int D, int G>
RANA_HD void load_dot_operand(const Operand<typename Lanes<V>::T>& x, const Block<Lanes<V>::L / HB>& b, int h0,
                              typename Lanes<V>::T mul, V* out) {
#if defined(__AVX512F__) && !defined(__CUDACC__)
  if constexpr (by_entry<V, HB, D, G>()) {
    if (x.sH == 1 && x.sC == HB) {
      __m512* m = reinterpret_cast<__m512*>(out);
      const __m512 mv = _mm512_set1_ps(mul);
      for (int e = 0; e < 4; ++e) {
        const float* row = x.p + (e < b.n ? b.id[e] * x.sN + h0 : 0);
        RANA_UNROLL
        for (int g = 0; g < D / 4; ++g)
          m[4 * g + e] = e < b.n ? _mm512_mul_ps(_mm512_loadu_ps(row + 16 * g), mv) : _mm512_setzero_ps();
      }
      return;
    }
  }
#endif
#if defined(__AVX2__) && !defined(__AVX512F__) && !defined(__CUDACC__)
  // AVX2, blocks of 4 heads (2 entries): with the heads of a channel adjacent (sH = 1, a channel-major operand),
  // channel c of an entry's 4 heads is one 128-bit load, so a lane vector is two loads rather than 8 scalars staged
  // through memory (the staging was a fixed cost of every block, a third of the forward at 1 bin per pixel)
  if constexpr (Lanes<V>::L == 8 && HB == 4 && sizeof(typename Lanes<V>::T) == 4) {
    if (x.sH == 1) {
      const __m256 mv = _mm256_set1_ps(mul);
      const float* r0 = x.p + b.id[0] * x.sN + h0;
      const float* r1 = x.p + (b.n > 1 ? b.id[1] : b.id[0]) * x.sN + h0;
      const __m128 keep = b.n > 1 ? _mm_castsi128_ps(_mm_set1_epi32(-1)) : _mm_setzero_ps();
      RANA_UNROLL
      for (int c = 0; c < D; ++c) {
        const __m128 lo = _mm_loadu_ps(r0 + c * x.sC), hi = _mm_and_ps(_mm_loadu_ps(r1 + c * x.sC), keep);
        const __m256 v = _mm256_mul_ps(_mm256_insertf128_ps(_mm256_castps128_ps256(lo), hi, 1), mv);
        out[c] = reinterpret_cast<const V&>(v);
      }
      return;
    }
  }
#endif
  load_lanes<V, HB, D>(x, b, h0, mul, out);
  dot_operand_layout<V, HB, D, G>(out);
}

// Writes D lane vectors to the block's rows of x.
#if defined(__AVX2__) && !defined(__AVX512F__) && !defined(__CUDACC__)
// Eight vectors of 8 floats transposed: out[i] lane j = in[j] lane i.
inline void transpose8(const __m256* in, __m256* out) {
  __m256 t[8], u[8];
  for (int i = 0; i < 4; ++i) {
    t[2 * i] = _mm256_unpacklo_ps(in[2 * i], in[2 * i + 1]);
    t[2 * i + 1] = _mm256_unpackhi_ps(in[2 * i], in[2 * i + 1]);
  }
  for (int i = 0; i < 2; ++i) {
    u[4 * i] = _mm256_shuffle_ps(t[4 * i], t[4 * i + 2], _MM_SHUFFLE(1, 0, 1, 0));
    u[4 * i + 1] = _mm256_shuffle_ps(t[4 * i], t[4 * i + 2], _MM_SHUFFLE(3, 2, 3, 2));
    u[4 * i + 2] = _mm256_shuffle_ps(t[4 * i + 1], t[4 * i + 3], _MM_SHUFFLE(1, 0, 1, 0));
    u[4 * i + 3] = _mm256_shuffle_ps(t[4 * i + 1], t[4 * i + 3], _MM_SHUFFLE(3, 2, 3, 2));
  }
  for (int i = 0; i < 4; ++i) {
    out[i] = _mm256_permute2f128_ps(u[i], u[i + 4], 0x20);
    out[i + 4] = _mm256_permute2f128_ps(u[i], u[i + 4], 0x31);
  }
}
#endif

template <typename V, int HB, int D>
RANA_HD void store_lanes(const V* in, const Block<Lanes<V>::L / HB>& b, int h0,
                         const Output<typename Lanes<V>::T>& x) {
#if defined(__AVX2__) && !defined(__AVX512F__) && !defined(__CUDACC__)
  // AVX2, 8 float lanes, rows of contiguous channels (sC = 1) and D a multiple of 8: each 8 x 8 block of (channel,
  // lane) transposed in registers and stored as whole rows, instead of D scalar extractions and stores per lane
  if constexpr (Lanes<V>::L == 8 && sizeof(typename Lanes<V>::T) == 4 && D % 8 == 0) {
    if (x.sC == 1) {
      RANA_UNROLL
      for (int c0 = 0; c0 < D; c0 += 8) {
        __m256 rows[8];
        transpose8(reinterpret_cast<const __m256*>(in + c0), rows);
        for (int l = 0; l < b.n * HB; ++l)
          _mm256_storeu_ps(x.p + b.id[l / HB] * x.sN + (h0 + l % HB) * x.sH + c0, rows[l]);
      }
      return;
    }
  }
#endif
  for (int l = 0; l < b.n * HB; ++l) {
    typename Lanes<V>::T* row = x.p + b.id[l / HB] * x.sN + (h0 + l % HB) * x.sH;
    RANA_UNROLL
    for (int c = 0; c < D; ++c) row[c * x.sC] = lane(in[c], l);
  }
}

// Per-lane values of a per-(entry, head) array x [N, H] (pad for padding lanes).
template <typename V, int HB>
RANA_HD V load_lane_scalars(const typename Lanes<V>::T* x, const Block<Lanes<V>::L / HB>& b, int h0, int H,
                            typename Lanes<V>::T pad) {
  using T = typename Lanes<V>::T;
  constexpr int L = Lanes<V>::L;
  T tmp[L];
  for (int l = 0; l < L; ++l) tmp[l] = l / HB < b.n ? x[b.id[l / HB] * H + h0 + l % HB] : pad;
  return load_vector<V>(tmp);
}

// Streams the logits of a query block against every key of the walk into the buffer s (key indices in key),
// calling flush(nb) whenever the buffer is full and once at the end. The value rows a flush will read (vt, dv
// channels) are prefetched meanwhile. Shared by the forward and the dQ pass.
template <typename V, int HB, int DK, int NB, int G, typename W, typename F>
RANA_HD void stream_logits(const Op<typename Lanes<V>::T>& op, const LaneTable<Lanes<V>::L>& lt, W& walk, int h0,
                           const V* qr, const typename Lanes<V>::T* __restrict__ kt,
                           const typename Lanes<V>::T* __restrict__ vt, int dv, V* s, int64_t* key, F& flush) {
  const Streamed<G> st{op.H};
  int r;
  int32_t x;
  int64_t first, last;
  int nb = 0;
  while (walk.next(r, x, first, last)) {
    const V bv = key_pixel_bias<V>(op, lt, r, x);
    for (int64_t j = first; j < last; ++j) {
      if (nb == NB) {
        flush(nb);
        nb = 0;
      }
      RANA_PREFETCH(vt + st.at(j, dv, h0));
      s[nb] = dot_rows<V, HB, DK, G>(qr, kt + st.at(j, DK, h0), st.stride()) + bv;
      key[nb++] = j;
    }
  }
  flush(nb);
}

// ---- forward: one query block, heads h0 .. h0 + HB - 1 --------------------------------------------------
// Online softmax over the keys of the block's discs, buffered: logits of up to NB keys are kept, then one step
// per full buffer rescales and accumulates p * v. q [Nq, H, DK] (any Operand layout); kt and vt head-grouped
// (Streamed<G>: one load serves HB heads). Writes out [Nq, H, DV] and lse [Nq, H] (-inf and zeros for a query whose
// disc holds no key bins).
template <typename V, int HB, int DK, int DV, int NB, int G, typename W>
RANA_HD void forward_block(const Op<typename Lanes<V>::T>& op, const Block<Lanes<V>::L / HB>& b,
                           const LaneTable<Lanes<V>::L>& lt, W walk, int h0,
                           const Operand<typename Lanes<V>::T>& q, const typename Lanes<V>::T* __restrict__ kt,
                           const typename Lanes<V>::T* __restrict__ vt, typename Lanes<V>::T* out,
                           typename Lanes<V>::T* lse) {
  using T = typename Lanes<V>::T;
  const int H = op.H;
  const Streamed<G> st{H};
  V qr[DK], acc_mem[DV];
  load_dot_operand<V, HB, DK, G>(q, b, h0, op.logit_scale(), qr);
  RANA_UNROLL
  for (int c = 0; c < DV; ++c) acc_mem[c] = splat<V>(0);
  keep_in_memory(acc_mem);
  V m = splat<V>(neg_inf<T>()), l = splat<V>(0);
  V s[NB];
  int64_t key[NB];
  // nb (entries in the buffer) is passed by value: captured by reference it lived in memory, and the store and
  // reload on every key became the loop's critical path
  auto flush = [&](int nb) RANA_NOINLINE {
    V mx0 = splat<V>(neg_inf<T>()), mx1 = mx0, mx2 = mx0, mx3 = mx0;  // four chains
    int i = 0;
    for (; i + 4 <= nb; i += 4) {
      mx0 = vmax(mx0, s[i]);
      mx1 = vmax(mx1, s[i + 1]);
      mx2 = vmax(mx2, s[i + 2]);
      mx3 = vmax(mx3, s[i + 3]);
    }
    for (; i < nb; ++i) mx0 = vmax(mx0, s[i]);
    const V mx = vmax(vmax(mx0, mx1), vmax(mx2, mx3));
    const V mn = vmax(m, mx);
    const V base = mn == neg_inf<T>() ? splat<V>(0) : mn;  // lanes with nothing yet: exp(-inf - 0) = 0
    const V corr = fast_exp2(m - base);
    l *= corr;
    RANA_UNROLL
    for (int c = 0; c < DV; ++c) acc_mem[c] *= corr;
    // two loops: the exp chains are long, and a loop of only exps keeps many in flight
    V sum = splat<V>(0);
    for (int i = 0; i < nb; ++i) {
      s[i] = fast_exp2(s[i] - base);
      sum += s[i];
    }
    l += sum;
    accumulate_rows<V, HB, DV>(acc_mem, s, nb, vt, key, st, h0);
    m = mn;
  };
  stream_logits<V, HB, DK, NB, G>(op, lt, walk, h0, qr, kt, vt, DV, s, key, flush);
  const V empty = l == T(0) ? splat<V>(1) : splat<V>(0);
  const V inv = T(1) / (l + empty);
  RANA_UNROLL
  for (int c = 0; c < DV; ++c) acc_mem[c] *= inv;
  store_lanes<V, HB, DV>(acc_mem, b, h0, Output<T>{out, int64_t(H) * DV, DV, 1});
  const V lse_v = (m + fast_log2(l + empty)) * T(kLn2);  // natural units
  for (int i = 0; i < b.n * HB; ++i)
    lse[b.id[i / HB] * H + h0 + i % HB] = lane(l, i) == T(0) ? neg_inf<T>() : lane(lse_v, i);
}

// ---- backward, dQ: one query block, heads h0 .. h0 + HB - 1 ----------------------------------------------
// FlashAttention-2: p = exp(s - lse), ds = p (dO.v - delta), dq = scale sum ds k. lse must be +inf (not -inf)
// for queries with an empty disc, giving p = 0. q, dout [Nq, H, d] (Operands), lse, delta [Nq, H]; kt, vt as in the
// forward. Writes dq [Nq, H, DK].
template <typename V, int HB, int DK, int DV, int NB, int G, typename W>
RANA_HD void backward_dq_block(const Op<typename Lanes<V>::T>& op, const Block<Lanes<V>::L / HB>& b,
                               const LaneTable<Lanes<V>::L>& lt, W walk, int h0,
                               const Operand<typename Lanes<V>::T>& q, const Operand<typename Lanes<V>::T>& dout,
                               const typename Lanes<V>::T* lse,
                               const typename Lanes<V>::T* delta, const typename Lanes<V>::T* __restrict__ kt,
                               const typename Lanes<V>::T* __restrict__ vt, const Output<typename Lanes<V>::T>& dq) {
  using T = typename Lanes<V>::T;
  const int H = op.H;
  const Streamed<G> st{H};
  V qr[DK], acc_mem[DK];
  load_dot_operand<V, HB, DK, G>(q, b, h0, op.logit_scale(), qr);
  RANA_UNROLL
  for (int c = 0; c < DK; ++c) acc_mem[c] = splat<V>(0);
  keep_in_memory(acc_mem);
  const V L = load_lane_scalars<V, HB>(lse, b, h0, H, T(INFINITY)) * T(kLog2e);  // base-2 units
  const V D = load_lane_scalars<V, HB>(delta, b, h0, H, T(0));
  V s[NB];
  int64_t key[NB];
  auto flush = [&](int nb) RANA_NOINLINE {  // nb by value (see forward_block)
    {
      V dr[DV];
      load_dot_operand<V, HB, DV, G>(dout, b, h0, T(1), dr);
      for (int i = 0; i < nb; ++i) {
        const V dp = dot_rows<V, HB, DV, G>(dr, vt + st.at(key[i], DV, h0), st.stride());
        s[i] = fast_exp2(s[i] - L) * (dp - D);
      }
    }
    accumulate_rows<V, HB, DK>(acc_mem, s, nb, kt, key, st, h0);
  };
  stream_logits<V, HB, DK, NB, G>(op, lt, walk, h0, qr, kt, vt, DV, s, key, flush);
  RANA_UNROLL
  for (int c = 0; c < DK; ++c) acc_mem[c] *= op.scale;
  store_lanes<V, HB, DK>(acc_mem, b, h0, dq);
}

// ---- backward, dK and dV: one key block, heads h0 .. h0 + HB - 1 -----------------------------------------
// From the reverse neighbourhood: the queries whose disc holds a key of the block, sorted by centre pixel and
// given in that order: qst, dost head-grouped (Streamed<G>), lse_s, delta_s [Nq, H] (lse +inf for
// queries with an empty disc). k, v [Nk, H, d] (Operands). Sums run in a fixed order without atomics. dbias_lanes (may be
// null): per-lane accumulators [rows.n][tw][L], ds added at (r, centre + dx, lane); the caller sums them into
// the bias gradient of each lane's head.
template <typename V, int HB, int DK, int DV, int NB, int G, typename W>
RANA_HD void backward_dkdv_block(const Op<typename Lanes<V>::T>& op, const Block<Lanes<V>::L / HB>& b,
                                 const LaneTable<Lanes<V>::L>& lt, W walk, int h0,
                                 const typename Lanes<V>::T* __restrict__ qst,
                                 const typename Lanes<V>::T* __restrict__ dost, const typename Lanes<V>::T* lse_s,
                                 const typename Lanes<V>::T* delta_s, const Operand<typename Lanes<V>::T>& k,
                                 const Operand<typename Lanes<V>::T>& v, const Output<typename Lanes<V>::T>& dk,
                                 const Output<typename Lanes<V>::T>& dv,
                                 typename Lanes<V>::T* dbias_lanes) {
  using T = typename Lanes<V>::T;
  constexpr int L = Lanes<V>::L;
  const int H = op.H, tw = table_width(op.rows.R), o = table_centre(op.rows.R);
  const Streamed<G> st{H};
  V acc_k[DK], acc_v[DV];
  RANA_UNROLL
  for (int c = 0; c < DK; ++c) acc_k[c] = splat<V>(0);
  RANA_UNROLL
  for (int c = 0; c < DV; ++c) acc_v[c] = splat<V>(0);
  keep_in_memory(acc_k);
  keep_in_memory(acc_v);
  V s[NB], p[NB];
  int64_t qid[NB];
  int32_t tag[NB];  // r * tw + centre - x: where ds goes in the per-lane bias tables (plus the lane's rel)
  auto flush = [&](int nb) RANA_NOINLINE {  // nb by value (see forward_block)
    {
      V vr[DV];
      load_dot_operand<V, HB, DV, G>(v, b, h0, T(1), vr);
      for (int i = 0; i < nb; ++i) {
        const V dp = dot_rows<V, HB, DV, G>(vr, dost + st.at(qid[i], DV, h0), st.stride());
        const V pi = fast_exp2(s[i] - load_chunk<V, HB>(lse_s + qid[i] * H + h0) * T(kLog2e));
        p[i] = pi;
        s[i] = pi * (dp - load_chunk<V, HB>(delta_s + qid[i] * H + h0));
      }
    }
    accumulate_rows<V, HB, DV>(acc_v, p, nb, dost, qid, st, h0);
    accumulate_rows<V, HB, DK>(acc_k, s, nb, qst, qid, st, h0);
    if (dbias_lanes) {  // ds summed over the queries of one pixel, then added per lane at its own dx
      for (int i = 0; i < nb;) {
        V sum = s[i];
        int e = i + 1;
        for (; e < nb && tag[e] == tag[i]; ++e) sum += s[e];
        // lane-minor tables: an entry's HB lanes are HB consecutive floats, added from a copy of the vector (one
        // short vector add per entry on the CPU; lane by lane, each of the L lanes cost an extract)
        T sum_lanes[L];
        std::memcpy(sum_lanes, &sum, sizeof(V));
        for (int e = 0; e < b.n; ++e) {
          T* dst = dbias_lanes + int64_t(tag[i] + b.rel[e]) * L + e * HB;
          RANA_UNROLL
          for (int hh = 0; hh < HB; ++hh) dst[hh] += sum_lanes[e * HB + hh];
        }
        i = e;
      }
    }
  };
  int nb = 0;
  {
    V kr[DK];
    load_dot_operand<V, HB, DK, G>(k, b, h0, op.logit_scale(), kr);
    int r;
    int32_t x;
    int64_t first, last;
    while (walk.next(r, x, first, last)) {
      const V bv = key_pixel_bias<V>(op, lt, r, -x);
      for (int64_t i = first; i < last; ++i) {
        if (nb == NB) {
          flush(nb);
          nb = 0;
        }
        RANA_PREFETCH(dost + st.at(i, DV, h0));
        s[nb] = dot_rows<V, HB, DK, G>(kr, qst + st.at(i, DK, h0), st.stride()) + bv;
        qid[nb] = i;
        tag[nb++] = r * tw + o - x;
      }
    }
  }
  flush(nb);
  RANA_UNROLL
  for (int c = 0; c < DK; ++c) acc_k[c] *= op.scale;
  store_lanes<V, HB, DK>(acc_k, b, h0, dk);
  store_lanes<V, HB, DV>(acc_v, b, h0, dv);
}

// ---- compiled head sizes (host side: the drivers of the CPU and CUDA kernels) ----------------------------
// Calls f.template operator()<DK, DV>() for the head sizes the kernels are compiled for: float d in 8, 16, 32, 64
// (q, k) and 3, 8, 16, 32, 64 (v); double (gradient checks) 16, 64 and 3, 16, 64. The bindings pad other sizes
// with zero channels, which changes no logit and no output.
template <typename T, typename F>
void dispatch_head_dims(int dk, int dv, F&& f) {
  if constexpr (std::is_same_v<T, double>) {
    auto with_dv = [&]<int DK>() {
      switch (dv) {
        case 3: return f.template operator()<DK, 3>();
        case 16: return f.template operator()<DK, 16>();
        case 64: return f.template operator()<DK, 64>();
        default: throw std::invalid_argument("value head size not compiled");
      }
    };
    if (dk == 16) return with_dv.template operator()<16>();
    if (dk == 64) return with_dv.template operator()<64>();
    throw std::invalid_argument("key head size not compiled");
  } else {
    auto with_dv = [&]<int DK>() {
      switch (dv) {
        case 3: return f.template operator()<DK, 3>();
        case 8: return f.template operator()<DK, 8>();
        case 16: return f.template operator()<DK, 16>();
        case 32: return f.template operator()<DK, 32>();
        case 64: return f.template operator()<DK, 64>();
        default: throw std::invalid_argument("value head size not compiled");
      }
    };
    switch (dk) {
      case 8: return with_dv.template operator()<8>();
      case 16: return with_dv.template operator()<16>();
      case 32: return with_dv.template operator()<32>();
      case 64: return with_dv.template operator()<64>();
      default: throw std::invalid_argument("key head size not compiled");
    }
  }
}

}  // namespace rana
