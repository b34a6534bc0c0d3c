// The uplink's frame order: events, then the newest surface, then full sample batches; a short
// batch and ENDED only once the loop has finished.
#include "frame_order.h"

#include <gtest/gtest.h>

namespace idms::test {
namespace {

using agent::FrameKind;
using agent::FrameOrder;
using agent::Waiting;

Waiting Make(size_t events, bool surface, size_t samples, bool finished) {
  Waiting w;
  w.events = events;
  w.surface = surface;
  w.samples = samples;
  w.loop_finished = finished;
  return w;
}

TEST(FrameOrder, EventsThenSurfaceThenSamples) {
  const FrameOrder order(20);
  EXPECT_EQ(order.Next(Make(1, true, 100, false)).kind, FrameKind::kEvent);
  EXPECT_EQ(order.Next(Make(0, true, 100, false)).kind, FrameKind::kSurface);
  EXPECT_EQ(order.Next(Make(0, false, 100, false)).kind, FrameKind::kSamples);
  EXPECT_EQ(order.Next(Make(0, false, 100, false)).num_samples, 20u) << "at most one batch per frame";
}

TEST(FrameOrder, PartialBatchWaitsUntilTheLoopHasFinished) {
  const FrameOrder order(20);
  EXPECT_EQ(order.Next(Make(0, false, 19, false)).kind, FrameKind::kNone);
  EXPECT_EQ(order.Next(Make(0, false, 20, false)).num_samples, 20u);
  const agent::NextFrame last = order.Next(Make(0, false, 7, true));
  EXPECT_EQ(last.kind, FrameKind::kSamples);
  EXPECT_EQ(last.num_samples, 7u);
}

TEST(FrameOrder, EndedOnlyWhenEverythingIsSentAndTheLoopHasFinished) {
  const FrameOrder order(20);
  EXPECT_EQ(order.Next(Make(0, false, 0, false)).kind, FrameKind::kNone);
  EXPECT_EQ(order.Next(Make(1, false, 0, true)).kind, FrameKind::kEvent);
  EXPECT_EQ(order.Next(Make(0, true, 0, true)).kind, FrameKind::kSurface);
  EXPECT_EQ(order.Next(Make(0, false, 1, true)).kind, FrameKind::kSamples);
  EXPECT_EQ(order.Next(Make(0, false, 0, true)).kind, FrameKind::kEnded);
}

TEST(FrameOrder, BatchDefaultsToTwentyWhenTheSceneLeavesItUnset) {
  EXPECT_EQ(FrameOrder(0).batch(), 20u);
  EXPECT_EQ(FrameOrder(5).batch(), 5u);
  EXPECT_EQ(FrameOrder(5).Next(Make(0, false, 12, false)).num_samples, 5u);
}

}  // namespace
}  // namespace idms::test
