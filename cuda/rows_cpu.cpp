// Fused per-bin layers for inference on the CPU (rows_cpu.h): LayerNorm, the small linear layers around each RaNA
// and the MLP of a RaNA block, done tile by tile (a few dozen bins) in one pass over the bins.
//
// Why: at 32 channels per bin these layers do little arithmetic per byte, so torch's one-op-per-pass execution (the
// LayerNorm, each Linear's bias copy and its GEMM, the ReLU, the residual add: a full pass over [N, C] or [N, 2C]
// each) ran at the machine's memory bandwidth and took most of the backbone's time. Tile by tile, a bin's channels
// stay in cache from the LayerNorm to the last add, and memory sees one read of the inputs and one write per output;
// the products run in a register-blocked micro-kernel (gemm_tile).
//
// Weights are passed transposed ([C_in, C_out], contiguous), so a weight row is a few vector loads shared by the
// tile's rows. Every row is computed by one thread in a fixed order: results do not depend on the number of threads.
// They differ from torch's (its GEMM's summation order, its LayerNorm's reductions) by rounding only.
#include "rows_cpu.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

namespace {

constexpr int kMaxWidth = 1024;  // widest row a kernel accepts (inputs, hidden layer, outputs)

// The float vector of the machine's register width (GCC splits wider ones badly) and the micro-kernel's shape: kRows
// rows x 2 vectors of outputs held in registers (AVX-512: 8 x 32 in 16 of 32 zmm; AVX2: 6 x 16 in 12 of 16 ymm, the
// classic shapes of a float GEMM kernel).
#if defined(__AVX512F__)
typedef float vfloat __attribute__((vector_size(64)));
constexpr int kRows = 8;
#else
typedef float vfloat __attribute__((vector_size(32)));
constexpr int kRows = 6;
#endif
constexpr int kLanes = int(sizeof(vfloat) / sizeof(float));
constexpr int64_t kTile = 8 * kRows;  // rows per task: their activations stay in L1/L2

void check_rows(const torch::Tensor& x, const char* what) {
  TORCH_CHECK(x.device().is_cpu() && x.scalar_type() == torch::kFloat, what, ": float32 CPU tensor expected");
  TORCH_CHECK(x.dim() == 2 && x.is_contiguous(), what, ": contiguous [N, C] expected");
  TORCH_CHECK(x.size(1) <= kMaxWidth, what, ": rows wider than ", kMaxWidth);
}

void check_weight(const torch::Tensor& wt, int64_t in, const char* what) {
  TORCH_CHECK(wt.device().is_cpu() && wt.scalar_type() == torch::kFloat && wt.dim() == 2 && wt.is_contiguous(),
              what, ": contiguous float32 [C_in, C_out] expected");
  TORCH_CHECK(wt.size(0) == in, what, ": ", wt.size(0), " input channels, expected ", in);
  TORCH_CHECK(wt.size(1) <= kMaxWidth, what, ": more than ", kMaxWidth, " outputs");
}

void check_vector(const torch::Tensor& v, int64_t n, const char* what) {
  TORCH_CHECK(v.device().is_cpu() && v.scalar_type() == torch::kFloat && v.dim() == 1 && v.is_contiguous() &&
                  v.size(0) == n,
              what, ": contiguous float32 [", n, "] expected");
}

// LayerNorm of one row (biased variance, as torch's), into out. The sums are SIMD reductions (partial sums per lane,
// then added): written as plain loops they were two chains of c dependent adds per row, which at 32 channels made
// the LayerNorm cost 40% of a 32 -> 96 projection.
inline void layer_norm_row(const float* x, int64_t c, const float* w, const float* b, double eps, float* out) {
  float mean = 0.f;
#pragma omp simd reduction(+ : mean)
  for (int64_t i = 0; i < c; ++i) mean += x[i];
  mean /= float(c);
  float var = 0.f;
#pragma omp simd reduction(+ : var)
  for (int64_t i = 0; i < c; ++i) {
    const float d = x[i] - mean;
    var += d * d;
  }
  var /= float(c);
  const float inv = 1.f / std::sqrt(var + float(eps));
#pragma omp simd
  for (int64_t i = 0; i < c; ++i) out[i] = (x[i] - mean) * inv * w[i] + b[i];
}

inline vfloat loadv(const float* p) {
  vfloat v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}

inline void storev(float* p, vfloat v) { std::memcpy(p, &v, sizeof(v)); }

// out[r, o] (+)= [bias[o]] + sum_i x[r, i] wt[i, o] for R rows (strides ldx, ldo), outputs o0..o0 + NV kLanes - 1:
// the R x NV accumulators stay in registers while the K inputs stream (one load of each weight row serves R rows).
template <int R, int NV>
inline void gemm_tile(const float* x, int64_t ldx, int64_t k, const float* wt, int64_t ldw, int64_t o0,
                      const float* bias, float* out, int64_t ldo, bool accumulate) {
  vfloat acc[R][NV];
  for (int r = 0; r < R; ++r)
    for (int v = 0; v < NV; ++v)
      acc[r][v] = accumulate ? loadv(out + r * ldo + o0 + kLanes * v) : bias ? loadv(bias + o0 + kLanes * v)
                                                                          : vfloat{};
  for (int64_t i = 0; i < k; ++i) {
    vfloat w[NV];
    for (int v = 0; v < NV; ++v) w[v] = loadv(wt + i * ldw + o0 + kLanes * v);
    for (int r = 0; r < R; ++r) {
      const float xi = x[r * ldx + i];
      for (int v = 0; v < NV; ++v) acc[r][v] += xi * w[v];
    }
  }
  for (int r = 0; r < R; ++r)
    for (int v = 0; v < NV; ++v) storev(out + r * ldo + o0 + kLanes * v, acc[r][v]);
}

// out[r, :n_out] (+)= [bias] + x[r, :] wt[:, :n_out] for `rows` rows (wt's rows ldw apart): kRows-row micro-kernels
// over chunks of two vectors of outputs, smaller tiles for the remainders, scalar code beyond the last whole vector.
inline void gemm_rows(const float* x, int64_t ldx, int64_t rows, int64_t k, const float* wt, int64_t ldw,
                      int64_t n_out, const float* bias, float* out, int64_t ldo, bool accumulate) {
  const int64_t vec_out = n_out / kLanes * kLanes;
  int64_t r = 0;
  for (; r + kRows <= rows; r += kRows) {
    int64_t o = 0;
    for (; o + 2 * kLanes <= vec_out; o += 2 * kLanes)
      gemm_tile<kRows, 2>(x + r * ldx, ldx, k, wt, ldw, o, bias, out + r * ldo, ldo, accumulate);
    for (; o < vec_out; o += kLanes)
      gemm_tile<kRows, 1>(x + r * ldx, ldx, k, wt, ldw, o, bias, out + r * ldo, ldo, accumulate);
  }
  for (; r < rows; ++r)
    for (int64_t o = 0; o < vec_out; o += kLanes)
      gemm_tile<1, 1>(x + r * ldx, ldx, k, wt, ldw, o, bias, out + r * ldo, ldo, accumulate);
  for (int64_t rr = 0; rr < rows; ++rr)  // outputs beyond the last whole vector
    for (int64_t o = vec_out; o < n_out; ++o) {
      float s = accumulate ? out[rr * ldo + o] : bias ? bias[o] : 0.f;
      for (int64_t i = 0; i < k; ++i) s += x[rr * ldx + i] * wt[i * ldw + o];
      out[rr * ldo + o] = s;
    }
}

int threads() { return at::get_num_threads(); }

// Runs body(first_row, rows) over tiles of kTile rows, spread over the threads.
template <typename F>
void over_tiles(int64_t n, F&& body) {
  const int64_t tiles = (n + kTile - 1) / kTile;
#pragma omp parallel for schedule(static) num_threads(threads())
  for (int64_t t = 0; t < tiles; ++t) body(t * kTile, std::min(kTile, n - t * kTile));
}

}  // namespace

