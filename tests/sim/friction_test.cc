// Friction with stiction (sim/src/friction.cc, issue 30): a finger held sideways below mu_s f_n
// does not creep, above it slides at mu_d f_n, no chattering, passivity, prediction, determinism,
// the tweezers, and bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
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

Model Hex() {
  Model model;
  LoadError error;
  const std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";
  EXPECT_TRUE(LoadModel(prefix + ".fem", prefix + ".plg", {}, &model, &error)) << error.ToString();
  return model;
}

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
