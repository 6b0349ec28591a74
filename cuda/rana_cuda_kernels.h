// Host entry points of the CUDA RaNA kernels (rana_cuda_kernels.cu). Torch-free and CUDA-header-free (the stream
// is passed as void*), so the torch binding (rana_cuda.cpp) compiles as plain C++ on any machine, and the
// kernels compile with nvcc alone: CI builds both without a GPU.
//
// Every pointer is a device pointer, including those inside rana::Op (offsets, disc rows, table).
#pragma once

#include <algorithm>
#include <cstdint>

#include "rana_math.h"

namespace rana_cuda {

constexpr int kThreads = 128;   // threads per block: one (entry, head) each
constexpr int kBuffer = 32;     // keys (or queries) buffered per softmax step (registers/local memory)
constexpr int kMaxRadius = 7;   // the bias gradient's per-thread table is sized for R <= 7
constexpr int kMaxTable = (2 * kMaxRadius + 1) * (2 * (kMaxRadius + rana::kMaxSpan) + 1);

// Forward: one thread per (query, head). q [Nq, H, dk] (Operand), kt [Nk, dk, H], vt [Nk, dv, H] (channel-major),
// qpix [Nq, 2]; writes out [Nq, H, dv], lse [Nq, H].
template <typename T>
void forward(const rana::Op<T>& op, const rana::Operand<T>& q, const T* kt, const T* vt, const int64_t* qpix,
             int64_t nq, T* out, T* lse, void* stream);

// dQ: one thread per (query, head); lse (+inf for empty discs), delta [Nq, H].
template <typename T>
void backward_dq(const rana::Op<T>& op, const rana::Operand<T>& q, const rana::Operand<T>& dout, const T* lse,
                 const T* delta, const T* kt, const T* vt, const int64_t* qpix, int64_t nq,
                 const rana::Output<T>& dq, void* stream);

// dK, dV: one thread per (key, head) over the reverse neighbourhood (queries sorted by pixel: q_ptr CSR, qst
// [Nq, dk, H], dost [Nq, dv, H], lse_s, delta_s [Nq, H]); kpix [Nk, 2]. With dbias (not null), the bias gradient
// [H, 2R+1, 2R+1] is summed without atomics: per-thread tables, a fixed-order tree per block into `partial`
// (workspace of partial_size(nk, H, R) elements), then a fixed-order sum over blocks. Deterministic.
template <typename T>
void backward_dkdv(const rana::Op<T>& op, const T* qst, const T* dost, const T* lse_s, const T* delta_s,
                   const rana::Operand<T>& k, const rana::Operand<T>& v, const int64_t* q_ptr, const int64_t* kpix,
                   int64_t nk, const rana::Output<T>& dk, const rana::Output<T>& dv, T* dbias, T* partial,
                   void* stream);

// dbias[h, e] = the sum over blocks of partial[h][block][e] (e < side2), blocks in order: the last step of the bias
// gradient of both kernel designs.
template <typename T>
void sum_bias_partials(const T* partial, int64_t blocks, int H, int side2, T* dbias, void* stream);

// ---- staged kernels (rana_cuda_staged.cu) --------------------------------------------------------------
// A block of kThreads / H neighbouring entries x H heads shares the rows it streams through shared memory (see the
// file's header). forward / backward_dq / backward_dkdv above use them when staged_options().enabled and they
// support the case (H <= kThreads, at least kStagedMinChunk rows fit in the shared memory), else the one-thread
// kernels. The options are a process-wide switch for benchmarks and tests (A/B in one process).
constexpr int kStagedMaxEntries = kThreads;  // entries per block (H = 1)
constexpr int kStagedMinChunk = 4;           // fewer rows per chunk than this: the one-thread kernels instead

struct StagedOptions {
  bool enabled = true;
  int max_chunk = 64;  // rows per shared-memory chunk: 16-128 measured on an H200, 64 fastest (bench/rana.py)
};
StagedOptions& staged_options();

bool staged_supported(int H);

template <typename T>
bool staged_forward(const rana::Op<T>& op, const rana::Operand<T>& q, const T* kt, const T* vt, const int64_t* qpix,
                    int64_t nq, T* out, T* lse, void* stream);

template <typename T>
bool staged_backward_dq(const rana::Op<T>& op, const rana::Operand<T>& q, const rana::Operand<T>& dout, const T* lse,
                        const T* delta, const T* kt, const T* vt, const int64_t* qpix, int64_t nq,
                        const rana::Output<T>& dq, void* stream);

template <typename T>
bool staged_backward_dkdv(const rana::Op<T>& op, const T* qst, const T* dost, const T* lse_s, const T* delta_s,
                          const rana::Operand<T>& k, const rana::Operand<T>& v, const int64_t* q_ptr,
                          const int64_t* kpix, int64_t nk, const rana::Output<T>& dk, const rana::Output<T>& dv,
                          T* dbias, T* partial, void* stream);

// Workspace of the bias gradient (elements): enough for either kernel, [H][blocks][side^2] partial sums.
inline int64_t partial_size(int64_t nk, int64_t H, int R) {
  const int64_t side = 2 * R + 1, per_block = H > 0 && H <= kThreads ? kThreads / H : 1;
  const int64_t blocks = std::max((nk + kThreads - 1) / kThreads, (nk + per_block - 1) / per_block);
  return H * blocks * side * side;
}

}  // namespace rana_cuda
