// Friction with stiction (sim/src/friction.cc, issue 30): a finger held sideways below mu_s f_n
// does not creep, above it slides at mu_d f_n, no chattering, passivity, prediction, determinism,
// the tweezers, and bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "alloc_counter.h"
#include "idms/sim/drag.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/model_io.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "step_test_util.h"

namespace idms {
namespace {

Model Hex() { return test::LoadShippedModel("hex_4x5_home"); }

ToolCommand Finger(double mu_s, double mu_d) {
  ToolCommand c;
  c.kind = ToolKind::kSphere;
  c.radius = 1.5;
  c.stiffness = 400;
  c.mu_s = mu_s;
  c.mu_d = mu_d;
  return c;
}

// One tick of the drag's history.
struct DragTick {
  double t, hand_x, push, fx, ft, fn;
  double anchor[3];  // the anchor point (weighted anchor atoms)
  FrictionState state;
  double work;
  int64_t warnings;
};

struct DragRun {
  std::vector<DragTick> ticks;
  double fn = 0;  // the drag's measured f_n
  double hold_start = 0;
};

DragRun RunDrag(const Model& model, ToolCommand tool, double fraction, StepOptions options = {}) {
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, options);
  DragOptions drag;
  drag.fraction = fraction;
  drag.mu_s = tool.mu_s;
  DragHand hand(MakeScriptGeometry(model, tool.radius), drag);
  DragRun run;
  run.hold_start = hand.HoldStart();
  ToolInput input;
  input.num_tools = 1;
  double force[3] = {0, 0, 0};
  const auto ticks = static_cast<int64_t>(std::llround(hand.Duration() / options.dt_s));
  for (int64_t n = 0; n < ticks; ++n) {
    const double t = (n + 1) * options.dt_s;
    const ScriptSample sample = hand.Next(t, force);
    for (int c = 0; c < 3; ++c) tool.pos[c] = sample.pos[c];
    input.tools[0] = tool;
    const StepReport r = Step(model, state, ws, input);
    const ToolReport& tr = r.tools[0];
    for (int c = 0; c < 3; ++c) force[c] = tr.force[c];
    DragTick k{};
    k.t = t, k.hand_x = hand.hand_x(), k.push = hand.push_force(), k.fx = tr.force[0];
    k.ft = std::sqrt(tr.friction_force[0] * tr.friction_force[0] + tr.friction_force[1] * tr.friction_force[1] +
                     tr.friction_force[2] * tr.friction_force[2]);
    k.fn = tr.normal_force;
    const ToolState& ts = state.tools[0];
    for (int i = 0; i < kAnchorAtoms && ts.anchor_atoms[i] >= 0; ++i) {
      for (int c = 0; c < 3; ++c) k.anchor[c] += ts.anchor_w[i] * state.atom_pos[3 * ts.anchor_atoms[i] + c];
    }
    k.state = tr.friction, k.work = tr.friction_work, k.warnings = TotalWarnings(state.warnings);
    run.ticks.push_back(k);
  }
  run.fn = hand.normal_force();
  return run;
}

const DragTick& At(const DragRun& run, double t) {
  for (const DragTick& k : run.ticks) {
    if (k.t >= t - 1e-9) return k;
  }
  return run.ticks.back();
}

TEST(Friction, AHeldSidewaysPushBelowMuSDoesNotCreep) {
  const Model model = Hex();
  const DragRun run = RunDrag(model, Finger(0.6, 0.4), 0.5);
  ASSERT_GT(run.fn, 0.5);
  // The last 10 s of the script: the hand and the anchored surface point stay put.
  const DragTick& a = At(run, run.ticks.back().t - 10.0);
  const DragTick& b = run.ticks.back();
  EXPECT_LT(std::fabs(b.hand_x - a.hand_x), 1e-6) << "the tool crept";
  for (int c = 0; c < 3; ++c) EXPECT_LT(std::fabs(b.anchor[c] - a.anchor[c]), 1e-6) << "the anchor crept, axis " << c;
  // It sticks all through the push, and the tangential force carries the push.
  for (const DragTick& k : run.ticks) {
    if (k.t >= run.hold_start) {
      ASSERT_EQ(k.state, FrictionState::kStick) << "at t = " << k.t;
    }
  }
  // The tangential force carries the push (plus the little the press itself left, 0.01 N).
  EXPECT_NEAR(b.ft, b.push, 0.01 * b.push);
  EXPECT_EQ(b.warnings, 0);
  std::printf("held at %.2f mu_s f_n = %.4g: tool moved %.3g, anchor %.3g over the last 10 s\n", 0.5, b.push,
              std::fabs(b.hand_x - a.hand_x), std::fabs(b.anchor[0] - a.anchor[0]));
}

TEST(Friction, AboveMuSItSlipsAtMuDWithoutChattering) {
  const Model model = Hex();
  const ToolCommand finger = Finger(0.6, 0.4);
  const DragRun run = RunDrag(model, finger, 1.3);
  // The first stretch of sliding, before the finger leaves the first atoms (the DSM's surface is
  // its atoms: between them a sphere at a fixed depth loses contact, the thesis's bumps).
  const DragTick& a = At(run, run.hold_start + 0.25);
  const DragTick& b = At(run, run.hold_start + 2.0);
  EXPECT_GT(b.hand_x - a.hand_x, 0.05) << "the tool did not slide";
  // Steady sliding: the tangential force is mu_d f_n (of the same tick's normal force).
  int transitions = 0, last_transition = -1000, slipping = 0;
  double worst = 0;
  for (size_t i = 1; i < run.ticks.size(); ++i) {
    const DragTick& k = run.ticks[i];
    const FrictionState before = run.ticks[i - 1].state;
    if (k.state != before && before != FrictionState::kNone && k.state != FrictionState::kNone) {
      ++transitions;
      EXPECT_GE(static_cast<int>(i) - last_transition, 10) << "two transitions within 10 ms at t = " << k.t;
      last_transition = static_cast<int>(i);
    }
    if (k.t < a.t || k.t > b.t) continue;
    ASSERT_EQ(k.state, FrictionState::kSlip) << "at t = " << k.t;
    ++slipping;
    EXPECT_NEAR(k.ft, finger.mu_d * k.fn, 0.02 * finger.mu_d * k.fn) << "at t = " << k.t;
    worst = std::max(worst, std::fabs(k.ft / (finger.mu_d * k.fn) - 1));
  }
  EXPECT_GT(slipping, 1000);
  EXPECT_LE(transitions, 3);
  std::printf("sliding: |f_t / (mu_d f_n) - 1| <= %.3g over %d ticks; %d stick/slip transitions\n", worst, slipping,
              transitions);
}

}  // namespace
}  // namespace idms

