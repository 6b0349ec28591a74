// Large CPU buffers for the op's outputs and temporaries, kept for reuse when torch frees them.
//
// Why: glibc serves every allocation of 32 MB or more with a fresh mmap and unmaps it on free, so each call of
// the op paid the kernel for zero-filling its outputs page by page (a 512x512 forward: ~200 MB of output, about
// 8% of the call). A buffer returned here goes to a small idle list instead, and the next request of a similar
// size takes it with its pages already mapped. Every byte of a buffer handed out is written by the kernels (or by
// the copy that fills it) before it is read, so reuse needs no clearing. The [Nq, H] per-row buffers of the
// backward (~13 MB at 512x512) are served too: as fresh torch tensors each cost ~20 ms of page faults there.
//
// Bounded: idle buffers are kept up to RANAD_RANA_BUFFER_CACHE_MB (default 2048; 0 turns the cache off), oldest
// freed first beyond it, and a request only takes a buffer at most 1.25x its size.
#pragma once

#include <torch/extension.h>

#include <cstdlib>
#include <deque>
#include <mutex>
#include <utility>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace rana_cpu_buffers {

constexpr size_t kMinBytes = size_t(4) << 20;  // smaller ones come from glibc's heap and are reused there
constexpr size_t kAlign = size_t(2) << 20;      // huge-page aligned (transparent huge pages where allowed)

class Cache {
 public:
  static Cache& instance() {
    static Cache* c = new Cache();  // never destroyed: tensors may be freed during interpreter shutdown
    return *c;
  }

  // An uninitialised buffer of at least `bytes`; its capacity in `capacity`.
  void* take(size_t bytes, size_t& capacity) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      size_t best = idle_.size();
      for (size_t i = 0; i < idle_.size(); ++i) {
        const size_t c = idle_[i].second;
        if (c >= bytes && c <= bytes + bytes / 4 && (best == idle_.size() || c < idle_[best].second)) best = i;
      }
      if (best < idle_.size()) {
        void* p = idle_[best].first;
        capacity = idle_[best].second;
        idle_bytes_ -= capacity;
        idle_.erase(idle_.begin() + best);
        return p;
      }
    }
    capacity = (bytes + kAlign - 1) / kAlign * kAlign;
    void* p = std::aligned_alloc(kAlign, capacity);
    if (!p) throw std::bad_alloc();
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    madvise(p, capacity, MADV_HUGEPAGE);
#endif
    return p;
  }

  // Back to the idle list, dropping the oldest idle buffers beyond the limit.
  void give(void* p, size_t capacity) {
    std::deque<std::pair<void*, size_t>> drop;
    {
      std::lock_guard<std::mutex> lock(mu_);
      idle_.emplace_back(p, capacity);
      idle_bytes_ += capacity;
      while (idle_bytes_ > limit_ && !idle_.empty()) {
        drop.push_back(idle_.front());
        idle_bytes_ -= idle_.front().second;
        idle_.pop_front();
      }
    }
    for (auto& d : drop) std::free(d.first);
  }

  bool enabled() const { return limit_ > 0; }

 private:
  Cache() {
    const char* env = std::getenv("RANAD_RANA_BUFFER_CACHE_MB");
    limit_ = (env ? size_t(std::strtoull(env, nullptr, 10)) : size_t(2048)) << 20;
  }
  std::mutex mu_;
  std::deque<std::pair<void*, size_t>> idle_;
  size_t idle_bytes_ = 0, limit_ = 0;
};

// torch::empty(sizes, options) for CPU tensors, large ones from the cache.
inline torch::Tensor empty(at::IntArrayRef sizes, const torch::TensorOptions& options) {
  int64_t numel = 1;
  for (const int64_t s : sizes) numel *= s;
  const size_t bytes = size_t(numel) * c10::elementSize(c10::typeMetaToScalarType(options.dtype()));
  Cache& cache = Cache::instance();
  if (bytes < kMinBytes || !cache.enabled() || !options.device().is_cpu()) return torch::empty(sizes, options);
  size_t capacity = 0;
  void* p = cache.take(bytes, capacity);
  return torch::from_blob(p, sizes, [capacity](void* q) { Cache::instance().give(q, capacity); }, options);
}

}  // namespace rana_cpu_buffers
