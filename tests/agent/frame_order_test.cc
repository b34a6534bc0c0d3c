// The uplink's frame order: events, then the newest surface (the samples up to it just before
// it), then full sample batches; other short batches and ENDED only once the loop has finished.
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

// Live: the samples of the mesh period go as a short batch right before their surface, so the
// server can forward both to viewers together without waiting for the next surface.
TEST(FrameOrder, TheSamplesUpToASurfaceGoJustBeforeIt) {
  const FrameOrder order(20);
  Waiting w = Make(0, true, 17, false);
  w.samples_to_surface = 17;
  EXPECT_EQ(order.Next(w).kind, FrameKind::kSamples);
  EXPECT_EQ(order.Next(w).num_samples, 17u);
  w.events = 1;
  EXPECT_EQ(order.Next(w).kind, FrameKind::kEvent) << "events still first";
  // Written; one more sample came meanwhile, after the surface: the surface goes, never starved
  // by samples that keep arriving.
  w = Make(0, true, 1, false);
  w.samples_to_surface = 0;
  EXPECT_EQ(order.Next(w).kind, FrameKind::kSurface);
  // Catching up after a resume (more than a batch before the surface): the surface first.
  w = Make(0, true, 500, false);
  w.samples_to_surface = 21;
  EXPECT_EQ(order.Next(w).kind, FrameKind::kSurface);
  w.samples_to_surface = 20;
  EXPECT_EQ(order.Next(w).kind, FrameKind::kSamples);
  EXPECT_EQ(order.Next(w).num_samples, 20u);
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
