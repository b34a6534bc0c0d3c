// The uplink's Backlog: samples kept after sending, the oldest evicted first, a never-sent
// eviction counted as a drop, resume at the server's next_tick, and each loss counted once.
#include "backlog.h"

#include <gtest/gtest.h>

#include <vector>

namespace idms::test {
namespace {

using agent::Backlog;
using agent::TickSample;

// Accepts ticks [begin, end).
void AcceptTicks(Backlog& backlog, uint64_t begin, uint64_t end) {
  for (uint64_t t = begin; t < end; ++t) {
    TickSample s;
    s.tick = t;
    backlog.Accept(s);
  }
}

std::vector<uint64_t> UnsentTicks(const Backlog& backlog) {
  std::vector<uint64_t> ticks;
  for (size_t i = 0; i < backlog.num_unsent(); ++i) ticks.push_back(backlog.unsent(i).tick);
  return ticks;
}

TEST(Backlog, KeepsSentSamplesAndSendsInOrder) {
  Backlog backlog(100);
  AcceptTicks(backlog, 0, 30);
  EXPECT_EQ(backlog.num_unsent(), 30u);
  backlog.MarkSent(20);
  EXPECT_EQ(backlog.num_unsent(), 10u);
  EXPECT_EQ(backlog.unsent(0).tick, 20u);
  EXPECT_EQ(backlog.size(), 30u) << "sent samples stay for a resume";
  EXPECT_EQ(backlog.num_sent(), 20u);
  EXPECT_EQ(backlog.num_dropped(), 0u);
}

TEST(Backlog, EvictsOldestAndCountsOnlyNeverSentAsDropped) {
  Backlog backlog(10);
  AcceptTicks(backlog, 0, 10);
  backlog.MarkSent(4);
  // Four sent samples make room first: no drop.
  AcceptTicks(backlog, 10, 14);
  EXPECT_EQ(backlog.size(), 10u);
  EXPECT_EQ(backlog.front_tick(), 4u);
  EXPECT_EQ(backlog.num_dropped(), 0u);
  // Then unsent ones go: drops, owed to the server once.
  AcceptTicks(backlog, 14, 17);
  EXPECT_EQ(backlog.front_tick(), 7u);
  EXPECT_EQ(backlog.num_dropped(), 3u);
  EXPECT_EQ(backlog.TakeUnreportedDrops(), 3u);
  EXPECT_EQ(backlog.TakeUnreportedDrops(), 0u);
  EXPECT_EQ(UnsentTicks(backlog), (std::vector<uint64_t>{7, 8, 9, 10, 11, 12, 13, 14, 15, 16}));
}

TEST(Backlog, ResumeResendsFromNextTickAndCountsResends) {
  Backlog backlog(100);
  AcceptTicks(backlog, 0, 50);
  backlog.MarkSent(50);
  // The server got ticks below 35; the rest were lost in flight.
  EXPECT_EQ(backlog.ResumeAt(35), 0u);
  EXPECT_EQ(backlog.num_unsent(), 15u);
  EXPECT_EQ(backlog.unsent(0).tick, 35u);
  backlog.MarkSent(15);
  EXPECT_EQ(backlog.num_sent(), 50u);
  EXPECT_EQ(backlog.num_resent(), 15u);
  // A server ahead of what is kept skips to the first tick it lacks.
  AcceptTicks(backlog, 50, 60);
  EXPECT_EQ(backlog.ResumeAt(55), 0u);
  EXPECT_EQ(backlog.unsent(0).tick, 55u);
}

TEST(Backlog, SentThenEvictedTicksTheServerLacksAreDroppedOnce) {
  Backlog backlog(10);
  AcceptTicks(backlog, 0, 10);
  backlog.MarkSent(10);
  AcceptTicks(backlog, 10, 16);  // ticks 0..5 pushed out after they were sent
  EXPECT_EQ(backlog.num_dropped(), 0u);
  // The server has ticks below 3 only: 3, 4, 5 are gone for good.
  EXPECT_EQ(backlog.ResumeAt(3), 3u);
  EXPECT_EQ(backlog.num_dropped(), 3u);
  EXPECT_EQ(backlog.TakeUnreportedDrops(), 3u);
  EXPECT_EQ(backlog.unsent(0).tick, 6u);
  // The connection fails again before anything arrives: the same loss is not counted twice.
  EXPECT_EQ(backlog.ResumeAt(3), 0u);
  EXPECT_EQ(backlog.num_dropped(), 3u);
}

TEST(Backlog, ResumeWithEverythingPushedOutCountsUnsentDropsOnce) {
  // A long outage: the backlog turns over completely while nothing is sent.
  Backlog backlog(5);
  AcceptTicks(backlog, 0, 5);
  backlog.MarkSent(2);  // 0, 1 sent; the server has only tick 0
  AcceptTicks(backlog, 5, 20);
  // 0, 1 left sent; 2..14 left unsent (13 drops); 15..19 kept.
  EXPECT_EQ(backlog.num_dropped(), 13u);
  EXPECT_EQ(backlog.ResumeAt(1), 1u) << "tick 1 was sent and lost";
  EXPECT_EQ(backlog.num_dropped(), 14u);
  EXPECT_EQ(UnsentTicks(backlog), (std::vector<uint64_t>{15, 16, 17, 18, 19}));
}

}  // namespace
}  // namespace idms::test