namespace idms {
namespace {

struct ScriptRun {
  // Friction's work (plus its spring's energy change): the largest in a tick, the sum, and the
  // largest the running sum reached (the passivity observer's energy, Hannaford and Ryu 2002).
  double max_work = -1e300, sum_work = 0, max_sum = 0;
  double max_ft = 0;
  int64_t stick = 0, slip = 0, warnings = 0, unrecovered = 0;
  uint64_t hash = 0;
  bool finite = true;
};

ScriptRun RunScript(const Model& model, Script script, ToolCommand tool, StepOptions options) {
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, options);
  const ScriptGeometry g = MakeScriptGeometry(model, tool.radius);
  if (script == Script::kPluck) tool.kind = ToolKind::kTweezers;
  ToolInput input;
  input.num_tools = 1;
  ScriptRun out;
  const auto ticks = static_cast<int64_t>(std::llround(ScriptDuration(script) / options.dt_s));
  for (int64_t n = 0; n < ticks; ++n) {
    const ScriptSample sample = SampleScript(script, g, (n + 1) * options.dt_s);
    for (int c = 0; c < 3; ++c) tool.pos[c] = sample.pos[c];
    tool.closed = sample.closed;
    input.tools[0] = tool;
    const StepReport r = Step(model, state, ws, input);
    const ToolReport& tr = r.tools[0];
    out.max_work = std::max(out.max_work, tr.friction_work);
    out.sum_work += tr.friction_work;
    out.max_sum = std::max(out.max_sum, out.sum_work);
    out.max_ft = std::max(out.max_ft, std::hypot(tr.friction_force[0], tr.friction_force[1], tr.friction_force[2]));
    out.stick += tr.friction == FrictionState::kStick;
    out.slip += tr.friction == FrictionState::kSlip;
    out.unrecovered += r.unrecovered;
    for (double f : tr.force) out.finite = out.finite && std::isfinite(f);
  }
  out.warnings = TotalWarnings(state.warnings);
  out.hash = test::HashState(state);
  return out;
}

constexpr Script kScripts[] = {Script::kPalpate, Script::kStrokeSlow, Script::kStrokeFast, Script::kStrokeGentle,
                               Script::kPluck};

// Friction only dissipates. Its work on the atoms and the device plus the change of its spring's
// energy, summed from the start (the energy a passivity observer sees), never exceeds 1e-9 in any
// shipped script or the drag, with and without the energy check, and the scripts run without a
// warning. Per tick it can be slightly positive: the atoms are integrated explicitly, so within a
// tick they move under the friction force of the tick's start, which gains k_t |du|^2 / 2 (the
// damping b_t = k_t T pays it back over the following ticks). The figures are printed.
TEST(Friction, NeverAddsEnergy) {
  const Model model = Hex();
  for (bool check : {true, false}) {
    StepOptions options;
    options.stability.energy_check = check;
    for (Script script : kScripts) {
      const ScriptRun run = RunScript(model, script, Finger(0.6, 0.4), options);
      EXPECT_LE(run.max_sum, 1e-9) << ScriptName(script) << (check ? "" : " without the energy check");
      EXPECT_LE(run.sum_work, 1e-9) << ScriptName(script);
      EXPECT_GT(run.stick + run.slip, 0) << ScriptName(script);
      EXPECT_EQ(run.warnings, 0) << ScriptName(script);
      std::printf(
          "%-13s energy check %-3s: friction's work: largest running sum %.3g, total %.3g, largest in a tick %.3g; "
          "%lld stick, %lld slip ticks\n",
          ScriptName(script), check ? "on" : "off", run.max_sum, run.sum_work, run.max_work,
          static_cast<long long>(run.stick), static_cast<long long>(run.slip));
    }
    for (double fraction : {0.5, 1.3}) {
      const DragRun run = RunDrag(model, Finger(0.6, 0.4), fraction, options);
      double max_work = -1e300, sum = 0, max_sum = 0;
      for (const DragTick& k : run.ticks)
        max_work = std::max(max_work, k.work), sum += k.work, max_sum = std::max(max_sum, sum);
      EXPECT_LE(max_sum, 1e-9) << "drag " << fraction;
      std::printf(
          "drag %.1f      energy check %-3s: friction's work: largest running sum %.3g, total %.3g, largest in a tick "
          "%.3g\n",
          fraction, check ? "on" : "off", max_sum, sum, max_work);
    }
  }
}

// Hysteresis: a push between mu_d and mu_s of f_n holds a contact that sticks, but once a kick
// has made it slip, the same push keeps it sliding (it sticks again only below mu_d f_n).
TEST(Friction, StickSlipHasHysteresis) {
  const Model model = Hex();
  const ToolCommand finger = Finger(0.6, 0.3);
  // 0.8 mu_s f_n = 1.6 mu_d f_n: held.
  const DragRun held = RunDrag(model, finger, 0.8);
  EXPECT_EQ(held.ticks.back().state, FrictionState::kStick);
  EXPECT_LT(std::fabs(held.ticks.back().hand_x - At(held, held.ticks.back().t - 10).hand_x), 1e-6);
  // The same push after a kick: a second run whose hand is shoved (10 force units for 30 ms).
  State state = MakeState(model);
  StepOptions options;
  Workspace ws = MakeWorkspace(model, options);
  DragOptions drag;
  drag.fraction = 0.8;
  drag.mu_s = finger.mu_s;
  DragHand hand(MakeScriptGeometry(model, finger.radius), drag);
  ToolInput input;
  input.num_tools = 1;
  double force[3] = {0, 0, 0};
  int64_t slip_after_kick = 0, ticks_after_kick = 0;
  for (int64_t n = 0; (n + 1) * 1e-3 <= hand.HoldStart() + 2.0; ++n) {
    const double t = (n + 1) * 1e-3;
    const bool kick = t > hand.HoldStart() && t <= hand.HoldStart() + 0.03;
    double felt[3] = {force[0] + (kick ? 10.0 : 0.0), force[1], force[2]};
    const ScriptSample sample = hand.Next(t, felt);
    ToolCommand tool = finger;
    for (int c = 0; c < 3; ++c) tool.pos[c] = sample.pos[c];
    input.tools[0] = tool;
    const StepReport r = Step(model, state, ws, input);
    for (int c = 0; c < 3; ++c) force[c] = r.tools[0].force[c];
    if (t > hand.HoldStart() + 0.1 && t < hand.HoldStart() + 1.0) {
      ++ticks_after_kick;
      slip_after_kick += r.tools[0].friction == FrictionState::kSlip;
    }
  }
  EXPECT_GT(slip_after_kick, ticks_after_kick * 9 / 10) << "the kicked contact stuck again under 1.6 mu_d f_n";
}

// The friction spring enters the stable-step prediction: with a tangential spring 100 times the
// MIO's (omega ~ 6e3 1/s on a 0.002 atom, against a tissue that is stable at 1 ms), the step
// predicts substeps and does not diverge; without the prediction the same case fails its checks.
TEST(Friction, StiffTangentialSpringIsPredicted) {
  const Model model = Hex();
  auto run = [&](bool friction, bool predict) {
    StepOptions options;
    options.stability.predict = predict;
    options.stability.implicit_fallback = false;
    State state = MakeState(model);
    Workspace ws = MakeWorkspace(model, options);
    ToolCommand tool = Finger(friction ? 0.6 : 0, friction ? 0.4 : 0);
    tool.friction_stiffness = 4e4;
    const ScriptGeometry g = MakeScriptGeometry(model, tool.radius);
    ToolInput input;
    input.num_tools = 1;
    double min_dt = 1e300;
    for (int n = 0; n < 3000; ++n) {
      const ScriptSample sample = SampleScript(Script::kStrokeSlow, g, 1.5 + (n + 1) * 1e-3);
      for (int c = 0; c < 3; ++c) tool.pos[c] = sample.pos[c];
      input.tools[0] = tool;
      const StepReport r = Step(model, state, ws, input);
      if (r.predicted_dt_s > 0) min_dt = std::min(min_dt, r.predicted_dt_s);
    }
    return std::make_pair(min_dt, state.warnings.rollback + state.warnings.unrecovered);
  };
  const auto [dt_without, failures_without] = run(false, true);
  const auto [dt_with, failures_with] = run(true, true);
  const auto [dt_blind, failures_blind] = run(true, false);
  EXPECT_LT(dt_with, 0.5 * dt_without) << "the friction spring did not shorten the predicted step";
  EXPECT_EQ(failures_with, 0);
  EXPECT_GT(failures_blind, 0) << "the case does not need the prediction";
  std::printf("predicted stable step: %.3g s frictionless, %.3g s with k_t = 4e4; unpredicted: %lld failed attempts\n",
              dt_without, dt_with, static_cast<long long>(failures_blind));
}

// Same inputs, same bits; and full mode's fused pass gives the general path's bits with friction.
TEST(Friction, IsDeterministicAndTheFusedPassAgrees) {
  const Model model = Hex();
  StepOptions options;
  EXPECT_EQ(RunScript(model, Script::kStrokeSlow, Finger(0.6, 0.4), options).hash,
            RunScript(model, Script::kStrokeSlow, Finger(0.6, 0.4), options).hash);
  EXPECT_NE(RunScript(model, Script::kStrokeSlow, Finger(0.6, 0.4), options).hash,
            RunScript(model, Script::kStrokeSlow, Finger(0, 0), options).hash);
  options.full = true;
  const ScriptRun fused = RunScript(model, Script::kStrokeSlow, Finger(0.6, 0.4), options);
  options.fused_pass = false;
  const ScriptRun general = RunScript(model, Script::kStrokeSlow, Finger(0.6, 0.4), options);
  EXPECT_EQ(fused.hash, general.hash);
  EXPECT_GT(fused.slip, 0);
}

// Frictionless is the default and unchanged: mu_s = 0 gives the bits of a tool without the fields.
TEST(Friction, OffByDefaultAndFree) {
  const Model model = Hex();
  EXPECT_EQ(ToolCommand{}.mu_s, 0.0);
  const ScriptRun off = RunScript(model, Script::kStrokeSlow, Finger(0, 0), {});
  EXPECT_EQ(off.stick + off.slip, 0);
  EXPECT_EQ(off.max_ft, 0.0);
}

// The step never allocates with friction (anchoring, slipping, re-spreading, losing contact).
TEST(Friction, StepAllocatesNothing) {
  const Model model = Hex();
  StepOptions options;
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, options);
  ToolCommand tool = Finger(0.6, 0.4);
  const ScriptGeometry g = MakeScriptGeometry(model, tool.radius);
  ToolInput input;
  input.num_tools = 1;
  const int64_t before = test::AllocationCount();
  for (int n = 0; n < 5800; ++n) {
    const ScriptSample sample = SampleScript(Script::kStrokeSlow, g, (n + 1) * 1e-3);
    for (int c = 0; c < 3; ++c) tool.pos[c] = sample.pos[c];
    input.tools[0] = tool;
    Step(model, state, ws, input);
  }
  EXPECT_EQ(test::AllocationCount() - before, 0);
}

