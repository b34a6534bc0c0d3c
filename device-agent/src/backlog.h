// The uplink's bounded backlog of tick samples: each is kept after it is sent, so that a resumed
// session can resend from the server's next_tick, until the capacity pushes it out, oldest first.
// Pure (no I/O, no clock, no protobuf); I/O thread only (the first to call owns it: ThreadOwner).
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>

#include "idms/agent/loop.h"
#include "idms/agent/thread_owner.h"

namespace idms::agent {

class Backlog {
 public:
  // capacity: samples kept, sent or not (>= 1). Allocates as it fills (a deque's blocks).
  explicit Backlog(int64_t capacity);

  // Appends s; ticks strictly increase. Past the capacity the oldest sample goes: one never sent
  // is a drop (counted, and owed to the server in TakeUnreportedDrops); one sent can no longer
  // be resent (ResumeAt counts it if the server turns out not to have it).
  void Accept(const TickSample& s);

  // The unsent samples, oldest first: unsent(0) .. unsent(num_unsent() - 1).
  size_t num_unsent() const { return samples_.size() - cursor_; }
  const TickSample& unsent(size_t i) const { return samples_[cursor_ + i]; }
  // The first n unsent samples went out (n <= num_unsent()); counts which went for the first
  // time (num_sent) and which again after a resume (num_resent).
  void MarkSent(size_t n);

  // A resumed session whose server holds every tick before next_tick: the unsent samples start
  // again at the first one kept with tick >= next_tick. Ticks from next_tick on that were sent,
  // then pushed out, are lost: counted as drops (each once, however often the server asks for
  // them again) and returned.
  uint64_t ResumeAt(uint64_t next_tick);

  // Drops since the last call (what the server has not been told yet).
  uint64_t TakeUnreportedDrops();

  bool empty() const { return samples_.empty(); }
  size_t size() const { return samples_.size(); }
  uint64_t front_tick() const { return samples_.front().tick; }  // precondition: !empty()
  uint64_t num_dropped() const { return dropped_; }
  uint64_t num_sent() const { return sent_; }  // distinct ticks sent at least once
  uint64_t num_resent() const { return resent_; }

 private:
  std::deque<TickSample> samples_;  // sent ones first: [0, cursor_) sent, [cursor_, end) unsent
  size_t capacity_;
  size_t cursor_ = 0;
  uint64_t dropped_ = 0, unreported_ = 0, sent_ = 0, resent_ = 0;
  uint64_t highest_sent_ = 0;  // valid when sent_ > 0
  // Ticks below this that left the backlog after being sent; 0 = none.
  uint64_t evicted_sent_end_ = 0;
  // Ticks below this are accounted for: a loss there was counted already.
  uint64_t counted_end_ = 0;
  // Off the 1 kHz loop: a call from another thread aborts in every build, as IDMS_CHECK does.
  ThreadOwner thread_{"the uplink's backlog", ThreadOwner::OnViolation::kAbort};
};

}  // namespace idms::agent