std::vector<torch::Tensor> rows_ln_linear(torch::Tensor x, c10::optional<torch::Tensor> ln_w,
                                          c10::optional<torch::Tensor> ln_b, double eps, torch::Tensor wt,
                                          torch::Tensor bias, std::vector<int64_t> splits) {
  check_rows(x, "rows_ln_linear x");
  const int64_t n = x.size(0), c = x.size(1), o = wt.size(1);
  check_weight(wt, c, "rows_ln_linear weight");
  check_vector(bias, o, "rows_ln_linear bias");
  TORCH_CHECK(ln_w.has_value() == ln_b.has_value(), "rows_ln_linear: LayerNorm weight and bias go together");
  if (ln_w) {
    check_vector(*ln_w, c, "rows_ln_linear LayerNorm weight");
    check_vector(*ln_b, c, "rows_ln_linear LayerNorm bias");
  }
  int64_t total = 0;
  for (int64_t s : splits) {
    TORCH_CHECK(s > 0, "rows_ln_linear: empty split");
    total += s;
  }
  TORCH_CHECK(total == o, "rows_ln_linear: splits add up to ", total, ", not the ", o, " outputs");
  std::vector<torch::Tensor> outs;
  std::vector<float*> dst;
  for (int64_t s : splits) {
    outs.push_back(torch::empty({n, s}, x.options()));
    dst.push_back(outs.back().data_ptr<float>());
  }
  const float* xp = x.data_ptr<float>();
  const float* lw = ln_w ? ln_w->data_ptr<float>() : nullptr;
  const float* lb = ln_b ? ln_b->data_ptr<float>() : nullptr;
  const float* w = wt.data_ptr<float>();
  const float* b = bias.data_ptr<float>();
  over_tiles(n, [&](int64_t r0, int64_t rows) {
    std::vector<float> xn(lw ? kTile * c : 0);
    const float* in = xp + r0 * c;
    if (lw) {
      for (int64_t r = 0; r < rows; ++r) layer_norm_row(in + r * c, c, lw, lb, eps, xn.data() + r * c);
      in = xn.data();
    }
    int64_t at = 0;   // each split straight into its output: the weights' columns at .. at + s - 1
    for (size_t k = 0; k < splits.size(); ++k) {
      const int64_t s = splits[k];
      gemm_rows(in, c, rows, c, w + at, o, s, b + at, dst[k] + r0 * s, s, false);
      at += s;
    }
  });
  return outs;
}