// Bad coefficients reaching the step (validation is the boundary's) mean no friction, and a NaN
// pose or NaN coefficient never reaches the device.
TEST(Friction, BadInputNeverReachesTheDevice) {
  const Model model = Hex();
  const double nan = std::nan("");
  for (const ToolCommand& bad : {Finger(nan, 0.4), Finger(0.6, nan), Finger(0.4, 0.6), Finger(-0.6, -1.0)}) {
    const ScriptRun run = RunScript(model, Script::kStrokeSlow, bad, {});
    EXPECT_EQ(run.stick + run.slip, 0);
    EXPECT_TRUE(run.finite);
  }
  ToolCommand inf_k = Finger(0.6, 0.4);
  inf_k.friction_stiffness = std::numeric_limits<double>::infinity();
  EXPECT_EQ(RunScript(model, Script::kStrokeSlow, inf_k, {}).stick, 0);
  // A NaN pose in the middle of a stick: the last valid pose is held, the force stays finite.
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, {});
  ToolCommand tool = Finger(0.6, 0.4);
  const ScriptGeometry g = MakeScriptGeometry(model, tool.radius);
  ToolInput input;
  input.num_tools = 1;
  for (int n = 0; n < 4000; ++n) {
    const ScriptSample sample = SampleScript(Script::kPalpate, g, (n + 1) * 1e-3);
    for (int c = 0; c < 3; ++c) tool.pos[c] = (n % 500 == 7) ? nan : sample.pos[c];
    input.tools[0] = tool;
    const StepReport r = Step(model, state, ws, input);
    for (double f : r.tools[0].force) ASSERT_TRUE(std::isfinite(f));
    for (double f : r.tools[0].friction_force) ASSERT_TRUE(std::isfinite(f));
  }
}

