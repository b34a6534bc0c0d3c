// Tests of Step: field forces, allocation-free and deterministic stepping, snapshot replay, local
// vs full simulation and the window's cost and settling, and the thesis's palpation (6.1.1).
#include "idms/sim/step.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "alloc_counter.h"
#include "idms/sim/edit.h"
#include "idms/sim/generate.h"
#include "idms/sim/workspace.h"
#include "step_test_util.h"
#include "warning_guard.h"

namespace idms {
namespace {

using test::FullOptions;
using test::HashState;
using test::SphereAt;

TEST(StepFieldForces, GravityAndAirOnlyWhenAsked) {
  const Model model = GenerateSlab(SlabOptions{});
  // Off by default: a slab at rest stays bit-for-bit at rest, even in full mode.
  {
    State s = MakeState(model);
    Workspace ws = MakeWorkspace(model, FullOptions(Integrator::kExplicitEuler, 1e-3));
    for (int i = 0; i < 100; ++i) Step(model, s, ws, ToolInput{});
    for (int32_t i = 0; i < 3 * model.num_atoms; ++i) ASSERT_EQ(s.atom_pos[i], model.atom_pos_eq[i]);
  }
  // Gravity: the free atoms sag; air resistance slows the fall.
  StepOptions o = FullOptions(Integrator::kSymplecticEuler, 1e-3);
  o.gravity = true;
  StepOptions o_air = o;
  o_air.air_damping = 50;
  State s = MakeState(model), s_air = MakeState(model);
  test::WarningGuard warnings(s, "gravity"), warnings_air(s_air, "gravity and air");
  Workspace ws = MakeWorkspace(model, o), ws_air = MakeWorkspace(model, o_air);
  for (int i = 0; i < 20; ++i) Step(model, s, ws, ToolInput{}), Step(model, s_air, ws_air, ToolInput{});
  EXPECT_LT(s_air.atom_pos[2], 0);
  EXPECT_LT(s.atom_pos[2], s_air.atom_pos[2]);  // top atom 0 falls faster without air
  for (int i = 0; i < 2000; ++i) Step(model, s, ws, ToolInput{});
  EXPECT_LT(s.atom_pos[2], -1e-5);
}

// A palpation followed by a stroke and a release: exercises contact, window changes, settling.
void RunScript(const Model& model, State& s, Workspace& ws, int ticks, int first_tick = 0) {
  for (int i = first_tick; i < first_tick + ticks; ++i) {
    const double t = i * 1e-3;
    const double z = t < 1 ? 2.0 - 1.8 * t : 0.2 + 1.0 * std::max(0.0, t - 1.6);
    const double x = t < 1 ? 1.5 : 1.5 + 1.5 * std::min(1.0, t - 1.0);
    Step(model, s, ws, SphereAt(x, 1.732, z));
  }
}

class StepDeterminism : public ::testing::TestWithParam<Integrator> {};

TEST_P(StepDeterminism, SameInputsSameBits) {
  const Model model = GenerateSlab(SlabOptions{});
  StepOptions o;
  o.integrator = GetParam();
  uint64_t hashes[2];
  for (uint64_t& h : hashes) {
    State s = MakeState(model);
    Workspace ws = MakeWorkspace(model, o);
    RunScript(model, s, ws, 2500);
    h = HashState(s);
  }
  EXPECT_EQ(hashes[0], hashes[1]);
}

// Implicit Euler is the documented exception: its CG warm start lives in the Workspace, so a
// replay from a snapshot starts its solves from another guess and agrees to the CG tolerance
// (relative residual 1e-8), not to the bit.
TEST(StepDeterminism, ImplicitReplayFromASnapshotAgreesToTheSolverTolerance) {
  const Model model = GenerateSlab(SlabOptions{});
  StepOptions o;
  o.integrator = Integrator::kImplicitEuler;
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, o);
  RunScript(model, s, ws, 1200);
  const State snapshot = s;
  RunScript(model, s, ws, 800, 1200);
  const State straight = s;
  s = snapshot;
  RunScript(model, s, ws, 800, 1200);
  double max_diff = 0;
  for (size_t i = 0; i < s.atom_pos.size(); ++i) {
    max_diff = std::max(max_diff, std::abs(static_cast<double>(s.atom_pos[i]) - straight.atom_pos[i]));
  }
  std::printf("implicit replay from a snapshot: max position difference %.3g\n", max_diff);
  EXPECT_LT(max_diff, 1e-9);
}

TEST_P(StepDeterminism, SnapshotReplayGivesSameBits) {
  if (GetParam() == Integrator::kImplicitEuler) GTEST_SKIP() << "CG warm start lives in the Workspace (tested above)";
  const Model model = GenerateSlab(SlabOptions{});
  StepOptions o;
  o.integrator = GetParam();
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, o);
  RunScript(model, s, ws, 1200);
  const State snapshot = s;  // a plain copy
  RunScript(model, s, ws, 800, 1200);
  const uint64_t straight = HashState(s);
  s = snapshot;  // rollback: the Workspace notices the tick and refiles its hash
  RunScript(model, s, ws, 800, 1200);
  // The hash covers every warning counter; the one expected difference is the resync.
  EXPECT_EQ(s.warnings.workspace_resync, 1);
  s.warnings.workspace_resync = 0;
  EXPECT_EQ(HashState(s), straight);
}

