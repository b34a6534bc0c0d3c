// Fork-join over a fixed set of threads, for the full-model pass's sections (full_step.cc).
// Nobody outside sim/src includes it.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

namespace idms::internal {

// size() - 1 threads started once and parked between runs; the caller is member 0. Run hands
// every member the same function and returns when all have returned: one release / acquire
// pair each way, so what a member wrote is visible to the caller after Run (and what the caller
// wrote before Run, to every member). A member that finds no work spins briefly (a substep of a
// 10^4-atom pass is tens of microseconds), then waits on a futex (std::atomic::wait). Run
// allocates nothing and takes no lock.
class WorkerPool {
 public:
  using Fn = void (*)(void* context, int32_t member);

  explicit WorkerPool(int32_t size);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int32_t size() const { return static_cast<int32_t>(threads_.size()) + 1; }
  // fn(context, i) for every member i in [0, size()), i = 0 on the calling thread.
  void Run(Fn fn, void* context);

 private:
  void Work(int32_t member);

  std::vector<std::thread> threads_;
  std::atomic<uint32_t> generation_{0};  // one more per Run; members wake on a change
  std::atomic<int32_t> pending_{0};      // members of this Run not yet done
  std::atomic<bool> quit_{false};
  Fn fn_ = nullptr;  // written before generation_ is released, read after it is acquired
  void* context_ = nullptr;
};

// Owns a WorkerPool, or none. Copies are empty: threads are not copied with a Workspace (the
// copy's first sectioned pass starts its own).
class WorkerPoolPtr {
 public:
  WorkerPoolPtr() = default;
  WorkerPoolPtr(const WorkerPoolPtr&) {}
  WorkerPoolPtr& operator=(const WorkerPoolPtr&) { return *this; }
  WorkerPoolPtr(WorkerPoolPtr&&) noexcept = default;
  WorkerPoolPtr& operator=(WorkerPoolPtr&&) noexcept = default;
  // The pool, started with `size` members if it has another size or none (allocates then).
  WorkerPool& Ensure(int32_t size) {
    if (p_ == nullptr || p_->size() != size) p_.reset(), p_ = std::make_unique<WorkerPool>(size);
    return *p_;
  }

 private:
  std::unique_ptr<WorkerPool> p_;
};

}  // namespace idms::internal