torch::Tensor rows_linear_residual(torch::Tensor res, torch::Tensor y1, torch::Tensor wt1,
                                   c10::optional<torch::Tensor> y2, c10::optional<torch::Tensor> wt2,
                                   torch::Tensor bias) {
  check_rows(res, "rows_linear_residual residual");
  check_rows(y1, "rows_linear_residual input");
  const int64_t n = res.size(0), o = res.size(1), k1 = y1.size(1);
  TORCH_CHECK(y1.size(0) == n, "rows_linear_residual: ", y1.size(0), " input rows, ", n, " residual rows");
  check_weight(wt1, k1, "rows_linear_residual weight");
  TORCH_CHECK(wt1.size(1) == o, "rows_linear_residual: weight gives ", wt1.size(1), " outputs, not ", o);
  TORCH_CHECK(y2.has_value() == wt2.has_value(), "rows_linear_residual: second input and weight go together");
  int64_t k2 = 0;
  if (y2) {
    check_rows(*y2, "rows_linear_residual second input");
    k2 = y2->size(1);
    TORCH_CHECK(y2->size(0) == n, "rows_linear_residual: second input rows differ");
    check_weight(*wt2, k2, "rows_linear_residual second weight");
    TORCH_CHECK(wt2->size(1) == o, "rows_linear_residual: second weight's outputs differ");
  }
  check_vector(bias, o, "rows_linear_residual bias");
  auto out = torch::empty({n, o}, res.options());
  const float *rp = res.data_ptr<float>(), *a = y1.data_ptr<float>(), *w1 = wt1.data_ptr<float>();
  const float* a2 = y2 ? y2->data_ptr<float>() : nullptr;
  const float* w2 = wt2 ? wt2->data_ptr<float>() : nullptr;
  const float* b = bias.data_ptr<float>();
  float* op = out.data_ptr<float>();
  over_tiles(n, [&](int64_t r0, int64_t rows) {
    float* d = op + r0 * o;
    gemm_rows(a + r0 * k1, k1, rows, k1, w1, o, o, b, d, o, false);
    if (a2) gemm_rows(a2 + r0 * k2, k2, rows, k2, w2, o, o, nullptr, d, o, true);
    const float* rr = rp + r0 * o;
#pragma omp simd
    for (int64_t j = 0; j < rows * o; ++j) d[j] += rr[j];
  });
  return out;
}

