// The uplink's backlog: a deque of samples with a sent/unsent cursor and the drop accounting.
#include "backlog.h"

#include <algorithm>

#include "idms/sim/check.h"

namespace idms::agent {

Backlog::Backlog(int64_t capacity) : capacity_(static_cast<size_t>(std::max<int64_t>(capacity, 1))) {}

void Backlog::Accept(const TickSample& s) {
  thread_.Check("Backlog::Accept");
  IDMS_CHECK(samples_.empty() || s.tick > samples_.back().tick);
  samples_.push_back(s);
  if (samples_.size() <= capacity_) return;
  // Full: the oldest goes. Unsent, the server never gets it; sent, it cannot be resent.
  if (cursor_ == 0) {
    ++dropped_;
    ++unreported_;
  } else {
    evicted_sent_end_ = samples_.front().tick + 1;
    --cursor_;
  }
  samples_.pop_front();
}

void Backlog::MarkSent(size_t n) {
  thread_.Check("Backlog::MarkSent");
  IDMS_CHECK(n <= num_unsent());
  for (size_t i = cursor_; i < cursor_ + n; ++i) {
    const uint64_t tick = samples_[i].tick;
    if (sent_ == 0 || tick > highest_sent_) {
      ++sent_;
      highest_sent_ = tick;
    } else {
      ++resent_;
    }
  }
  cursor_ += n;
}

uint64_t Backlog::ResumeAt(uint64_t next_tick) {
  thread_.Check("Backlog::ResumeAt");
  // Lost: [next_tick, first kept) among the sent-then-evicted ticks, not counted before. The
  // ticks evicted unsent lie above every sent-then-evicted one and were counted by Accept.
  uint64_t lost = 0;
  if (!samples_.empty() && next_tick < samples_.front().tick && evicted_sent_end_ > 0) {
    const uint64_t end = std::min(samples_.front().tick, evicted_sent_end_);
    const uint64_t begin = std::min(std::max(next_tick, counted_end_), end);
    lost = end - begin;
    counted_end_ = std::max(counted_end_, end);
  }
  dropped_ += lost;
  unreported_ += lost;
  // Resend from the first tick the server lacks.
  const auto it = std::lower_bound(samples_.begin(), samples_.end(), next_tick,
                                   [](const TickSample& s, uint64_t tick) { return s.tick < tick; });
  cursor_ = static_cast<size_t>(it - samples_.begin());
  return lost;
}

uint64_t Backlog::TakeUnreportedDrops() {
  thread_.Check("Backlog::TakeUnreportedDrops");
  const uint64_t n = unreported_;
  unreported_ = 0;
  return n;
}

}  // namespace idms::agent