// The tweezers with friction: the pluck still grasps, lifts and lets go, and while the jaws press
// the surface before closing, friction holds there too.
TEST(Friction, TweezersHoldTissueWithFriction) {
  const Model model = Hex();
  StepOptions options;
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, options);
  ToolCommand tool = Finger(0.6, 0.4);
  tool.kind = ToolKind::kTweezers;
  const ScriptGeometry g = MakeScriptGeometry(model, tool.radius);
  ToolInput input;
  input.num_tools = 1;
  bool grasped = false, stuck = false;
  double lift = 0;
  for (int n = 0; n < 5000; ++n) {
    const ScriptSample sample = SampleScript(Script::kPluck, g, (n + 1) * 1e-3);
    for (int c = 0; c < 3; ++c) tool.pos[c] = sample.pos[c];
    tool.closed = sample.closed;
    input.tools[0] = tool;
    const StepReport r = Step(model, state, ws, input);
    grasped = grasped || r.tools[0].grasp_atom >= 0;
    stuck = stuck || r.tools[0].friction == FrictionState::kStick;
    if (r.tools[0].grasp_atom >= 0) lift = std::max(lift, double(state.atom_pos[3 * r.tools[0].grasp_atom + 2]));
  }
  EXPECT_TRUE(grasped);
  EXPECT_TRUE(stuck);
  // Open tweezers pressed on the surface and pushed sideways hold as the finger does.
  ToolCommand open = Finger(0.6, 0.4);
  open.kind = ToolKind::kTweezers;
  const DragRun held = RunDrag(model, open, 0.5);
  EXPECT_EQ(held.ticks.back().state, FrictionState::kStick);
  EXPECT_LT(std::fabs(held.ticks.back().hand_x - At(held, held.ticks.back().t - 10).hand_x), 1e-6);
  EXPECT_NEAR(held.ticks.back().ft, held.ticks.back().push, 0.01 * held.ticks.back().push);
  EXPECT_GT(lift, 0.02) << "the grasped atom was not lifted";
  EXPECT_EQ(TotalWarnings(state.warnings), 0);
}