torch::Tensor rows_mlp(torch::Tensor x, c10::optional<torch::Tensor> ln_w, c10::optional<torch::Tensor> ln_b,
                       double eps, torch::Tensor wt1, torch::Tensor b1, torch::Tensor wt2, torch::Tensor b2,
                       bool residual) {
  check_rows(x, "rows_mlp x");
  const int64_t n = x.size(0), c = x.size(1), hid = wt1.size(1), o = wt2.size(1);
  check_weight(wt1, c, "rows_mlp first weight");
  check_vector(b1, hid, "rows_mlp first bias");
  check_weight(wt2, hid, "rows_mlp second weight");
  check_vector(b2, o, "rows_mlp second bias");
  TORCH_CHECK(!residual || o == c, "rows_mlp: a residual needs as many outputs as inputs");
  TORCH_CHECK(ln_w.has_value() == ln_b.has_value(), "rows_mlp: LayerNorm weight and bias go together");
  if (ln_w) {
    check_vector(*ln_w, c, "rows_mlp LayerNorm weight");
    check_vector(*ln_b, c, "rows_mlp LayerNorm bias");
  }
  auto out = torch::empty({n, o}, x.options());
  const float* xp = x.data_ptr<float>();
  const float* lw = ln_w ? ln_w->data_ptr<float>() : nullptr;
  const float* lb = ln_b ? ln_b->data_ptr<float>() : nullptr;
  const float *w1 = wt1.data_ptr<float>(), *bb1 = b1.data_ptr<float>(), *w2 = wt2.data_ptr<float>(),
              *bb2 = b2.data_ptr<float>();
  float* op = out.data_ptr<float>();
  over_tiles(n, [&](int64_t r0, int64_t rows) {
    std::vector<float> xn(lw ? kTile * c : 0), h(kTile * hid);
    const float* rowp = xp + r0 * c;
    const float* in = rowp;
    if (lw) {
      for (int64_t r = 0; r < rows; ++r) layer_norm_row(rowp + r * c, c, lw, lb, eps, xn.data() + r * c);
      in = xn.data();
    }
    gemm_rows(in, c, rows, c, w1, hid, hid, bb1, h.data(), hid, false);
#pragma omp simd
    for (int64_t j = 0; j < rows * hid; ++j) h[j] = h[j] > 0.f ? h[j] : 0.f;
    float* d = op + r0 * o;
    gemm_rows(h.data(), hid, rows, hid, w2, o, o, bb2, d, o, false);
    if (residual) {
#pragma omp simd
      for (int64_t j = 0; j < rows * o; ++j) d[j] += rowp[j];
    }
  });
  return out;
}

torch::Tensor rows_wide_operand(torch::Tensor proj, int64_t heads, double scale, torch::Tensor terms,
                                double term_scale, int64_t wide) {
  check_rows(proj, "rows_wide_operand projection");
  check_rows(terms, "rows_wide_operand terms");
  const int64_t n = proj.size(0), dh = proj.size(1), e = terms.size(1);
  TORCH_CHECK(heads > 0 && dh % heads == 0, "rows_wide_operand: ", dh, " columns are not whole heads of ", heads);
  const int64_t d = dh / heads;
  TORCH_CHECK(terms.size(0) == n, "rows_wide_operand: ", terms.size(0), " term rows, ", n, " projection rows");
  TORCH_CHECK(d + e <= wide, "rows_wide_operand: ", d, " channels and ", e, " terms do not fit ", wide);
  auto out = torch::empty({n, wide, heads}, proj.options());
  const float *pp = proj.data_ptr<float>(), *tp = terms.data_ptr<float>();
  const float s = float(scale), ts = float(term_scale);   // as torch multiplies a float32 tensor by a scalar
  float* op = out.data_ptr<float>();
  const int64_t row = wide * heads;
  over_tiles(n, [&](int64_t r0, int64_t rows) {
    for (int64_t r = r0; r < r0 + rows; ++r) {
      float* o = op + r * row;
      const float* p = pp + r * dh;
#pragma omp simd
      for (int64_t j = 0; j < dh; ++j) o[j] = p[j] * s;
      for (int64_t c = 0; c < e; ++c) {
        const float t = tp[r * e + c] * ts;
        for (int64_t h = 0; h < heads; ++h) o[dh + c * heads + h] = t;
      }
      for (int64_t j = dh + e * heads; j < row; ++j) o[j] = 0.f;
    }
  });
  return out;
}

