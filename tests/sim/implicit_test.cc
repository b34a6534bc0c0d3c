// Tests of linearised backward Euler (sim/src/implicit.cc): one spring against the closed-form
// backward-Euler update, the energy it takes out, the assembled system (symmetric, solved to the
// CG tolerance), the CG iteration limit, and the buffers (sized once, grown only past them).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "alloc_counter.h"
#include "idms/sim/generate.h"
#include "idms/sim/model.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"
#include "step_test_util.h"
#include "warning_guard.h"

namespace idms {
namespace {

using internal::ImplicitEulerSubstep;

// The spring's axis, not a coordinate axis, so that the 3x3 system has off-diagonal terms.
constexpr double kAxis[3] = {1.0 / 3, 2.0 / 3, 2.0 / 3};

// Atom 0 fixed at the origin, atom 1 free at l_eq = 1 along kAxis.
Model ObliqueSpring(double k, double b, double mass) {
  return test::TwoAtomModel({.name = "oblique", .end = {kAxis[0], kAxis[1], kAxis[2]}, .external = {0, 0}}, k, b, mass);
}

StepOptions ImplicitOptions(double T, bool full = true) {
  StepOptions o = test::FullOptions(Integrator::kImplicitEuler, T);
  o.full = full;
  o.stability.cg_tolerance = 1e-14;
  return o;
}

// Backward Euler for m u'' = -k (u - l_eq) - b u' along the axis, exactly:
//   (m + T b + T^2 k) w' = m w - T k (u - l_eq),  u' = u + T w'.
// Linearised backward Euler is exact for a linear force, and along its axis the spring's
// stiffness block is k whatever the geometric term, so the step must reproduce this.
struct Axial {
  double u, w;
};
Axial BackwardEuler(Axial x, double k, double b, double m, double T) {
  const double w = (m * x.w - T * k * (x.u - 1.0)) / (m + T * b + T * T * k);
  return {x.u + T * w, w};
}

// Atom 1's position and velocity along kAxis, and the largest component across it.
Axial Along(const State& s, double* across) {
  Axial x{0, 0};
  for (int c = 0; c < 3; ++c) x.u += s.atom_pos[3 + c] * kAxis[c], x.w += s.atom_vel[3 + c] * kAxis[c];
  *across = 0;
  for (int c = 0; c < 3; ++c) {
    *across = std::max(*across, std::fabs(s.atom_pos[3 + c] - x.u * kAxis[c]));
    *across = std::max(*across, std::fabs(s.atom_vel[3 + c] - x.w * kAxis[c]));
  }
  return x;
}

void Place(State& s, Axial x) {
  for (int c = 0; c < 3; ++c) s.atom_pos[3 + c] = x.u * kAxis[c], s.atom_vel[3 + c] = x.w * kAxis[c];
}

// omega T = sqrt(k / m) T = 3.2: explicit Euler's limit is 2, so this is the implicit regime.
TEST(Implicit, OneSpringIsTheClosedFormBackwardEulerUpdate) {
  const double k = 1e4, b = 0.5, m = 1e-3, T = 1e-3;
  const Model model = ObliqueSpring(k, b, m);
  for (Axial start : {Axial{1.2, 0.3}, Axial{0.7, -2.0}}) {  // stretched and compressed
    SCOPED_TRACE(start.u);
    State s = MakeState(model);
    test::WarningGuard warnings(s);
    Place(s, start);
    Workspace ws = MakeWorkspace(model, ImplicitOptions(T));
    internal::BuildActiveSet(model, s, ws);
    internal::StageTimes times;
    const int32_t iterations = ImplicitEulerSubstep(model, s, ws, Real(T), &times);
    EXPECT_GE(iterations, 1);
    EXPECT_LE(iterations, 3) << "CG on 3 unknowns";
    const Axial expected = BackwardEuler(start, k, b, m, T);
    double across = 0;
    const Axial got = Along(s, &across);
    EXPECT_NEAR(got.w, expected.w, 1e-11 * std::fabs(expected.w));
    EXPECT_NEAR(got.u, expected.u, 1e-12);
    EXPECT_LT(across, 1e-10) << "the motion stays on the axis";
  }
}

// Over many substeps, the trajectory is the backward-Euler recurrence's, and the energy falls at
// every one of them, damped or not: backward Euler's own dissipation (m |dv|^2 + k |dx|^2) / 2.
TEST(Implicit, TrajectoryFollowsTheRecurrenceAndEnergyFallsEverySubstep) {
  // omega T = 1.6: the energy falls ~3.5-fold a substep, so 20 substeps stay above rounding.
  const double k = 1e4, m = 1e-3, T = 5e-4;
  for (double b : {0.0, 0.5}) {
    SCOPED_TRACE(b);
    const Model model = ObliqueSpring(k, b, m);
    State s = MakeState(model);
    test::WarningGuard warnings(s);
    Axial expected{1.2, 0.0};
    Place(s, expected);
    Workspace ws = MakeWorkspace(model, ImplicitOptions(T));
    internal::BuildActiveSet(model, s, ws);
    internal::StageTimes times;
    double energy = ModelEnergy(model, s, ws);
    ASSERT_NEAR(energy, 0.5 * k * 0.2 * 0.2, 1e-9);
    for (int n = 0; n < 20; ++n) {
      ImplicitEulerSubstep(model, s, ws, Real(T), &times);
      expected = BackwardEuler(expected, k, b, m, T);
      double across = 0;
      const Axial got = Along(s, &across);
      ASSERT_NEAR(got.u, expected.u, 1e-11) << "substep " << n;
      ASSERT_NEAR(got.w, expected.w, 1e-9 * (1 + std::fabs(expected.w))) << "substep " << n;
      ASSERT_LT(across, 1e-10) << "substep " << n;
      const double next = ModelEnergy(model, s, ws);
      ASSERT_LT(next, energy) << "substep " << n;
      energy = next;
    }
    EXPECT_LT(energy, 1e-6 * 0.5 * k * 0.2 * 0.2) << "backward Euler damps even the undamped spring";
  }
}

// The hex slab, pressed and set moving: the assembled matrix is symmetric with a positive
// diagonal (CG needs SPD), and the solution meets the CG tolerance on its own residual.
struct Pressed {
  Model model = GenerateSlab(SlabOptions{});
  State state = MakeState(model);
  Workspace ws;
  explicit Pressed(const StepOptions& o) {
    ws = MakeWorkspace(model, o);
    for (int32_t a = 0; a < model.num_atoms; ++a) {
      if (model.atom_fixed[a]) continue;
      for (int c = 0; c < 3; ++c) {
        state.atom_pos[3 * a + c] += Real(0.02 * std::sin(1.0 + 3 * a + c));
        state.atom_vel[3 * a + c] = Real(0.5 * std::cos(2.0 + 5 * a + c));
      }
    }
    ResyncWorkspace(model, state, ws);
    StepReport report;
    internal::ResolveTools(model, state, ws, test::SphereAt(2.5, 1.732, 1.2), &report);  // top atom 11 in
    internal::BuildActiveSet(model, state, ws);
  }
};

TEST(Implicit, TheSystemIsSymmetricAndSolvedToTheTolerance) {
  StepOptions o = ImplicitOptions(5e-3);
  o.stability.cg_tolerance = 1e-10;
  Pressed p(o);
  test::WarningGuard warnings(p.state);
  internal::StageTimes times;
  const int32_t iterations = ImplicitEulerSubstep(p.model, p.state, p.ws, Real(5e-3), &times);
  EXPECT_GT(iterations, 1);
  EXPECT_LT(iterations, o.stability.cg_max_iterations);
  const ImplicitBuffers& ib = p.ws.implicit;
  const int32_t rows = 3 * p.ws.num_active;
  ASSERT_EQ(rows, 3 * 36) << "every free atom of the slab";
  std::vector<double> dense(static_cast<size_t>(rows) * rows, 0.0);
  for (int32_t r = 0; r < rows; ++r) {
    for (int32_t j = ib.outer[r]; j < ib.outer[r + 1]; ++j)
      dense[static_cast<size_t>(r) * rows + ib.inner[j]] += ib.values[j];
  }
  double residual2 = 0, rhs2 = 0;
  for (int32_t r = 0; r < rows; ++r) {
    EXPECT_GT(dense[static_cast<size_t>(r) * rows + r], 0) << "row " << r;
    double row = 0;
    for (int32_t c = 0; c < rows; ++c) {
      EXPECT_EQ(dense[static_cast<size_t>(r) * rows + c], dense[static_cast<size_t>(c) * rows + r])
          << "A(" << r << ", " << c << ")";
      row += dense[static_cast<size_t>(r) * rows + c] * ib.dv[c];
    }
    residual2 += (row - ib.rhs[r]) * (row - ib.rhs[r]);
    rhs2 += double(ib.rhs[r]) * ib.rhs[r];
  }
  ASSERT_GT(rhs2, 0);
  EXPECT_LE(std::sqrt(residual2), 1.5e-10 * std::sqrt(rhs2));
  // The update is v += dv, x += T v: the velocity change is the solution, slot by slot.
  Pressed before(o);
  for (int32_t i = 0; i < p.ws.num_active; ++i) {
    const int32_t a = p.ws.active[i];
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(p.state.atom_vel[3 * a + c], before.state.atom_vel[3 * a + c] + ib.dv[3 * i + c]);
      EXPECT_EQ(p.state.atom_pos[3 * a + c],
                before.state.atom_pos[3 * a + c] + Real(5e-3) * p.state.atom_vel[3 * a + c]);
    }
  }
}

TEST(Implicit, CgStoppedAtItsLimitIsAWarning) {
  StepOptions o = ImplicitOptions(5e-3);
  o.stability.cg_max_iterations = 1;
  Pressed p(o);
  test::WarningGuard warnings(p.state);
  warnings.Expect(&WarningCounters::cg_not_converged, 1);
  internal::StageTimes times;
  EXPECT_EQ(ImplicitEulerSubstep(p.model, p.state, p.ws, Real(5e-3), &times), 1);
  EXPECT_EQ(p.state.warnings.cg_not_converged, 1);
}

// Full mode: the whole free system fits the buffers MakeWorkspace sized, so a substep neither
// grows them nor allocates.
TEST(Implicit, FullModeBuffersHoldTheWholeSystem) {
  Pressed p(ImplicitOptions(5e-3));
  test::WarningGuard warnings(p.state);  // no implicit_grew
  const size_t values = p.ws.implicit.values.size(), rhs = p.ws.implicit.rhs.size();
  EXPECT_EQ(rhs, 3u * 36);
  EXPECT_EQ(p.ws.implicit.atom_dv_guess.size(), 3u * p.model.num_atoms);
  internal::StageTimes times;
  const int64_t before = test::AllocationCount();
  ImplicitEulerSubstep(p.model, p.state, p.ws, Real(5e-3), &times);
  EXPECT_EQ(test::AllocationCount() - before, 0);
  EXPECT_LE(p.ws.implicit.outer[3 * p.ws.num_active], static_cast<int32_t>(values));
  EXPECT_EQ(p.ws.implicit.values.size(), values);
  // SizeImplicitBuffers again (what MakeWorkspace calls) gives the same sizes and a cold start.
  internal::SizeImplicitBuffers(p.model, p.ws);
  EXPECT_EQ(p.ws.implicit.values.size(), values);
  EXPECT_EQ(p.ws.implicit.rhs.size(), rhs);
  for (Real g : p.ws.implicit.atom_dv_guess) ASSERT_EQ(g, 0);
}

// Local mode sizes a window; an active system past it grows the buffers (counted) and is solved
// exactly as one that fitted.
TEST(Implicit, ASystemPastTheBuffersGrowsThemAndIsSolvedTheSame) {
  StepOptions o = ImplicitOptions(5e-3, /*full=*/false);
  o.local_radius = 2.25;
  Pressed fits(o), grows(o);
  ASSERT_GT(fits.ws.num_active, 1);
  grows.ws.implicit.rhs.resize(3);  // room for one atom
  test::WarningGuard fits_warnings(fits.state), grows_warnings(grows.state);
  grows_warnings.Expect(&WarningCounters::implicit_grew, 1);
  internal::StageTimes times;
  ImplicitEulerSubstep(fits.model, fits.state, fits.ws, Real(5e-3), &times);
  ImplicitEulerSubstep(grows.model, grows.state, grows.ws, Real(5e-3), &times);
  EXPECT_EQ(grows.state.warnings.implicit_grew, 1);
  EXPECT_EQ(fits.state.atom_pos, grows.state.atom_pos);
  EXPECT_EQ(fits.state.atom_vel, grows.state.atom_vel);
}

}  // namespace
}  // namespace idms