// Every integrator (and full mode's fused pass) holds below mu_s f_n and slides above it, with
// no warning: the implicit fallback's Jacobian and RK4's stages see the same friction force.
TEST(Friction, EveryIntegratorHoldsAndSlides) {
  const Model model = Hex();
  for (Integrator integrator :
       {Integrator::kExplicitEuler, Integrator::kSymplecticEuler, Integrator::kRk4, Integrator::kImplicitEuler}) {
    for (bool full : {false, true}) {
      StepOptions options;
      options.integrator = integrator;
      options.full = full;
      const DragRun held = RunDrag(model, Finger(0.6, 0.4), 0.5, options);
      const DragTick& a = At(held, held.ticks.back().t - 10.0);
      const DragTick& b = held.ticks.back();
      EXPECT_EQ(b.state, FrictionState::kStick) << IntegratorName(integrator) << (full ? " full" : "");
      EXPECT_LT(std::fabs(b.hand_x - a.hand_x), 1e-6) << IntegratorName(integrator) << (full ? " full" : "");
      EXPECT_EQ(b.warnings, 0) << IntegratorName(integrator) << (full ? " full" : "");
      const DragRun slid = RunDrag(model, Finger(0.6, 0.4), 1.3, options);
      const DragTick& c = At(slid, slid.hold_start + 0.25);
      const DragTick& d = At(slid, slid.hold_start + 1.5);
      EXPECT_EQ(d.state, FrictionState::kSlip) << IntegratorName(integrator) << (full ? " full" : "");
      EXPECT_GT(d.hand_x - c.hand_x, 0.02) << IntegratorName(integrator) << (full ? " full" : "");
      EXPECT_NEAR(d.ft, 0.4 * d.fn, 0.02 * 0.4 * d.fn) << IntegratorName(integrator) << (full ? " full" : "");
      EXPECT_EQ(slid.ticks.back().warnings, 0) << IntegratorName(integrator) << (full ? " full" : "");
    }
  }
}

