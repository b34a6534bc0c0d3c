// Global dynamics at a slower rate (global.cc, global_compare.cc): the two-rate mode against the
// whole model at 1 kHz on a pluck that local simulation alone gets wrong, the blend that keeps
// the force from jumping at an update, the threaded pass that the local loop never waits for,
// and a clean stop.
#include "idms/sim/global.h"

#include <gtest/gtest.h>

#include <cmath>

#include "alloc_counter.h"
#include "idms/sim/generate.h"
#include "idms/sim/global_compare.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"

namespace idms {
namespace {

// A slab on home springs a fiftieth of its elements' k: a pluck lifts far more than the window.
Model SoftMembrane() {
  SlabOptions so;
  so.rows = 20, so.cols = 20;
  so.home_k = 0.3;
  return GenerateSlab(so);
}

TEST(GlobalDynamics, TwoRateFollowsTheWholeModelOnAPluckWhereLocalOnlyDoesNot) {
  const Model model = SoftMembrane();
  const ScriptedTrace reference = RunScripted(model, {.script = Script::kPluck, .mode = RunMode::kFull});
  const TraceError local =
      CompareTraces(reference, RunScripted(model, {.script = Script::kPluck, .mode = RunMode::kLocal}));
  const ScriptedTrace two_rate =
      RunScripted(model, {.script = Script::kPluck, .mode = RunMode::kTwoRate, .global_rate_hz = 100});
  const TraceError global = CompareTraces(reference, two_rate);
  ASSERT_GT(local.peak_force, 0.1) << "the pluck pulled nothing";
  // The goals: force RMS error within 5% of the peak, no jump over 0.05 N at an update.
  EXPECT_GT(local.force_rms, 0.05 * local.peak_force) << "local simulation alone is close enough: no test";
  EXPECT_LT(global.force_rms, 0.05 * global.peak_force);
  EXPECT_LT(global.force_max, 0.5 * local.force_max);
  EXPECT_LT(global.surface_rms, 0.5 * local.surface_rms) << "the membrane around the window did not follow";
  EXPECT_EQ(two_rate.update_ticks.size(), 499u) << "a result every 10 ticks after the first";
  EXPECT_LT(global.jump_at_update_max, 0.05);
}

TEST(GlobalDynamics, AnUpdateAddsNoJumpToAStrokesForce) {
  // A stroke changes the force by tenths of a newton from one tick to the next as surface atoms
  // enter the sphere, at update ticks as elsewhere. The update's own part: against the same run
  // with its exchanges half a slow step later (no update at these ticks, the same contacts).
  const Model model = SoftMembrane();
  const ScriptedRunOptions o{.script = Script::kStrokeSlow, .mode = RunMode::kTwoRate, .global_rate_hz = 100};
  ScriptedRunOptions shifted = o;
  shifted.global_phase = 5;
  const ScriptedTrace run = RunScripted(model, o);
  const UpdateJump u = CompareShifted(run, RunScripted(model, shifted));
  ASSERT_GT(run.update_ticks.size(), 500u);
  EXPECT_LT(u.at_update_max, 0.05);
  EXPECT_LT(u.at_update_max, u.elsewhere_max + 1e-3) << "the updates stand out";
}

TEST(GlobalDynamics, SynchronousRunsAreReproducibleAndTheBlendNeverJumps) {
  const Model model = SoftMembrane();
  const ScriptedRunOptions o{
      .script = Script::kPluck, .mode = RunMode::kTwoRate, .global_rate_hz = 50, .max_ticks = 2500};
  const ScriptedTrace a = RunScripted(model, o), b = RunScripted(model, o);
  ASSERT_EQ(a.force.size(), b.force.size());
  for (size_t i = 0; i < a.force.size(); ++i) ASSERT_EQ(a.force[i], b.force[i]) << i;
  EXPECT_EQ(a.surface, b.surface);
  // Atoms outside the window move by at most (target - start) / K per tick: the surface between
  // two samples 10 ticks apart moves by no more than the reference's does in a slow step.
  double largest = 0;
  const size_t n = model.external_atoms.size() * 3;
  for (size_t s = n; s < a.surface.size(); s += 1)
    largest = std::max(largest, std::fabs(a.surface[s] - a.surface[s - n]));
  EXPECT_LT(largest, 0.5);
}

TEST(GlobalDynamics, TheLocalLoopNeverWaitsForASlowThreadedPass) {
  const Model model = SoftMembrane();
  StepOptions step;
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, step);
  // 200 ms after every global step: a pass far slower than its 100 Hz.
  GlobalDynamics global(model, s, step, {.rate_hz = 100, .threaded = true, .extra_delay_us = 200000});
  ToolInput input = {};
  input.num_tools = 1;
  input.tools[0].kind = ToolKind::kSphere;
  input.tools[0].pos[2] = 10;
  Step(model, s, ws, input), global.AfterTick(s, ws);
  const int64_t allocations = test::AllocationCount();
  for (int i = 1; i < 400; ++i) Step(model, s, ws, input), global.AfterTick(s, ws);
  EXPECT_EQ(test::AllocationCount() - allocations, 0) << "the loop's side allocated";
  const GlobalStats st = global.stats();
  // 40 exchanges; had AfterTick waited for the pass, none would have found it still stepping.
  EXPECT_LE(st.steps, 2);
  EXPECT_GE(st.late, 35);
  EXPECT_LE(st.exchanges, 1);
  // The destructor stops the thread while it sleeps in its slow step.
}

TEST(GlobalDynamics, ReportsTheRateItCanReach) {
  const Model model = SoftMembrane();
  StepOptions step;
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, step);
  GlobalDynamics global(model, s, step, {.rate_hz = 100});
  EXPECT_EQ(global.ticks_per_step(), 10);
  for (int i = 0; i < 50; ++i) Step(model, s, ws, ToolInput{}), global.AfterTick(s, ws);
  const GlobalStats st = global.stats();
  EXPECT_EQ(st.steps, 5);
  EXPECT_EQ(st.exchanges, 4);
  EXPECT_GT(st.last_step_ms, 0);
  EXPECT_NEAR(st.reachable_hz, 1e3 / st.last_step_ms, 0.9 * 1e3 / st.last_step_ms);
}

}  // namespace
}  // namespace idms
