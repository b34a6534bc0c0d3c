#include "worker_pool.h"

#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace idms::internal {
namespace {

// Spins before a futex wait: about 20-50 us, longer than a small pass's substep, shorter than
// what a parked thread would steal from a busy neighbour.
constexpr int kSpins = 1 << 12;

inline void Pause() {
#if defined(__SSE2__)
  _mm_pause();
#endif
}

}  // namespace

WorkerPool::WorkerPool(int32_t size) {
  threads_.reserve(size > 1 ? size - 1 : 0);
  for (int32_t i = 1; i < size; ++i) threads_.emplace_back([this, i] { Work(i); });
}

WorkerPool::~WorkerPool() {
  quit_.store(true, std::memory_order_relaxed);
  generation_.fetch_add(1, std::memory_order_release);
  generation_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void WorkerPool::Run(Fn fn, void* context) {
  if (threads_.empty()) return fn(context, 0);
  fn_ = fn, context_ = context;
  pending_.store(static_cast<int32_t>(threads_.size()), std::memory_order_relaxed);
  generation_.fetch_add(1, std::memory_order_release);
  generation_.notify_all();
  fn(context, 0);
  for (int i = 0; i < kSpins; ++i) {
    if (pending_.load(std::memory_order_acquire) == 0) return;
    Pause();
  }
  for (int32_t left = pending_.load(std::memory_order_acquire); left != 0;
       left = pending_.load(std::memory_order_acquire)) {
    pending_.wait(left, std::memory_order_acquire);
  }
}

void WorkerPool::Work(int32_t member) {
  uint32_t seen = 0;
  for (;;) {
    uint32_t now = generation_.load(std::memory_order_acquire);
    for (int i = 0; i < kSpins && now == seen; ++i) Pause(), now = generation_.load(std::memory_order_acquire);
    while (now == seen)
      generation_.wait(seen, std::memory_order_acquire), now = generation_.load(std::memory_order_acquire);
    seen = now;
    if (quit_.load(std::memory_order_relaxed)) return;
    fn_(context_, member);
    if (pending_.fetch_sub(1, std::memory_order_acq_rel) == 1) pending_.notify_one();
  }
}

}  // namespace idms::internal