// Between steps no atom keeps the stiffness the friction spring gave it (Workspace's invariant),
// though a slipping anchor moves to other atoms: local mode and full mode's fused pass.
TEST(Friction, AnchorStiffnessIsClearedBetweenSteps) {
  const Model model = Hex();
  for (bool full : {false, true}) {
    StepOptions options;
    options.full = full;
    State state = MakeState(model);
    Workspace ws = MakeWorkspace(model, options);
    ToolCommand tool = Finger(0.6, 0.4);
    const ScriptGeometry g = MakeScriptGeometry(model, tool.radius);
    ToolInput input;
    input.num_tools = 1;
    int64_t slip = 0;
    for (int n = 0; n < 4000; ++n) {
      const ScriptSample sample = SampleScript(Script::kStrokeFast, g, (n + 1) * 1e-3);
      for (int c = 0; c < 3; ++c) tool.pos[c] = sample.pos[c];
      input.tools[0] = tool;
      slip += Step(model, state, ws, input).tools[0].friction == FrictionState::kSlip;
      for (int32_t a = 0; a < model.num_atoms; ++a) {
        ASSERT_EQ(ws.atom_extra_k[a], 0.0) << "atom " << a << " after tick " << n << (full ? " (full)" : "");
      }
    }
    EXPECT_GT(slip, 100);
  }
}