torch::Tensor rows_scale_mix(torch::Tensor feat, torch::Tensor wt, torch::Tensor bias,
                             std::vector<torch::Tensor> outs) {
  check_rows(feat, "rows_scale_mix features");
  const int64_t n = feat.size(0), c = feat.size(1), scales = wt.size(1);
  check_weight(wt, c, "rows_scale_mix weight");
  check_vector(bias, scales, "rows_scale_mix bias");
  TORCH_CHECK(scales >= 1 && int64_t(outs.size()) == scales, "rows_scale_mix: ", outs.size(), " results for ",
              scales, " scales");
  const int64_t v = outs[0].dim() == 2 ? outs[0].size(1) : -1;
  std::vector<const float*> src;
  for (auto& o : outs) {
    check_rows(o, "rows_scale_mix result");
    TORCH_CHECK(o.size(0) == n && o.size(1) == v, "rows_scale_mix: results of differing shapes");
    src.push_back(o.data_ptr<float>());
  }
  auto out = torch::empty({n, v}, feat.options());
  const float *fp = feat.data_ptr<float>(), *w = wt.data_ptr<float>(), *b = bias.data_ptr<float>();
  float* op = out.data_ptr<float>();
  over_tiles(n, [&](int64_t r0, int64_t rows) {
    std::vector<float> logit(kTile * scales);
    gemm_rows(fp + r0 * c, c, rows, c, w, scales, scales, b, logit.data(), scales, false);
    for (int64_t r = 0; r < rows; ++r) {
      float* l = logit.data() + r * scales;
      float m = l[0], sum = 0.f;
      for (int64_t s = 1; s < scales; ++s) m = std::max(m, l[s]);
      for (int64_t s = 0; s < scales; ++s) sum += (l[s] = std::exp(l[s] - m));
      for (int64_t s = 0; s < scales; ++s) l[s] /= sum;
      const int64_t at = (r0 + r) * v;
      float* d = op + at;
      const float w0 = l[0];
      const float* s0 = src[0] + at;
#pragma omp simd
      for (int64_t j = 0; j < v; ++j) d[j] = w0 * s0[j];
      for (int64_t s = 1; s < scales; ++s) {
        const float ws = l[s];
        const float* ss = src[s] + at;
#pragma omp simd
        for (int64_t j = 0; j < v; ++j) d[j] += ws * ss[j];
      }
    }
  });
  return out;
}

torch::Tensor rows_concat(std::vector<torch::Tensor> parts) {
  TORCH_CHECK(!parts.empty(), "rows_concat: no parts");
  const int64_t n = parts[0].size(0);
  std::vector<const float*> src;
  std::vector<int64_t> width;
  int64_t total = 0;
  for (auto& p : parts) {
    TORCH_CHECK(p.device().is_cpu() && p.scalar_type() == torch::kFloat && p.dim() == 2 && p.is_contiguous(),
                "rows_concat: contiguous float32 [N, C] CPU tensors expected");
    TORCH_CHECK(p.size(0) == n, "rows_concat: parts of ", p.size(0), " and ", n, " rows");
    src.push_back(p.data_ptr<float>());
    width.push_back(p.size(1));
    total += p.size(1);
  }
  auto out = torch::empty({n, total}, parts[0].options());
  float* op = out.data_ptr<float>();
  over_tiles(n, [&](int64_t r0, int64_t rows) {
    int64_t at = 0;
    for (size_t k = 0; k < src.size(); ++k) {
      const int64_t w = width[k];
      const float* s = src[k] + r0 * w;
      float* d = op + r0 * total + at;
      for (int64_t r = 0; r < rows; ++r)
        for (int64_t j = 0; j < w; ++j) d[r * total + j] = s[r * w + j];
      at += w;
    }
  });
  return out;
}

namespace {

// The (qi, kj) pair indices of rows_pair_features and rows_pair_sum: contiguous int64 CPU vectors of one length,
// which is returned (their ranges are each kernel's own check).
int64_t check_pairs(const torch::Tensor& qi, const torch::Tensor& kj, const char* what) {
  for (const auto* t : {&qi, &kj})
    TORCH_CHECK(t->device().is_cpu() && t->scalar_type() == torch::kLong && t->dim() == 1 && t->is_contiguous(),
                what, ": contiguous int64 pair indices expected");
  TORCH_CHECK(kj.size(0) == qi.size(0), what, ": ", qi.size(0), " and ", kj.size(0), " pair indices");
  return qi.size(0);
}

}  // namespace

