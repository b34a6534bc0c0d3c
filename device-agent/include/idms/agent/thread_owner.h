// Thread ownership, asserted (STYLE: "each object belongs to one thread; assert it"), as Drake's
// meshcat checks every call against the thread it was made on. Here the owner is the first thread
// that calls: the agent builds its objects on the main thread and hands each to the thread that
// runs it (the loop, the uplink's I/O thread).
#pragma once

#include <atomic>
#include <cstdint>
#include <thread>

namespace idms::agent {

class ThreadOwner {
 public:
  // What a call from another thread does. kAbort: names the object and the call on stderr and
  // aborts, as IDMS_CHECK does (it is a data race: a bug). kCount: counts it (violations()) and
  // lets the call run; for release builds, where the 1 kHz loop must not abort.
  enum class OnViolation : uint8_t { kAbort, kCount };
#ifdef NDEBUG
  static constexpr OnViolation kDefault = OnViolation::kCount;
#else
  static constexpr OnViolation kDefault = OnViolation::kAbort;
#endif

  // what: the object, for the message ("the loop's tick side"); a string literal.
  explicit ThreadOwner(const char* what, OnViolation on_violation = kDefault) : what_(what), on_(on_violation) {}
  ThreadOwner(const ThreadOwner&) = delete;
  ThreadOwner& operator=(const ThreadOwner&) = delete;

  // True on the owning thread; the first thread to call becomes the owner. Any thread; cheap
  // enough for every call of the 1 kHz loop: one pthread_self, one lock-free atomic load (a
  // compare-exchange the first time); no allocation, lock, system call or I/O unless violated.
  // call: what was called, for the message ("Loop::Tick"); a string literal.
  bool Check(const char* call) noexcept {
    const std::thread::id me = std::this_thread::get_id();
    std::thread::id owner = owner_.load(std::memory_order_acquire);
    if (owner == me) [[likely]] {
      return true;
    }
    if (owner == std::thread::id() && owner_.compare_exchange_strong(owner, me, std::memory_order_acq_rel)) {
      return true;
    }
    Violated(call);
    return false;
  }

  // The next thread to call becomes the owner: for an object handed on after its thread joined.
  void Release() noexcept { owner_.store(std::thread::id(), std::memory_order_release); }

  // Calls from a thread not the owner's so far (kCount; kAbort never returns from one).
  uint64_t violations() const noexcept { return violations_.load(std::memory_order_relaxed); }
  bool owned_by_this_thread() const noexcept {
    return owner_.load(std::memory_order_acquire) == std::this_thread::get_id();
  }

 private:
  void Violated(const char* call) noexcept;  // thread_owner.cc: counts, or says and aborts

  static_assert(std::atomic<std::thread::id>::is_always_lock_free, "the check must not lock");
  std::atomic<std::thread::id> owner_{};
  std::atomic<uint64_t> violations_{0};
  const char* what_;
  OnViolation on_;
};

}  // namespace idms::agent