// The command lines' specs (idms-sim run --tool, idms-agent --friction): what they accept sets
// exactly the named fields; every refusal names the item or the field.
TEST(Friction, SpecsAreParsedAndRefusedByItem) {
  ToolCommand tool;
  std::string error;
  ASSERT_TRUE(ParseToolSpec("sphere:r=2,k=300,law=linear,mu_s=0.6", &tool, &error)) << error;
  EXPECT_EQ(tool.kind, ToolKind::kSphere);
  EXPECT_EQ(tool.radius, 2);
  EXPECT_EQ(tool.stiffness, 300);
  EXPECT_EQ(tool.law, ContactLaw::kLinear);
  EXPECT_EQ(tool.mu_s, 0.6);
  EXPECT_EQ(tool.mu_d, 0.6) << "mu_d defaults to mu_s";
  tool = {};
  ASSERT_TRUE(ParseToolSpec("tweezers:mu_d=0.2,mu_s=0.5,k_t=100,b_t=0.1", &tool, &error)) << error;
  EXPECT_EQ(tool.kind, ToolKind::kTweezers);
  EXPECT_EQ(tool.mu_d, 0.2) << "a given mu_d is kept whatever the order";
  EXPECT_EQ(tool.friction_stiffness, 100);
  EXPECT_EQ(tool.friction_damping, 0.1);
  tool = {};
  ASSERT_TRUE(ParseToolSpec("sphere:", &tool, &error)) << error;
  EXPECT_EQ(tool.radius, 1.5);

  const std::pair<const char*, const char*> bad_tools[] = {
      {"scalpel:r=1", "--tool 'scalpel:r=1': expected sphere:... or tweezers:..."},
      {"sphere:r=-1", "bad item 'r=-1'"},
      {"sphere:r", "bad item 'r'"},
      {"sphere:k=1e999", "bad item 'k=1e999'"},
      {"sphere:law=stiff", "bad item 'law=stiff'"},
      {"sphere:mu_s=nan", "bad item 'mu_s=nan'"},
      {"sphere:r=1,,k=2", "bad item ''"},
      {"sphere:mu_s=0.3,mu_d=0.5", "--tool 'sphere:mu_s=0.3,mu_d=0.5': mu_d must be <= mu_s (0.3), got 0.5"},
      {"sphere:mu_s=-0.1", "mu_s must be a finite number >= 0, got -0.1"},
  };
  for (const auto& [spec, want] : bad_tools) {
    tool = {};
    error.clear();
    EXPECT_FALSE(ParseToolSpec(spec, &tool, &error)) << spec;
    EXPECT_NE(error.find(want), std::string::npos) << spec << ": " << error;
  }

  FrictionGiven given;
  tool = {};
  ASSERT_TRUE(ParseFrictionSpec("b_t=0.2,mu_s=0.5", &tool, &given, &error)) << error;
  EXPECT_TRUE(given.mu_s && given.b_t && !given.mu_d && !given.k_t);
  EXPECT_EQ(tool.mu_s, 0.5);
  EXPECT_EQ(tool.mu_d, 0.5);
  EXPECT_EQ(tool.friction_damping, 0.2);
  const std::pair<const char*, const char*> bad_specs[] = {
      {"", "bad item ''"},
      {"mu_d=0.1", "give mu_s=S"},
      {"mu_s=0.5,mu_s=0.4", "bad item 'mu_s=0.4'"},
      {"mu_s", "bad item 'mu_s'"},
      {"mu_s=0.5,r=1", "bad item 'r=1'"},
      {"mu_s=0.5x", "bad item 'mu_s=0.5x'"},
      {"mu_s=0.5,mu_d=0.6", "mu_d must be <= mu_s (0.5), got 0.6"},
      {"mu_s=0.5,k_t=-3", "k_t must be a finite number > 0"},
  };
  for (const auto& [spec, want] : bad_specs) {
    tool = {};
    error.clear();
    EXPECT_FALSE(ParseFrictionSpec(spec, &tool, &given, &error)) << spec;
    EXPECT_NE(error.find(want), std::string::npos) << spec << ": " << error;
  }
}

}  // namespace
}  // namespace idms