INSTANTIATE_TEST_SUITE_P(AllIntegrators, StepDeterminism,
                         ::testing::Values(Integrator::kExplicitEuler, Integrator::kSymplecticEuler, Integrator::kRk4,
                                           Integrator::kImplicitEuler),
                         [](const auto& param_info) { return std::string(IntegratorName(param_info.param)); });

struct AllocCase {
  Integrator integrator;
  bool full;
};

class StepAllocation : public ::testing::TestWithParam<AllocCase> {};

TEST_P(StepAllocation, StepAllocatesNothing) {
  const Model model = GenerateSlab(SlabOptions{});
  StepOptions o;
  o.integrator = GetParam().integrator;
  o.full = GetParam().full;
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, o);
  // One warm-up tick (the implicit buffers may grow once, counted as a warning).
  Step(model, s, ws, SphereAt(1.5, 1.732, 1.0));
  const int64_t before = test::AllocationCount();
  RunScript(model, s, ws, 2500, 1);
  EXPECT_EQ(test::AllocationCount() - before, 0);
  EXPECT_EQ(s.warnings.implicit_grew, 0);
}

INSTANTIATE_TEST_SUITE_P(
    Integrators, StepAllocation,
    ::testing::Values(AllocCase{Integrator::kExplicitEuler, false}, AllocCase{Integrator::kExplicitEuler, true},
                      AllocCase{Integrator::kSymplecticEuler, false}, AllocCase{Integrator::kRk4, false},
                      AllocCase{Integrator::kRk4, true}, AllocCase{Integrator::kImplicitEuler, false},
                      AllocCase{Integrator::kImplicitEuler, true}),
    [](const auto& param_info) {
      return std::string(IntegratorName(param_info.param.integrator)) + (param_info.param.full ? "_full" : "_local");
    });

TEST(StepAllocation, ToolsAndEditsAllocateNothing) {
  const Model base = GenerateSlab(SlabOptions{});
  Model model = base;
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, StepOptions{});
  ToolInput in;
  in.num_tools = 2;
  in.tools[0].kind = ToolKind::kTweezers;
  in.tools[1].kind = ToolKind::kScalpel;
  in.tools[1].blade[2] = -1.0;
  auto set = [&](int i) {
    const double t = i * 1e-3;
    in.tools[0].pos[0] = 1.5, in.tools[0].pos[1] = 1.732, in.tools[0].pos[2] = std::max(1.2, 2.0 - t);
    in.tools[0].closed = t > 1.0 && t < 1.8;
    in.tools[1].pos[0] = 3.0, in.tools[1].pos[1] = -1.0 + 3.0 * t, in.tools[1].pos[2] = 0.5;
  };
  set(0);
  Step(model, s, ws, in);
  const int64_t before = test::AllocationCount();
  int32_t removed = 0;
  for (int i = 1; i < 2000; ++i) {
    set(i);
    Step(model, s, ws, in);
    removed += ApplyPendingEdits(model, s, ws).elements_removed;
  }
  EXPECT_EQ(test::AllocationCount() - before, 0);
  EXPECT_GT(removed, 0);
}

TEST(StepLocal, HugeLocalRadiusEqualsFullBitForBit) {
  const Model model = GenerateSlab(SlabOptions{});
  StepOptions local;
  local.local_radius = 100;
  StepOptions full = local;
  full.full = true;
  State a = MakeState(model), b = MakeState(model);
  Workspace wa = MakeWorkspace(model, local), wb = MakeWorkspace(model, full);
  RunScript(model, a, wa, 2000);
  RunScript(model, b, wb, 2000);
  EXPECT_EQ(HashState(a), HashState(b));
}

