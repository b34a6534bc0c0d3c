// The straight needle (sim/src/needle.cc, issue 32): no puncture below the threshold, puncture
// within the tick the tip force passes it, axial friction (slip at mu f_n, stick below), withdrawal,
// no step in the device force at the puncture, determinism, no allocation, bad parameters refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include "alloc_counter.h"
#include "idms/sim/generate.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "step_test_util.h"

namespace idms {
namespace {

// Above atom 10 of the hex fragment, (1.5, 1.732, 0): an inner atom of the top surface.
constexpr double kX = 1.5, kY = 1.732;
constexpr double kTip = 0.25;  // tip radius

ToolCommand Needle(double z, double puncture_force) {
  ToolCommand c;
  c.kind = ToolKind::kNeedle;
  c.pos[0] = kX, c.pos[1] = kY, c.pos[2] = z;
  c.axis[0] = 0, c.axis[1] = 0, c.axis[2] = -1;
  c.radius = kTip;
  c.stiffness = 400;
  c.law = ContactLaw::kLinear;
  c.needle.length = 5;
  c.needle.puncture_force = puncture_force;
  c.needle.mu = 0.5;
  c.needle.grip = 1;
  c.needle.capture_radius = 0.7;
  c.needle.lateral_stiffness = 20;  // of the order of the tissue's element k (15)
  c.needle.axial_stiffness = 100;
  return c;
}

struct Tick {
  double z = 0;
  double force[3] = {0, 0, 0};  // device force
  ToolReport report;
};

// The tip's height along a press-insert-hold-withdraw path at speed v (units / s): from z0 down
// to z_low, held for hold_s, then back up to z0.
struct Path {
  double z0 = kTip + 0.05;
  double z_low = -1.0;
  double speed = 0.2;
  double hold_s = 0.2;
  double Z(double t) const {
    const double down = (z0 - z_low) / speed;
    if (t <= down) return z0 - speed * t;
    if (t <= down + hold_s) return z_low;
    return std::min(z0, z_low + speed * (t - down - hold_s));
  }
  double Duration() const { return 2 * (z0 - z_low) / speed + hold_s; }
};

std::vector<Tick> RunNeedle(const Model& model, State& state, Workspace& ws, const Path& path, double puncture_force,
                            double seconds = -1) {
  const double dt = ws.options.dt_s;
  const auto n = static_cast<int64_t>(std::llround((seconds > 0 ? seconds : path.Duration()) / dt));
  std::vector<Tick> ticks;
  ticks.reserve(n);
  ToolInput in;
  in.num_tools = 1;
  for (int64_t i = 0; i < n; ++i) {
    Tick k;
    k.z = path.Z((i + 1) * dt);
    in.tools[0] = Needle(k.z, puncture_force);
    const StepReport r = Step(model, state, ws, in);
    k.report = r.tools[0];
    std::copy(r.tools[0].force, r.tools[0].force + 3, k.force);
    ticks.push_back(k);
  }
  return ticks;
}

int FirstPuncture(const std::vector<Tick>& ticks) {
  for (size_t i = 0; i < ticks.size(); ++i) {
    if (ticks[i].report.punctured) return static_cast<int>(i);
  }
  return -1;
}

double Step3(const double* a, const double* b) {
  return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
}

// The hex fragment of thesis figure 3-1 (generated: GenerateSlab's defaults), at rest, stepped in
// local mode with the default options.
class NeedleTest : public ::testing::Test {
 protected:
  std::vector<Tick> Insert(const Path& path, double puncture_force, double seconds = -1) {
    return RunNeedle(model_, state_, ws_, path, puncture_force, seconds);
  }
  const Model model_ = GenerateSlab(SlabOptions{});
  State state_ = MakeState(model_);
  Workspace ws_ = MakeWorkspace(model_, StepOptions{});
};

// Below the threshold the tip presses like a small MIO and never enters; with the threshold under
// the force that press reached, the needle enters in the very tick its tip force passes it.
TEST_F(NeedleTest, PuncturesOnlyAboveTheThresholdAndWithinTheTick) {
  const Model& model = model_;
  Path press;
  press.z_low = 0.1;  // a press of the surface, not through it
  {
    State state = MakeState(model);
    Workspace ws = MakeWorkspace(model, StepOptions{});
    const std::vector<Tick> ticks = RunNeedle(model, state, ws, press, 1e6, 1.0);
    double peak = 0;
    for (const Tick& k : ticks) {
      EXPECT_FALSE(k.report.punctured);
      peak = std::max(peak, k.report.tip_axial_force);
    }
    // The tip pushed the surface (its force on the device is up the axis, the hand feels it).
    EXPECT_GT(peak, 1.0);
    EXPECT_GT(ticks.back().force[2], 1.0);
    EXPECT_EQ(state.warnings.bad_tool_input, 0);
  }
  const double threshold = 0.5;
  const std::vector<Tick> ticks = Insert(press, threshold, 1.0);
  const int p = FirstPuncture(ticks);
  ASSERT_GT(p, 0);
  EXPECT_GT(ticks[p].report.tip_axial_force, threshold);
  EXPECT_LE(ticks[p - 1].report.tip_axial_force, threshold);
  EXPECT_EQ(TotalWarnings(state_.warnings), 0);
}

// Sliding in, the axial friction is mu times the grip and resists the motion; held still, the
// needle sticks (below mu f_n, no creep of its depth).
TEST_F(NeedleTest, AxialFrictionSlidesAtMuTimesTheGripAndSticksBelowIt) {
  Path path;
  const std::vector<Tick> ticks = Insert(path, 0.5, (path.z0 - path.z_low) / path.speed + path.hold_s);
  const int p = FirstPuncture(ticks);
  ASSERT_GT(p, 0);
  const int down_end = static_cast<int>(std::llround((path.z0 - path.z_low) / path.speed / ws_.options.dt_s)) - 1;
  // Sliding: the last 100 ticks of the insertion.
  int slipping = 0;
  for (int i = down_end - 100; i < down_end; ++i) {
    const ToolReport& r = ticks[i].report;
    ASSERT_TRUE(r.punctured);
    EXPECT_GT(r.needle_normal, 0.5);
    if (r.axial != FrictionState::kSlip) continue;
    ++slipping;
    // On the device, against the motion (the needle moves -z, the hand is pushed +z).
    EXPECT_NEAR(-r.axial_force, r.needle_normal * 0.5, 1e-9 * r.needle_normal);
  }
  EXPECT_GT(slipping, 90);
  // Held: sticking within its bound, the depth still.
  const ToolReport& held = ticks.back().report;
  EXPECT_EQ(held.axial, FrictionState::kStick);
  EXPECT_LE(std::fabs(held.axial_force), 0.5 * held.needle_normal);
  const double depth_mid = ticks[ticks.size() - 100].report.inserted;
  EXPECT_NEAR(held.inserted, depth_mid, 1e-3);
  EXPECT_GT(held.inserted, 0.5);
  EXPECT_EQ(TotalWarnings(state_.warnings), 0);
}

// Pulled back out past its entry the needle is free again, and the hand feels nothing once the
// tip has left the surface.
TEST_F(NeedleTest, WithdrawalFreesIt) {
  Path path;
  std::vector<Tick> ticks = Insert(path, 0.5);
  ASSERT_GT(FirstPuncture(ticks), 0);
  EXPECT_FALSE(ticks.back().report.punctured);
  // Held above the surface a while: no force, tip contact faded back in.
  Path away;
  away.z_low = away.z0 = kTip + 0.3;
  ticks = Insert(away, 0.5, 0.3);
  EXPECT_FALSE(ticks.back().report.punctured);
  EXPECT_LT(Step3(ticks.back().force, std::array<double, 3>{0, 0, 0}.data()), 1e-9);
  EXPECT_EQ(state_.tools[0].needle.tip_scale, 1.0);
}

// The puncture's give is felt no faster than the press built it: from the puncture on, no
// per-tick change of the device force exceeds the largest of the press before it.
TEST_F(NeedleTest, NoStepInTheDeviceForceAtThePuncture) {
  Path path;
  const std::vector<Tick> ticks = Insert(path, 0.5, (path.z0 - path.z_low) / path.speed);
  const int p = FirstPuncture(ticks);
  ASSERT_GT(p, 0);
  double press_max = 0, after_max = 0;
  for (int i = 1; i <= p; ++i) press_max = std::max(press_max, Step3(ticks[i].force, ticks[i - 1].force));
  for (size_t i = p + 1; i < ticks.size(); ++i)
    after_max = std::max(after_max, Step3(ticks[i].force, ticks[i - 1].force));
  EXPECT_GT(press_max, 0);
  EXPECT_LE(after_max, press_max) << "press " << press_max << ", after the puncture " << after_max;
  // The tip's give happened: its contact faded out over several ticks.
  EXPECT_EQ(state_.tools[0].needle.tip_scale, 0.0);
  EXPECT_GT(state_.tools[0].needle.tip_ramp, 0.0);
}

// The hand feels exactly what the tissue receives: the device force is minus the sum of the
// needle's forces on the atoms (before the clamps, which this path never reaches).
TEST_F(NeedleTest, DeviceForceIsTheTissueReaction) {
  Path path;
  const std::vector<Tick> ticks = Insert(path, 0.5, (path.z0 - path.z_low) / path.speed);
  for (const Tick& k : ticks) {
    for (int c = 0; c < 3; ++c) EXPECT_EQ(k.force[c], k.report.force_raw[c]);
  }
  EXPECT_GT(ticks.back().report.needle_atoms, 1);
}

// Same inputs, same bits: twice from rest, and from a snapshot taken inside the tissue.
TEST_F(NeedleTest, IsDeterministic) {
  const Model& model = model_;
  Path path;
  auto run = [&](State& state, Workspace& ws) { return RunNeedle(model, state, ws, path, 0.5); };
  State a = MakeState(model), b = MakeState(model);
  Workspace wa = MakeWorkspace(model, StepOptions{}), wb = MakeWorkspace(model, StepOptions{});
  const std::vector<Tick> ta = run(a, wa), tb = run(b, wb);
  EXPECT_EQ(test::HashState(a), test::HashState(b));
  ASSERT_EQ(ta.size(), tb.size());
  for (size_t i = 0; i < ta.size(); ++i) {
    for (int c = 0; c < 3; ++c) ASSERT_EQ(ta[i].force[c], tb[i].force[c]) << i;
  }
  // A snapshot inside the tissue replays to the same bits in a fresh workspace.
  State& s = state_;
  Workspace& ws = ws_;
  const double inside = (path.z0 - path.z_low) / path.speed;
  RunNeedle(model, s, ws, path, 0.5, inside);
  ASSERT_TRUE(s.tools[0].needle.punctured);
  State snapshot = s;
  Path rest = path;
  rest.z0 = rest.z_low;  // hold, then nothing more: the same input for both
  RunNeedle(model, s, ws, rest, 0.5, 0.1);
  Workspace fresh = MakeWorkspace(model, StepOptions{});
  RunNeedle(model, snapshot, fresh, rest, 0.5, 0.1);
  EXPECT_EQ(test::HashState(s), test::HashState(snapshot));
  EXPECT_EQ(s.tools[0].needle.axial_offset, snapshot.tools[0].needle.axial_offset);
}

// Every scheme, and full mode (whose fused pass hands the ticks with a needle inside to the general
// kernel), gives the same bits twice and takes the needle in.
class NeedleSchemes : public ::testing::TestWithParam<std::pair<Integrator, bool>> {};

TEST_P(NeedleSchemes, SameInputsSameBits) {
  const Model model = GenerateSlab(SlabOptions{});
  StepOptions options;
  options.integrator = GetParam().first;
  options.full = GetParam().second;
  Path path;
  State a = MakeState(model), b = MakeState(model);
  Workspace wa = MakeWorkspace(model, options), wb = MakeWorkspace(model, options);
  const std::vector<Tick> ta = RunNeedle(model, a, wa, path, 0.5), tb = RunNeedle(model, b, wb, path, 0.5);
  EXPECT_GT(FirstPuncture(ta), 0);
  EXPECT_EQ(test::HashState(a), test::HashState(b));
  for (size_t i = 0; i < ta.size(); ++i) {
    for (int c = 0; c < 3; ++c) ASSERT_EQ(ta[i].force[c], tb[i].force[c]) << i;
  }
}

INSTANTIATE_TEST_SUITE_P(Schemes, NeedleSchemes,
                         ::testing::Values(std::pair{Integrator::kExplicitEuler, false},
                                           std::pair{Integrator::kSymplecticEuler, false},
                                           std::pair{Integrator::kRk4, false},
                                           std::pair{Integrator::kImplicitEuler, false},
                                           std::pair{Integrator::kSymplecticEuler, true}));

// Inside the tissue the step allocates nothing.
TEST_F(NeedleTest, StepAllocatesNothingInside) {
  Path path;
  Insert(path, 0.5, 0.5);
  ToolInput in;
  in.num_tools = 1;
  const int64_t before = test::AllocationCount();
  for (int i = 0; i < 200; ++i) {
    in.tools[0] = Needle(path.Z(0.5 + i * 1e-3), 0.5);
    Step(model_, state_, ws_, in);
  }
  EXPECT_EQ(test::AllocationCount(), before);
  EXPECT_TRUE(state_.tools[0].needle.punctured);
}

// Bad parameters: the boundary's check names the field; the step holds the last valid pose.
// The pose a device gives: the local -z of its orientation. The pierce's quaternion (-30 degrees
// about y) points the needle down and towards +x, and the script's tip moves along that axis.
TEST(NeedleAxis, IsTheOrientationsLocalMinusZAndThePierceMovesAlongIt) {
  const double identity[4] = {1, 0, 0, 0};
  double axis[3];
  NeedleAxisOf(identity, axis);
  EXPECT_EQ(axis[0], 0);
  EXPECT_EQ(axis[1], 0);
  EXPECT_EQ(axis[2], -1);
  const double half_turn_x[4] = {0, 1, 0, 0};  // 180 degrees about x: the needle points up
  NeedleAxisOf(half_turn_x, axis);
  EXPECT_NEAR(axis[2], 1, 1e-15);
  const ScriptGeometry g = MakeScriptGeometry(test::LoadShippedModel("hex_4x5_home"), PierceNeedle().radius);
  const ScriptSample a = SampleScript(Script::kPierce, g, 2.0), b = SampleScript(Script::kPierce, g, 3.0);
  ASSERT_TRUE(a.oriented);
  NeedleAxisOf(a.orientation, axis);
  const double tilt = kPierceTiltDeg * std::numbers::pi / 180;
  EXPECT_NEAR(axis[0], std::sin(tilt), 1e-12);
  EXPECT_NEAR(axis[1], 0, 1e-12);
  EXPECT_NEAR(axis[2], -std::cos(tilt), 1e-12);
  const double d[3] = {b.pos[0] - a.pos[0], b.pos[1] - a.pos[1], b.pos[2] - a.pos[2]};
  const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  ASSERT_GT(n, 0.1);
  EXPECT_NEAR((d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2]) / n, 1, 1e-12);
}

TEST_F(NeedleTest, BadParametersAreRefusedNamingTheField) {
  std::string error;
  ToolCommand c = Needle(1, 0.5);
  EXPECT_TRUE(ValidateNeedle(c, &error)) << error;
  struct Bad {
    double NeedleParams::*field;
    double value;
    const char* error;
  };
  const Bad bad[] = {
      {&NeedleParams::puncture_force, 0, "needle.puncture_force must be a finite number > 0, got 0"},
      {&NeedleParams::length, std::nan(""), "needle.length must be a finite number > 0, got nan"},
      {&NeedleParams::mu, -0.1, "needle.mu must be a finite number >= 0, got -0.1"},
      {&NeedleParams::axial_damping, std::numeric_limits<double>::infinity(),
       "needle.axial_damping must be a finite number (< 0 = axial_stiffness * dt), got inf"},
  };
  for (const Bad& b : bad) {
    c = Needle(1, 0.5);
    c.needle.*b.field = b.value;
    EXPECT_FALSE(ValidateNeedle(c, &error));
    EXPECT_EQ(error, b.error);
  }

  // In the step: a zero axis or a bad parameter is bad input, the last valid pose held.
  ToolInput in;
  in.num_tools = 1;
  in.tools[0] = Needle(1, 0.5);
  Step(model_, state_, ws_, in);
  in.tools[0].axis[2] = 0;
  in.tools[0].pos[2] = 0.5;
  EXPECT_TRUE(Step(model_, state_, ws_, in).tools[0].input_held);
  in.tools[0] = Needle(0.5, std::numeric_limits<double>::quiet_NaN());
  EXPECT_TRUE(Step(model_, state_, ws_, in).tools[0].input_held);
  EXPECT_EQ(state_.tools[0].pos[2], 1.0);
  EXPECT_EQ(state_.warnings.bad_tool_input, 2);
}

}  // namespace
}  // namespace idms
