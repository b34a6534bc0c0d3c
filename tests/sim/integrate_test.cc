// Tests of the integrators against hand computation: explicit Euler exactly as eqs. 4.13-4.15
// with the eq. 4.6 filter, symplectic Euler's order of updates, RK4's accuracy, and implicit
// Euler's stability far past the explicit limit.
#include <gtest/gtest.h>

#include <cmath>

#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "step_test_util.h"
#include "warning_guard.h"

namespace idms {
namespace {

using test::FullOptions;
using test::OneSpring;

TEST(IntegrateExplicitEuler, MatchesEquations413To415ByHand) {
  const double k = 15, b = 0.2, m = 0.002, T = 1e-4;
  const Model model = OneSpring(k, b, m);
  State s = MakeState(model);
  test::WarningGuard warnings(s);
  s.atom_pos[3] = 1.1;  // stretched by 0.1
  s.atom_vel[3] = 0.5;
  SyncFilterToPositions(model, s);
  StepOptions o = FullOptions(Integrator::kExplicitEuler, T);
  o.stability.predict = false;
  Workspace ws = MakeWorkspace(model, o);
  const ToolInput none;

  // Tick 1: the filter starts at l = 1.1, so the rate (eq. 4.6, lambda = 1) is 0.
  Step(model, s, ws, none);
  const double a0 = -k * 0.1 / m;
  EXPECT_DOUBLE_EQ(s.atom_pos[3], 1.1 + T * 0.5);  // eq. 4.13 with x1' = v(n) (4.10)
  EXPECT_DOUBLE_EQ(s.atom_vel[3], 0.5 + T * a0);   // eq. 4.14
  // Tick 2: rate = (l_n - l_{n-1}) / T = v(n-1).
  const double x1 = s.atom_pos[3], v1 = s.atom_vel[3];
  Step(model, s, ws, none);
  const double rate = (x1 - 1.1) / T;
  EXPECT_NEAR(s.elem_rate[0], rate, 1e-9);
  EXPECT_DOUBLE_EQ(s.atom_pos[3], x1 + T * v1);
  EXPECT_NEAR(s.atom_vel[3], v1 + T * (-k * (x1 - 1.0) - b * rate) / m, 1e-9);
}

TEST(IntegrateExplicitEuler, FilterLambdaBlendsRates) {
  const double T = 1e-4, lambda = 0.25;
  const Model model = OneSpring(15, 0.2, 0.002);
  State s = MakeState(model);
  s.atom_vel[3] = 1.0;
  StepOptions o = FullOptions(Integrator::kExplicitEuler, T);
  o.lambda = lambda;
  Workspace ws = MakeWorkspace(model, o);
  Step(model, s, ws, ToolInput{});
  EXPECT_EQ(s.elem_rate[0], 0);  // l did not change yet
  const double l1 = s.atom_pos[3];
  Step(model, s, ws, ToolInput{});
  const double r2 = lambda * (l1 - 1.0) / T;
  EXPECT_NEAR(s.elem_rate[0], r2, 1e-9);
  const double l2 = s.atom_pos[3];
  Step(model, s, ws, ToolInput{});
  EXPECT_NEAR(s.elem_rate[0], lambda * (l2 - l1) / T + (1 - lambda) * r2, 1e-9);
}

TEST(IntegrateSymplecticEuler, UpdatesVelocityThenPosition) {
  const double k = 15, m = 0.002, T = 1e-4;
  const Model model = OneSpring(k, 0, m);
  State s = MakeState(model);
  s.atom_pos[3] = 1.1;
  SyncFilterToPositions(model, s);
  Workspace ws = MakeWorkspace(model, FullOptions(Integrator::kSymplecticEuler, T));
  Step(model, s, ws, ToolInput{});
  const double v1 = T * (-k * 0.1 / m);
  EXPECT_DOUBLE_EQ(s.atom_vel[3], v1);
  EXPECT_DOUBLE_EQ(s.atom_pos[3], 1.1 + T * v1);
}

TEST(IntegrateRk4, HarmonicOscillatorMatchesAnalytic) {
  const double k = 15, m = 0.002, T = 1e-3, x0 = 0.1;
  const Model model = OneSpring(k, 0, m);
  State s = MakeState(model);
  test::WarningGuard warnings(s);
  s.atom_pos[3] = 1.0 + x0;
  Workspace ws = MakeWorkspace(model, FullOptions(Integrator::kRk4, T));
  for (int i = 0; i < 1000; ++i) Step(model, s, ws, ToolInput{});
  const double w = std::sqrt(k / m);
  // RK4's global error is O((wT)^4) per unit phase: (0.087)^4 * w * t ~ 5e-3 relative.
  EXPECT_NEAR(s.atom_pos[3] - 1.0, x0 * std::cos(w * 1.0), 1e-3 * x0);
  EXPECT_NEAR(s.atom_vel[3], -x0 * w * std::sin(w * 1.0), 1e-2 * x0 * w);
}

TEST(IntegrateImplicitEuler, StableAndDissipativeFarBeyondTheExplicitLimit) {
  const double k = 1e6, m = 1e-6, T = 5e-3;  // omega T = 5e3
  const Model model = OneSpring(k, 0.2, m);
  State s = MakeState(model);
  test::WarningGuard warnings(s);
  s.atom_pos[3] = 1.5;
  SyncFilterToPositions(model, s);
  Workspace ws = MakeWorkspace(model, FullOptions(Integrator::kImplicitEuler, T));
  double energy = ModelEnergy(model, s, ws);
  for (int i = 0; i < 50; ++i) {
    const StepReport r = Step(model, s, ws, ToolInput{});
    const double next = ModelEnergy(model, s, ws);
    ASSERT_TRUE(std::isfinite(next));
    EXPECT_LE(next, energy * (1 + 1e-9));
    EXPECT_EQ(r.integrator_used, Integrator::kImplicitEuler);
    energy = next;
  }
  EXPECT_NEAR(s.atom_pos[3], 1.0, 1e-6);
}

}  // namespace
}  // namespace idms