torch::Tensor rows_pair_features(torch::Tensor a, torch::Tensor b, torch::Tensor qi, torch::Tensor kj) {
  check_rows(a, "rows_pair_features a");
  check_rows(b, "rows_pair_features b");
  const int64_t d = a.size(1), na = a.size(0), nb = b.size(0);
  TORCH_CHECK(b.size(1) == d, "rows_pair_features: rows of ", d, " and ", b.size(1), " columns");
  const int64_t n = check_pairs(qi, kj, "rows_pair_features");
  const int64_t* ip = qi.data_ptr<int64_t>();
  const int64_t* jp = kj.data_ptr<int64_t>();
  // indices checked before anything is read: a bad pair is an error, not a read out of bounds
  int64_t bad = 0;
#pragma omp parallel for reduction(+ : bad) num_threads(threads())
  for (int64_t p = 0; p < n; ++p) bad += (ip[p] < 0) | (ip[p] >= na) | (jp[p] < 0) | (jp[p] >= nb);
  TORCH_CHECK(bad == 0, "rows_pair_features: ", bad, " pair indices out of range");
  auto out = torch::empty({n, 2 * d}, a.options());
  const float* ap = a.data_ptr<float>();
  const float* bp = b.data_ptr<float>();
  float* op = out.data_ptr<float>();
  over_tiles(n, [&](int64_t p0, int64_t rows) {
    for (int64_t p = p0; p < p0 + rows; ++p) {
      const float* x = ap + ip[p] * d;
      const float* y = bp + jp[p] * d;
      float* o = op + p * 2 * d;
      for (int64_t j = 0; j < d; ++j) {
        o[j] = std::fabs(x[j] - y[j]);
        o[d + j] = x[j] * y[j];
      }
    }
  });
  return out;
}

torch::Tensor rows_pair_sum(torch::Tensor w, torch::Tensor v, torch::Tensor qi, torch::Tensor kj, int64_t queries) {
  check_rows(v, "rows_pair_sum values");
  const int64_t c = v.size(1), nk = v.size(0), n = check_pairs(qi, kj, "rows_pair_sum");
  TORCH_CHECK(w.device().is_cpu() && w.scalar_type() == torch::kFloat && w.dim() == 1 && w.is_contiguous() &&
                  w.size(0) == n,
              "rows_pair_sum: contiguous float32 weights, one per pair, expected");
  TORCH_CHECK(queries >= 0, "rows_pair_sum: a negative number of queries");
  const float* wp = w.data_ptr<float>();
  const float* vp = v.data_ptr<float>();
  const int64_t* ip = qi.data_ptr<int64_t>();
  const int64_t* jp = kj.data_ptr<int64_t>();
  int64_t bad = 0;
#pragma omp parallel for reduction(+ : bad) num_threads(threads())
  for (int64_t p = 0; p < n; ++p)
    bad += (ip[p] < 0) | (ip[p] >= queries) | (jp[p] < 0) | (jp[p] >= nk) | (p > 0 && ip[p] < ip[p - 1]);
  TORCH_CHECK(bad == 0, "rows_pair_sum: ", bad, " pair indices out of range or queries out of order");
  auto out = torch::zeros({queries, c}, v.options());
  float* op = out.data_ptr<float>();
  // each thread a run of queries: its pairs are one run too (qi ascending)
  over_tiles(queries, [&](int64_t q0, int64_t rows) {
    int64_t p = std::lower_bound(ip, ip + n, q0) - ip;
    const int64_t end = std::lower_bound(ip, ip + n, q0 + rows) - ip;
    for (; p < end; ++p) {
      const float* x = vp + jp[p] * c;
      float* o = op + ip[p] * c;
      for (int64_t j = 0; j < c; ++j) {
        // the product rounded on its own, as torch's w * v before its index_add: through a volatile, which the
        // compiler may not fuse with the addition into one multiply-add (GCC fuses across statements otherwise)
        volatile float t = wp[p] * x[j];
        o[j] = o[j] + t;
      }
    }
  });
  return out;
}