TEST(StepLocal, WindowCostDoesNotGrowWithTheModel) {
  // The same press on an interior point of a small and a ~40x larger slab: the same active set.
  SlabOptions small;
  small.rows = 21, small.cols = 20;
  SlabOptions large;
  large.rows = 121, large.cols = 120;
  const Model ms = GenerateSlab(small), ml = GenerateSlab(large);
  ASSERT_GT(ml.num_atoms, 30 * ms.num_atoms);
  State ss = MakeState(ms), sl = MakeState(ml);
  Workspace ws = MakeWorkspace(ms, StepOptions{}), wl = MakeWorkspace(ml, StepOptions{});
  for (int i = 0; i < 1500; ++i) {
    const double z = 2.0 - 1.5 * i * 1e-3;
    const StepReport rs = Step(ms, ss, ws, SphereAt(10.0, 10 * 0.866, z));
    const StepReport rl = Step(ml, sl, wl, SphereAt(10.0, 10 * 0.866, z));
    ASSERT_EQ(rs.active_atoms, rl.active_atoms) << "tick " << i;
    ASSERT_EQ(rs.active_elems, rl.active_elems) << "tick " << i;
    ASSERT_NEAR(rs.tools[0].force[2], rl.tools[0].force[2], 1e-9) << "tick " << i;
  }
}

TEST(StepLocal, SettlingReleasesTheDentThesisModeFreezesIt) {
  const Model model = GenerateSlab(SlabOptions{});
  for (const double settle : {0.0, 0.3}) {
    StepOptions o;
    o.settle_time_s = settle;
    State s = MakeState(model);
    Workspace ws = MakeWorkspace(model, o);
    // Press, then jump the tool far away.
    for (int i = 0; i < 500; ++i) Step(model, s, ws, SphereAt(1.5, 1.732, 2.0 - 2.0 * i / 500.0));
    for (int i = 0; i < 1000; ++i) Step(model, s, ws, SphereAt(1.5, 1.732, 10.0));
    double dent = 0;
    for (int32_t a = 0; a < model.num_atoms; ++a)
      dent = std::max(dent, std::fabs(s.atom_pos[3 * a + 2] - model.atom_pos_eq[3 * a + 2]));
    if (settle == 0) {
      EXPECT_GT(dent, 0.05) << "thesis mode immobilises the atoms where the window left them";
    } else {
      EXPECT_LT(dent, 0.01);
    }
    EXPECT_EQ(s.num_active, 0);
  }
}

TEST(StepReport, StageTimesAddUp) {
  const Model model = GenerateSlab(SlabOptions{});
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, StepOptions{});
  const StepReport r = Step(model, s, ws, SphereAt(1.5, 1.732, 1.2));
  for (int64_t ns : {r.tools_ns, r.active_set_ns, r.forces_ns, r.integrate_ns, r.checks_ns}) EXPECT_GE(ns, 0);
  EXPECT_LE(r.tools_ns + r.active_set_ns + r.forces_ns + r.integrate_ns + r.checks_ns, r.total_ns);
  EXPECT_GT(r.active_atoms, 0);
  EXPECT_GT(r.tools[0].contacts, 0);
  EXPECT_EQ(r.attempts, 1);
}

TEST(StepTools, SeveralSpheresEachFeelTheirOwnForce) {
  SlabOptions so;
  so.rows = 9, so.cols = 12;
  const Model model = GenerateSlab(so);
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, StepOptions{});
  ToolInput in = SphereAt(2.5, 1.732, 1.3);
  in.num_tools = 2;
  in.tools[1] = in.tools[0];
  in.tools[1].pos[0] = 9.5;
  in.tools[1].pos[2] = 5.0;  // out of reach
  StepReport r;
  for (int i = 0; i < 300; ++i) r = Step(model, s, ws, in);
  EXPECT_GT(r.tools[0].force[2], 0.5);
  EXPECT_EQ(r.tools[1].force[2], 0);
  in.tools[1].pos[2] = 1.3;  // both press the same way on equivalent spots
  for (int i = 0; i < 1000; ++i) r = Step(model, s, ws, in);
  EXPECT_NEAR(r.tools[1].force[2], r.tools[0].force[2], 0.05 * r.tools[0].force[2]);
}

// Thesis 6.1.1 / fig. 6-2 on the hex fragment (GenerateSlab defaults: k 15, b 0.2, m 0.002)
// with the thesis's MIO (r 1.5, k 400, thesis law) and window (r_l 2.25): the tool comes down
// over the middle atom of the fragment from z = 2 to z = -0.3 in 2 s and holds.
struct PalpationResult {
  double onset_z = 0;   // first tick with f_z > 1e-3
  double z_at_1_7 = 0;  // first tick with f_z >= 1.7 N (the thesis's peak)
  double peak_fz = 0, peak_z = 0, max_fx = 0, max_fy = 0, final_fz = 0;
};

PalpationResult Palpate(Integrator integrator, double x, double y) {
  const Model model = GenerateSlab(SlabOptions{});
  StepOptions o;
  o.integrator = integrator;
  o.local_radius = 2.25;
  o.max_device_force = 1e6;  // measure the model, not the device limits
  o.max_device_force_rate = 1e9;
  State s = MakeState(model);
  test::WarningGuard warnings(s, std::string("palpation, ") + IntegratorName(integrator));
  Workspace ws = MakeWorkspace(model, o);
  PalpationResult out;
  out.onset_z = out.z_at_1_7 = std::nan("");
  for (int i = 0; i <= 2500; ++i) {
    const double z = 2.0 - 2.3 * std::min(i, 2000) / 2000.0;
    const StepReport r = Step(model, s, ws, SphereAt(x, y, z));
    const double fz = r.tools[0].force[2];
    if (std::isnan(out.onset_z) && fz > 1e-3) out.onset_z = z;
    if (std::isnan(out.z_at_1_7) && fz >= 1.7) out.z_at_1_7 = z;
    if (fz > out.peak_fz) out.peak_fz = fz, out.peak_z = z;
    out.max_fx = std::max(out.max_fx, std::fabs(r.tools[0].force[0]));
    out.max_fy = std::max(out.max_fy, std::fabs(r.tools[0].force[1]));
    out.final_fz = fz;
  }
  return out;
}

TEST(StepPalpation, ThesisFigure62OnTheHexFragment) {
  double hold_reference = NAN;
  for (Integrator integrator :
       {Integrator::kExplicitEuler, Integrator::kSymplecticEuler, Integrator::kRk4, Integrator::kImplicitEuler}) {
    SCOPED_TRACE(IntegratorName(integrator));
    const PalpationResult p = Palpate(integrator, 2.5, 2 * 0.866);  // over top atom 11
    std::printf("palpation %-10s onset z %.3f, f_z = 1.7 N at z %.3f, peak f_z %.1f N at z %.3f, hold %.1f N\n",
                IntegratorName(integrator), p.onset_z, p.z_at_1_7, p.peak_fz, p.peak_z, p.final_fz);
    // Onset where the sphere first reaches the atom: z = r = 1.5 (thesis: "at approximately 1.5").
    EXPECT_NEAR(p.onset_z, 1.5, 0.01);
    // The thesis's peak of 1.7 N is reached a few hundredths below onset on this fragment ...
    EXPECT_GT(p.z_at_1_7, 1.4);
    EXPECT_LT(p.z_at_1_7, 1.49);
    // ... and pressing on to z = -0.3 (1.8 units deep) gives tens of newtons: the home
    // elements (k = 15 each) of several atoms pushed down ~1.5 units. Held there, the tissue comes
    // to rest, and the static force does not depend on how it was integrated: every integrator
    // ends at explicit Euler's hold force, to 0.1%, and none peaks more than 5% above it.
    if (std::isnan(hold_reference)) hold_reference = p.final_fz;
    EXPECT_GT(p.final_fz, 30);
    EXPECT_NEAR(p.final_fz, hold_reference, 1e-3 * hold_reference);
    EXPECT_GE(p.peak_fz, p.final_fz);
    EXPECT_LT(p.peak_fz, 1.05 * hold_reference);
    // f_x, f_y small next to f_z (the atom is off the fragment's centre, so not zero).
    EXPECT_LT(std::max(p.max_fx, p.max_fy), 0.1 * p.peak_fz);
  }
  // Between atoms the sphere meets two atoms half a spacing away: onset at sqrt(1.5^2 - 0.5^2).
  const PalpationResult mid = Palpate(Integrator::kExplicitEuler, 2.0, 2 * 0.866);
  std::printf(
      "palpation mid-fragment onset z %.3f, f_z = 1.7 N at z %.3f, peak f_z %.1f N, max |f_x| %.2g |f_y| %.2g N\n",
      mid.onset_z, mid.z_at_1_7, mid.peak_fz, mid.max_fx, mid.max_fy);
  EXPECT_NEAR(mid.onset_z, std::sqrt(1.5 * 1.5 - 0.25), 0.01);
  // On the fragment's centre f_x vanishes by symmetry; f_y stays small (the lower layer of the
  // fragment is not symmetric in y: apexes sit under the downward triangles only).
  EXPECT_LT(mid.max_fx, 1e-6 * mid.peak_fz);
  EXPECT_LT(mid.max_fy, 0.1 * mid.peak_fz);
}

}  // namespace
}  // namespace idms
