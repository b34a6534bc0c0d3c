// Tests of full mode's fused pass (full_step.cc): the same bits as the general path over many
// ticks in every configuration it takes (integrators, rate modes, field forces, tools, substeps,
// edits, a switch from local mode, the energy check on), the same repair and fallback on
// non-finite values and on a divergence the energy check catches, and no allocation.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "alloc_counter.h"
#include "idms/sim/edit.h"
#include "idms/sim/generate.h"
#include "idms/sim/model.h"
#include "idms/sim/reorder.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"
#include "step_test_util.h"

namespace idms {
namespace {

using test::HashState;

Model Slab(double b = 0.2) {
  SlabOptions so;
  so.rows = 9, so.cols = 10;
  so.b = so.home_b = b;
  return GenerateSlab(so);
}

// A deformed start, so every element carries force from the first tick.
State Deformed(const Model& model) {
  State s = MakeState(model);
  for (int32_t a = 0; a < model.num_atoms; ++a) {
    if (!model.atom_fixed[a]) s.atom_pos[3 * a + 2] += static_cast<Real>(0.05 * std::sin(0.37 * a));
  }
  return s;
}

StepOptions FullNoCheck(Integrator integrator) {
  StepOptions o;
  o.full = true;
  o.integrator = integrator;
  o.stability.energy_check = false;
  return o;
}

// A sphere pressing down over the slab's middle, then a tweezers grasp that lifts and lets go.
ToolInput Tools(int tick) {
  const double t = tick * 1e-3;
  ToolInput in = test::SphereAt(4.5, 3.5, 1.8 - 0.6 * std::min(t, 0.5));
  in.num_tools = 2;
  ToolCommand& tw = in.tools[1];
  tw.kind = ToolKind::kTweezers;
  tw.pos[0] = 2.0, tw.pos[1] = 1.732, tw.pos[2] = t < 0.15 ? 1.6 - t : 1.45 + 0.5 * (t - 0.15);
  tw.closed = t > 0.12 && t < 0.3;
  return in;
}

struct Run {
  uint64_t hash = 0;
  int64_t warnings = 0;
  double force_bits = 0;    // sum of device forces, compared exactly
  int64_t fused_ticks = 0;  // StepReport::fused
  int64_t rollbacks = 0, fallbacks = 0, unrecovered = 0;
  int64_t retried = 0;         // ticks whose first attempt was not accepted
  double max_energy_diff = 0;  // the largest |energy_before - general's| relative to its scale, per tick
};

// Steps the same model and start three times: the general path, the fused pass, and the fused
// pass without its AVX2 code (the baseline x86-64 code, whatever this machine has). Returns the
// general run and the fused one, after checking that both fused runs agree.
std::pair<Run, Run> RunBoth(const Model& model, const State& start, const StepOptions& o, int ticks, bool tools,
                            const std::vector<Real>& external = {}) {
  Run runs[3];
  std::vector<double> general_energy;
  for (int fused = 0; fused < 3; ++fused) {
    State s = start;
    Workspace ws = MakeWorkspace(model, o);
    ws.options.fused_pass = fused > 0;
    ws.options.fused_avx2 = fused == 1;
    ws.atom_force_external = external;
    for (int i = 0; i < ticks; ++i) {
      const StepReport r = Step(model, s, ws, tools ? Tools(i) : ToolInput{});
      for (int t = 0; t < r.num_tools; ++t)
        runs[fused].force_bits += r.tools[t].force[0] + r.tools[t].force[1] + r.tools[t].force[2];
      runs[fused].fused_ticks += r.fused;
      runs[fused].fallbacks += r.fallback;
      runs[fused].unrecovered += r.unrecovered;
      runs[fused].retried += r.attempts != 1 || r.unrecovered;
      if (fused == 0) {
        general_energy.push_back(r.energy_before);
      } else if (std::isfinite(r.energy_before) && std::isfinite(general_energy[i])) {
        const double diff = std::fabs(r.energy_before - general_energy[i]) / (std::fabs(general_energy[i]) + 1e-12);
        runs[fused].max_energy_diff = std::max(runs[fused].max_energy_diff, diff);
      }
    }
    runs[fused].hash = HashState(s);
    runs[fused].warnings = TotalWarnings(s.warnings);
    runs[fused].rollbacks = s.warnings.rollback;
  }
  EXPECT_EQ(runs[2].hash, runs[1].hash) << "the baseline and the AVX2 code differ";
  EXPECT_EQ(runs[2].force_bits, runs[1].force_bits);
  return {runs[0], runs[1]};
}

struct Case {
  std::string name;
  Integrator integrator;
  double b;
  LengthRate rate;
  double lambda;
  bool predict;
  bool field;
  bool tools;
  bool check = false;  // the energy check on (formed in the pass)
};

class FusedEqualsGeneral : public ::testing::TestWithParam<Case> {};

TEST_P(FusedEqualsGeneral, SameBitsOverManyTicks) {
  const Case& c = GetParam();
  const Model model = Slab(c.b);
  StepOptions o = FullNoCheck(c.integrator);
  o.length_rate = c.rate;
  o.lambda = c.lambda;
  o.stability.predict = c.predict;
  o.stability.energy_check = c.check;
  if (c.field) o.gravity = true, o.air_damping = 3;
  const auto [general, fused] = RunBoth(model, Deformed(model), o, 400, c.tools);
  EXPECT_EQ(fused.hash, general.hash);
  EXPECT_EQ(fused.warnings, general.warnings);
  EXPECT_EQ(fused.force_bits, general.force_bits);
  // The deformed start's first tick fails the energy check (both paths roll it back alike).
  if (!c.check) {
    EXPECT_EQ(general.warnings, 0);
  }
  EXPECT_EQ(fused.fused_ticks, 400 - general.retried) << "a tick left the fused pass";
  EXPECT_LE(general.retried, 1);
  EXPECT_EQ(general.fused_ticks, 0);
  // The energies the pass forms are ActiveEnergy's, up to the order of the sums.
  if (c.check) {
    EXPECT_LT(fused.max_energy_diff, sizeof(Real) == 4 ? 1e-4 : 1e-12);
  }
}

INSTANTIATE_TEST_SUITE_P(
    Configurations, FusedEqualsGeneral,
    ::testing::Values(
        Case{"euler_filtered", Integrator::kExplicitEuler, 0.2, LengthRate::kAuto, 1.0, true, false, false},
        Case{"symplectic_filtered", Integrator::kSymplecticEuler, 0.2, LengthRate::kAuto, 1.0, false, false, false},
        Case{"symplectic_lambda", Integrator::kSymplecticEuler, 0.2, LengthRate::kFiltered, 0.5, true, false, false},
        Case{"euler_analytic", Integrator::kExplicitEuler, 0.2, LengthRate::kAnalytic, 1.0, true, false, false},
        Case{"symplectic_undamped", Integrator::kSymplecticEuler, 0.0, LengthRate::kAuto, 1.0, true, false, false},
        Case{"symplectic_field", Integrator::kSymplecticEuler, 0.2, LengthRate::kAuto, 1.0, true, true, false},
        Case{"euler_tools", Integrator::kExplicitEuler, 0.2, LengthRate::kAuto, 1.0, true, false, true},
        Case{"symplectic_everything", Integrator::kSymplecticEuler, 0.2, LengthRate::kAuto, 0.7, true, true, true},
        Case{"euler_checked", Integrator::kExplicitEuler, 0.2, LengthRate::kAuto, 1.0, true, false, false, true},
        Case{"symplectic_analytic_checked", Integrator::kSymplecticEuler, 0.2, LengthRate::kAnalytic, 1.0, true, false,
             false, true},
        Case{"euler_tools_checked", Integrator::kExplicitEuler, 0.2, LengthRate::kAuto, 1.0, true, false, true, true},
        Case{"symplectic_everything_checked", Integrator::kSymplecticEuler, 0.2, LengthRate::kAuto, 0.7, true, true,
             true, true}),
    [](const auto& param_info) { return param_info.param.name; });

// The caller's external forces (draping's form) come last in each atom's sum in both kernels:
// the general one adds them after the elements, the fused one as it integrates the atom.
TEST(FusedPass, ExternalForcesMatch) {
  const Model model = Slab();
  std::vector<Real> external(3 * static_cast<size_t>(model.num_atoms));
  for (size_t i = 0; i < external.size(); ++i) external[i] = static_cast<Real>(0.3 * std::cos(0.71 * i));
  for (Integrator integrator : {Integrator::kExplicitEuler, Integrator::kSymplecticEuler}) {
    StepOptions o = FullNoCheck(integrator);
    o.gravity = true;
    const auto [general, fused] = RunBoth(model, Deformed(model), o, 200, true, external);
    EXPECT_EQ(fused.fused_ticks, 200);
    EXPECT_EQ(fused.hash, general.hash) << IntegratorName(integrator);
    EXPECT_EQ(fused.force_bits, general.force_bits);
    // And they act: the same run without them ends elsewhere.
    const auto [without, unused] = RunBoth(model, Deformed(model), o, 200, true);
    EXPECT_NE(without.hash, general.hash);
  }
}

TEST(FusedPass, RestartMarksOfDegenerateElementsMatch) {
  // At rest every zero-length home element is degenerate (its filter is marked to restart); the
  // press then stretches them one by one.
  const Model model = Slab();
  for (const Integrator integrator : {Integrator::kExplicitEuler, Integrator::kSymplecticEuler}) {
    const auto [general, fused] = RunBoth(model, MakeState(model), FullNoCheck(integrator), 400, true);
    EXPECT_EQ(fused.hash, general.hash) << IntegratorName(integrator);
    EXPECT_EQ(fused.force_bits, general.force_bits);
    EXPECT_EQ(general.warnings, 0);
  }
}

TEST(FusedPass, CoincidentAtomsArePushedApartAlike) {
  // Two free atoms put on one point: their element (l_eq > 0) has no direction and pushes them
  // apart along its rest direction (DegenerateElement).
  const Model model = Slab();
  State start = Deformed(model);
  int32_t e = 0;
  while (model.atom_fixed[model.elem_atoms[2 * e]] || model.atom_fixed[model.elem_atoms[2 * e + 1]]) ++e;
  const int32_t a0 = model.elem_atoms[2 * e], a1 = model.elem_atoms[2 * e + 1];
  for (int c = 0; c < 3; ++c) start.atom_pos[3 * a1 + c] = start.atom_pos[3 * a0 + c];
  const auto [general, fused] = RunBoth(model, start, FullNoCheck(Integrator::kSymplecticEuler), 200, false);
  EXPECT_EQ(fused.hash, general.hash);
}

TEST(FusedPass, SubstepsFromThePredictionMatchToo) {
  // Stiff elements: the prediction asks for several substeps each tick.
  SlabOptions so;
  so.rows = 7, so.cols = 8;
  so.k = so.home_k = 400;
  const Model model = GenerateSlab(so);
  StepOptions o = FullNoCheck(Integrator::kSymplecticEuler);
  Workspace probe = MakeWorkspace(model, o);
  State s = Deformed(model);
  ASSERT_GT(Step(model, s, probe, ToolInput{}).substeps, 1);
  const auto [general, fused] = RunBoth(model, Deformed(model), o, 200, true);
  EXPECT_EQ(fused.hash, general.hash);
  EXPECT_EQ(fused.force_bits, general.force_bits);
}

// The tools' loops visit only the candidates within reach of a tool at the tick's start
// (Workspace::reach) while the pass's measured displacement says no other atom can have come in.
// An atom thrown from outside the reach into the sphere within one substep must still be felt in
// the next one, as the general path (which visits every candidate) feels it.
TEST(FusedPass, AnAtomThrownIntoTheToolWithinATickIsFeltAlike) {
  SlabOptions so;
  so.rows = 7, so.cols = 8;
  so.k = so.home_k = 400;  // several substeps a tick
  const Model model = GenerateSlab(so);
  StepOptions o = FullNoCheck(Integrator::kSymplecticEuler);
  // The sphere hovers above the slab's middle, touching nothing; the thrown atom is a free
  // external one at least four radii away.
  const double r = 0.5, centre[3] = {3.0, 3.0, 4.0};
  const ToolInput sphere = test::SphereAt(centre[0], centre[1], centre[2], r);
  int32_t thrown = -1;
  for (int32_t a = 0; a < model.num_atoms && thrown < 0; ++a) {
    double d2 = 0;
    for (int c = 0; c < 3; ++c)
      d2 += (model.atom_pos_eq[3 * a + c] - centre[c]) * (model.atom_pos_eq[3 * a + c] - centre[c]);
    if (model.atom_external[a] && !model.atom_fixed[a] && d2 > 16 * r * r) thrown = a;
  }
  ASSERT_GE(thrown, 0);
  Workspace probe = MakeWorkspace(model, o);
  State probe_state = MakeState(model);
  const int32_t substeps = Step(model, probe_state, probe, sphere).substeps;
  ASSERT_GT(substeps, 1);
  // Aimed so that its first substep (T = dt / substeps) takes it to the sphere's centre.
  const double T = o.dt_s / substeps;
  State start = MakeState(model);
  for (int c = 0; c < 3; ++c)
    start.atom_vel[3 * thrown + c] = static_cast<Real>((centre[c] - start.atom_pos[3 * thrown + c]) / T);
  double force[2][3] = {};
  uint64_t hash[2] = {};
  for (int fused = 0; fused < 2; ++fused) {
    State s = start;
    Workspace ws = MakeWorkspace(model, o);
    ws.options.fused_pass = fused == 1;
    const StepReport rep = Step(model, s, ws, sphere);
    EXPECT_EQ(rep.fused, fused == 1);
    EXPECT_EQ(rep.substeps, substeps);
    EXPECT_EQ(rep.tools[0].contacts, 0) << "no contact at the tick's start";
    std::copy(rep.tools[0].force_raw, rep.tools[0].force_raw + 3, force[fused]);
    hash[fused] = test::HashState(s);
  }
  // The atom is felt: the reaction on the device is not zero, and the same bits either way.
  EXPECT_GT(std::fabs(force[0][0]) + std::fabs(force[0][1]) + std::fabs(force[0][2]), 0.0);
  for (int c = 0; c < 3; ++c) EXPECT_EQ(force[1][c], force[0][c]) << "axis " << c;
  EXPECT_EQ(hash[1], hash[0]);
}

TEST(FusedPass, IsTakenAndReportsTheWholeModel) {
  const Model model = Slab();
  State s = Deformed(model);
  Workspace ws = MakeWorkspace(model, FullNoCheck(Integrator::kSymplecticEuler));
  StepReport r;
  for (int i = 0; i < 3; ++i) r = Step(model, s, ws, ToolInput{});
  EXPECT_TRUE(GetFusedPassStatus(ws).live);
  int32_t free_atoms = 0;
  for (uint8_t f : model.atom_fixed) free_atoms += !f;
  EXPECT_EQ(r.active_atoms, free_atoms);
  EXPECT_EQ(r.active_elems, model.num_elems);
  EXPECT_TRUE(r.fused);
  // The energy check (on by default) keeps the pass, and reports the energies it formed.
  StepOptions checked = FullNoCheck(Integrator::kSymplecticEuler);
  checked.stability.energy_check = true;
  Workspace wc = MakeWorkspace(model, checked);
  r = Step(model, s, wc, ToolInput{});
  EXPECT_TRUE(GetFusedPassStatus(wc).live);
  EXPECT_TRUE(r.fused);
  EXPECT_GT(r.energy_before, 0);
  EXPECT_GT(r.energy_after, 0);
  // Full mode with the default options, as `idms-sim run --full` and the agent make them.
  StepOptions defaults;
  defaults.full = true;
  Workspace wd = MakeWorkspace(model, defaults);
  for (int i = 0; i < 20; ++i) EXPECT_TRUE(Step(model, s, wd, Tools(i)).fused) << "tick " << i;
  // Local mode and the other integrators take the general path.
  StepOptions rk4 = defaults;
  rk4.integrator = Integrator::kRk4;
  Workspace wr = MakeWorkspace(model, rk4);
  EXPECT_FALSE(Step(model, s, wr, ToolInput{}).fused);
  Workspace wl = MakeWorkspace(model, StepOptions{});
  EXPECT_FALSE(Step(model, s, wl, Tools(0)).fused);
}

TEST(FusedPass, SwitchingFromLocalModeMatches) {
  // Local ticks leave some filters fresh and others stale; the first fused tick reads the stamps.
  const Model model = Slab();
  StepOptions local;
  State s = Deformed(model);
  Workspace wl = MakeWorkspace(model, local);
  for (int i = 0; i < 100; ++i) Step(model, s, wl, Tools(i));
  const auto [general, fused] = RunBoth(model, s, FullNoCheck(Integrator::kExplicitEuler), 100, true);
  EXPECT_EQ(fused.hash, general.hash);
  EXPECT_EQ(fused.force_bits, general.force_bits);
}

TEST(FusedPass, AlternatingWithTheGeneralPathMatches) {
  // Every third tick takes the general path (its lists are rebuilt, the stamp floor folded).
  const Model model = Slab();
  const StepOptions o = FullNoCheck(Integrator::kSymplecticEuler);
  State a = Deformed(model), b = Deformed(model);
  Workspace wa = MakeWorkspace(model, o), wb = MakeWorkspace(model, o);
  wa.options.fused_pass = false;
  for (int i = 0; i < 300; ++i) {
    wb.options.fused_pass = i % 3 != 0;
    Step(model, a, wa, Tools(i));
    Step(model, b, wb, Tools(i));
  }
  EXPECT_EQ(HashState(a), HashState(b));
}

// Fused against general: 50 ticks, then a NaN in a free atom's velocity and in an element's
// filter rate mid-model, then 50 more. The pass stops, restores what it wrote and the general path
// repairs the state: both must end on the same bits, with the same repairs.
void ExpectNanRepairedAlike(const Model& model) {
  const StepOptions o = FullNoCheck(Integrator::kSymplecticEuler);
  const Real nan = std::numeric_limits<Real>::quiet_NaN();
  uint64_t hashes[2];
  int64_t repaired[2];
  for (int fused = 0; fused < 2; ++fused) {
    State s = Deformed(model);
    Workspace ws = MakeWorkspace(model, o);
    ws.options.fused_pass = fused == 1;
    for (int i = 0; i < 50; ++i) Step(model, s, ws, ToolInput{});
    s.atom_vel[3 * 40 + 1] = nan;  // a free atom mid-model
    s.elem_rate[model.num_elems / 2] = nan;
    for (int i = 0; i < 50; ++i) Step(model, s, ws, ToolInput{});
    hashes[fused] = HashState(s);
    repaired[fused] = s.warnings.state_repaired;
    for (Real p : s.atom_pos) ASSERT_TRUE(std::isfinite(p));
  }
  EXPECT_EQ(hashes[1], hashes[0]);
  EXPECT_EQ(repaired[1], repaired[0]);
  EXPECT_GE(repaired[0], 1);
}

// Undamped explicit Euler diverges: with the prediction off nothing substeps, so the state grows
// until a result is not finite; both paths must then roll back and fall back alike.
void ExpectDivergenceAlike(const Model& undamped) {
  StepOptions o = FullNoCheck(Integrator::kExplicitEuler);
  o.stability.predict = false;
  o.dt_s = 5e-3;
  const auto [general, fused] = RunBoth(undamped, Deformed(undamped), o, 3000, false);
  EXPECT_GT(general.warnings, 0) << "the run never left the fused pass";
  EXPECT_EQ(fused.hash, general.hash);
  EXPECT_EQ(fused.warnings, general.warnings);
}

// A tick too long for the model with the energy check on: symplectic Euler at three times its stable
// step diverges within a tick or two, and the check must catch it before anything is non-finite,
// roll back and fall back to implicit Euler, in the fused pass as in the general path.
void ExpectCheckCatchesDivergenceAlike(const Model& model) {
  StepOptions o;
  o.full = true;
  o.integrator = Integrator::kSymplecticEuler;
  o.stability.predict = false;  // nothing substeps the tick
  o.dt_s = 3e-3;                // the slab's symplectic bound is 1.01e-3 s
  const auto [general, fused] = RunBoth(model, Deformed(model), o, 300, true);
  EXPECT_GT(general.rollbacks, 0) << "the tick did not diverge";
  EXPECT_GT(general.fallbacks, 0);
  EXPECT_EQ(fused.hash, general.hash);
  EXPECT_EQ(fused.warnings, general.warnings);
  EXPECT_EQ(fused.rollbacks, general.rollbacks);
  EXPECT_EQ(fused.fallbacks, general.fallbacks);
  EXPECT_EQ(fused.unrecovered, general.unrecovered);
  EXPECT_EQ(fused.force_bits, general.force_bits);
  // Every tick whose check failed left the pass; the others stayed in it.
  EXPECT_EQ(fused.fused_ticks, 300 - general.retried);
}

TEST(FusedPass, NonFiniteStateIsRepairedLikeTheGeneralPath) { ExpectNanRepairedAlike(Slab()); }

TEST(FusedPass, EnergyCheckCatchesDivergenceLikeTheGeneralPath) {
  ExpectCheckCatchesDivergenceAlike(Slab());
  ExpectCheckCatchesDivergenceAlike(ReorderForLocality(Slab()));
}

TEST(FusedPass, DivergenceFallsBackLikeTheGeneralPath) { ExpectDivergenceAlike(Slab(0.0)); }

TEST(FusedPass, ScalpelCutsAndEditsMatch) {
  const Model base = Slab();
  const StepOptions o = FullNoCheck(Integrator::kSymplecticEuler);
  uint64_t hashes[2];
  int32_t removed[2] = {0, 0};
  for (int fused = 0; fused < 2; ++fused) {
    Model model = base;
    State s = Deformed(model);
    Workspace ws = MakeWorkspace(model, o);
    ws.options.fused_pass = fused == 1;
    ToolInput in;
    in.num_tools = 1;
    in.tools[0].kind = ToolKind::kScalpel;
    in.tools[0].blade[2] = -1.0;
    for (int i = 0; i < 300; ++i) {
      in.tools[0].pos[0] = 3.0, in.tools[0].pos[1] = -1.0 + 0.03 * i, in.tools[0].pos[2] = 0.5;
      Step(model, s, ws, in);
      removed[fused] += ApplyPendingEdits(model, s, ws).elements_removed;
    }
    hashes[fused] = HashState(s);
  }
  EXPECT_GT(removed[0], 0);
  EXPECT_EQ(removed[1], removed[0]);
  EXPECT_EQ(hashes[1], hashes[0]);
}

TEST(FusedPass, RenumberedModelMatches) {
  // Renumbered in walk order, the pass reads and writes the filter state in place (with its
  // rollback copy on the way) instead of through the element ids.
  const Model model = ReorderForLocality(Slab());
  Workspace probe = MakeWorkspace(model, FullNoCheck(Integrator::kSymplecticEuler));
  State s = Deformed(model);
  Step(model, s, probe, ToolInput{});
  ASSERT_TRUE(GetFusedPassStatus(probe).identity);
  for (const Integrator integrator : {Integrator::kExplicitEuler, Integrator::kSymplecticEuler}) {
    for (const bool at_rest : {false, true}) {  // at rest: degenerate home elements, restart marks
      const State start = at_rest ? MakeState(model) : Deformed(model);
      const auto [general, fused] = RunBoth(model, start, FullNoCheck(integrator), 400, true);
      EXPECT_EQ(fused.hash, general.hash) << IntegratorName(integrator) << " at rest " << at_rest;
      EXPECT_EQ(fused.force_bits, general.force_bits);
      EXPECT_EQ(general.warnings, 0);
    }
  }
}

TEST(FusedPass, RenumberedModelFailsLikeTheGeneralPath) {
  // Renumbered, the pass restores the filter state through the copy it made in place.
  ExpectDivergenceAlike(ReorderForLocality(Slab(0.0)));
  ExpectNanRepairedAlike(ReorderForLocality(Slab()));
}

TEST(FusedPass, SnapshotReplayGivesSameBits) {
  const Model model = Slab();
  State s = Deformed(model);
  Workspace ws = MakeWorkspace(model, FullNoCheck(Integrator::kSymplecticEuler));
  for (int i = 0; i < 100; ++i) Step(model, s, ws, Tools(i));
  const State snapshot = s;
  for (int i = 100; i < 200; ++i) Step(model, s, ws, Tools(i));
  const uint64_t straight = HashState(s);
  s = snapshot;
  for (int i = 100; i < 200; ++i) Step(model, s, ws, Tools(i));
  // The hash covers every warning counter; the one expected difference is the resync.
  EXPECT_EQ(s.warnings.workspace_resync, snapshot.warnings.workspace_resync + 1) << "the rollback was noticed";
  s.warnings.workspace_resync = snapshot.warnings.workspace_resync;
  EXPECT_EQ(HashState(s), straight);
}

TEST(FusedPass, AllocatesNothing) {
  Model model = Slab();
  State s = Deformed(model);
  Workspace ws = MakeWorkspace(model, FullNoCheck(Integrator::kSymplecticEuler));
  Step(model, s, ws, Tools(0));
  const int64_t before = test::AllocationCount();
  for (int i = 1; i < 400; ++i) Step(model, s, ws, Tools(i));
  // A cut, its edit, and the rebuild of the pass's arrays at the next tick: still no allocation.
  ToolInput cut;
  cut.num_tools = 1;
  cut.tools[0].kind = ToolKind::kScalpel;
  cut.tools[0].blade[2] = -1.0;
  for (int i = 0; i < 60; ++i) {
    cut.tools[0].pos[0] = 3.0, cut.tools[0].pos[1] = -1.0 + 0.1 * i, cut.tools[0].pos[2] = 0.5;
    Step(model, s, ws, cut);
    ApplyPendingEdits(model, s, ws);
  }
  for (int i = 0; i < 10; ++i) Step(model, s, ws, ToolInput{});
  EXPECT_EQ(test::AllocationCount() - before, 0);
  EXPECT_TRUE(GetFusedPassStatus(ws).live);
}

TEST(FusedPass, HugePageInteriorIsTheWholeAlignedPagesInside) {
  constexpr uintptr_t kHuge = uintptr_t{2} << 20;
  auto at = [](uintptr_t a) { return reinterpret_cast<const void*>(a); };
  internal::HugeRange r = internal::HugePageInterior(at(8 * kHuge), kHuge + 1);
  EXPECT_EQ(r.begin, 8 * kHuge);
  EXPECT_EQ(r.length, kHuge);
  // 16 bytes past a boundary (where glibc's large blocks start), three pages long: two inside.
  r = internal::HugePageInterior(at(8 * kHuge + 16), 3 * kHuge);
  EXPECT_EQ(r.begin, 9 * kHuge);
  EXPECT_EQ(r.length, 2 * kHuge);
  // A page's length that straddles a boundary covers no whole page; nor does a short array.
  EXPECT_EQ(internal::HugePageInterior(at(8 * kHuge + 16), kHuge).length, 0u);
  EXPECT_EQ(internal::HugePageInterior(at(8 * kHuge), kHuge - 1).length, 0u);
  EXPECT_EQ(internal::HugePageInterior(nullptr, 10 * kHuge).length, 0u);
}

// A slab whose arrays span whole 2 MiB pages (2 to 4 x 10^5 atoms): huge pages are the caller's
// choice (a Workspace advises nothing by itself), change no bits, and are reported in whole pages.
TEST(FusedPass, HugePagesAreOptInAndChangeNoBits) {
  SlabOptions so;
  so.rows = so.cols = sizeof(Real) == 4 ? 370 : 260;  // positions over 4 MiB
  const Model model = GenerateSlab(so);
  ASSERT_GT(3 * sizeof(Real) * model.num_atoms, size_t{4} << 20);
  State on = Deformed(model), off = Deformed(model);
  Workspace ws_on = MakeWorkspace(model, FullNoCheck(Integrator::kSymplecticEuler));
  Workspace ws_off = MakeWorkspace(model, FullNoCheck(Integrator::kSymplecticEuler));
  const int64_t advised = AdviseHugePages(on, ws_on);
  EXPECT_EQ(advised % (int64_t{2} << 20), 0);  // 0 where the kernel declines
  for (int i = 0; i < 20; ++i) Step(model, on, ws_on, ToolInput{}), Step(model, off, ws_off, ToolInput{});
  EXPECT_EQ(HashState(on), HashState(off));
  EXPECT_EQ(GetFusedPassStatus(ws_on).huge_bytes, advised);
  EXPECT_EQ(GetFusedPassStatus(ws_off).huge_bytes, 0);
  // Local mode has no fused pass to advise.
  StepOptions local;
  Workspace ws_local = MakeWorkspace(model, local);
  EXPECT_EQ(AdviseHugePages(on, ws_local), 0);
}

// The walk in sections on threads (StepOptions::threads). A slab large enough for several
// sections of four batches or more, renumbered (the sections need the walk in element order).
Model SectionSlab(double b) {
  SlabOptions so;
  so.rows = 22, so.cols = 24;
  so.b = so.home_b = b;
  return ReorderForLocality(GenerateSlab(so));
}

struct Threaded {
  uint64_t hash = 0;
  double force_bits = 0;
  int64_t warnings = 0, rollbacks = 0, fallbacks = 0, fused_ticks = 0;
  std::vector<double> energy_before, energy_after;
  FusedPassStatus status;
};

Threaded RunThreaded(const Model& model, const State& start, StepOptions o, int32_t threads, int ticks, bool tools,
                     const std::function<void(int, State&)>& poke = {}) {
  o.threads = threads;
  Threaded out;
  State s = start;
  Workspace ws = MakeWorkspace(model, o);
  for (int i = 0; i < ticks; ++i) {
    if (poke) poke(i, s);
    const StepReport r = Step(model, s, ws, tools ? Tools(i) : ToolInput{});
    for (int t = 0; t < r.num_tools; ++t)
      out.force_bits += r.tools[t].force[0] + r.tools[t].force[1] + r.tools[t].force[2];
    out.fused_ticks += r.fused;
    out.fallbacks += r.fallback;
    out.energy_before.push_back(r.energy_before), out.energy_after.push_back(r.energy_after);
  }
  out.hash = HashState(s);
  out.warnings = TotalWarnings(s.warnings);
  out.rollbacks = s.warnings.rollback;
  out.status = GetFusedPassStatus(ws);
  return out;
}

// Same bits, same warnings, the same forces at the device; the energy check's sums (formed per
// section, then added) agree up to the order of the sums.
void ExpectThreadsAlike(const Threaded& one, const Threaded& many, int32_t threads) {
  EXPECT_EQ(many.status.sections, threads);
  EXPECT_GT(many.status.cross_elements, 0);
  EXPECT_EQ(one.status.sections, 1);
  EXPECT_EQ(many.hash, one.hash) << threads << " threads";
  EXPECT_EQ(many.force_bits, one.force_bits);
  EXPECT_EQ(many.warnings, one.warnings);
  EXPECT_EQ(many.rollbacks, one.rollbacks);
  EXPECT_EQ(many.fused_ticks, one.fused_ticks);
  ASSERT_EQ(many.energy_before.size(), one.energy_before.size());
  for (size_t i = 0; i < one.energy_before.size(); ++i) {
    for (const auto& [a, b] : {std::pair{one.energy_before[i], many.energy_before[i]},
                               std::pair{one.energy_after[i], many.energy_after[i]}}) {
      if (std::isfinite(a)) {
        EXPECT_NEAR(b, a, (sizeof(Real) == 4 ? 1e-5 : 1e-12) * (std::fabs(a) + 1e-9)) << i;
      }
    }
  }
}

TEST(FusedSections, SameBitsAsOneThreadInEveryConfiguration) {
  struct Config {
    const char* name;
    Integrator integrator;
    double b;
    LengthRate rate;
    double lambda;
    bool field, tools, check;
  };
  const Config configs[] = {
      {"euler_filtered_tools", Integrator::kExplicitEuler, 0.2, LengthRate::kAuto, 1.0, false, true, false},
      {"symplectic_lambda_field", Integrator::kSymplecticEuler, 0.2, LengthRate::kFiltered, 0.7, true, false, false},
      {"euler_analytic_checked", Integrator::kExplicitEuler, 0.2, LengthRate::kAnalytic, 1.0, false, true, true},
      {"symplectic_undamped_tools", Integrator::kSymplecticEuler, 0.0, LengthRate::kAuto, 1.0, false, true, false},
      {"symplectic_everything_checked", Integrator::kSymplecticEuler, 0.2, LengthRate::kAuto, 0.7, true, true, true},
  };
  for (const Config& c : configs) {
    SCOPED_TRACE(c.name);
    const Model model = SectionSlab(c.b);
    StepOptions o = FullNoCheck(c.integrator);
    o.length_rate = c.rate, o.lambda = c.lambda, o.stability.energy_check = c.check;
    if (c.field) o.gravity = true, o.air_damping = 3;
    const Threaded one = RunThreaded(model, Deformed(model), o, 1, 300, c.tools);
    EXPECT_EQ(one.warnings, c.check ? one.warnings : 0);
    for (const int32_t threads : {2, 3, 7}) {
      ExpectThreadsAlike(one, RunThreaded(model, Deformed(model), o, threads, 300, c.tools), threads);
    }
  }
}

TEST(FusedSections, AtRestWithRestartMarksAndDegenerateElements) {
  // At rest, the home elements are degenerate (zero length) and their filters restart: the cross
  // elements among them push the far endpoint before the sweep as the sweep would.
  const Model model = SectionSlab(0.2);
  const StepOptions o = FullNoCheck(Integrator::kSymplecticEuler);
  const Threaded one = RunThreaded(model, MakeState(model), o, 1, 200, true);
  ExpectThreadsAlike(one, RunThreaded(model, MakeState(model), o, 2, 200, true), 2);
  ExpectThreadsAlike(one, RunThreaded(model, MakeState(model), o, 4, 200, true), 4);
}

TEST(FusedSections, FailuresRollBackAlike) {
  // A NaN in an atom and in a filter mid-model: the section that meets it stops, every section's
  // written part is restored, and the general path repairs the state.
  const Model model = SectionSlab(0.2);
  const Real nan = std::numeric_limits<Real>::quiet_NaN();
  const auto poke = [&](int tick, State& s) {
    if (tick != 50) return;
    s.atom_vel[3 * (model.num_atoms / 3) + 1] = nan;
    s.elem_rate[2 * model.num_elems / 3] = nan;
  };
  const StepOptions nocheck = FullNoCheck(Integrator::kSymplecticEuler);
  const Threaded one = RunThreaded(model, Deformed(model), nocheck, 1, 100, false, poke);
  EXPECT_GE(one.warnings, 1);
  ExpectThreadsAlike(one, RunThreaded(model, Deformed(model), nocheck, 3, 100, false, poke), 3);
  // Too long a tick for symplectic Euler with the energy check on: rolled back and taken by
  // implicit Euler alike.
  StepOptions checked;
  checked.full = true, checked.integrator = Integrator::kSymplecticEuler;
  checked.stability.predict = false, checked.dt_s = 3e-3;
  const Threaded diverging = RunThreaded(model, Deformed(model), checked, 1, 100, true);
  EXPECT_GT(diverging.rollbacks, 0);
  EXPECT_GT(diverging.fallbacks, 0);
  ExpectThreadsAlike(diverging, RunThreaded(model, Deformed(model), checked, 2, 100, true), 2);
  // Undamped explicit Euler without the check grows until a result is not finite.
  const Model undamped = SectionSlab(0.0);
  StepOptions growing = FullNoCheck(Integrator::kExplicitEuler);
  growing.stability.predict = false, growing.dt_s = 5e-3;
  const Threaded grown = RunThreaded(undamped, Deformed(undamped), growing, 1, 1500, false);
  EXPECT_GT(grown.warnings, 0);
  ExpectThreadsAlike(grown, RunThreaded(undamped, Deformed(undamped), growing, 2, 1500, false), 2);
}

TEST(FusedSections, OneSectionWhereTheModelIsNotRenumberedOrTooSmall) {
  SlabOptions so;
  so.rows = 22, so.cols = 24;
  const Model plain = GenerateSlab(so);
  StepOptions o = FullNoCheck(Integrator::kSymplecticEuler);
  const Threaded not_renumbered = RunThreaded(plain, Deformed(plain), o, 4, 3, false);
  if (!not_renumbered.status.identity) {
    EXPECT_EQ(not_renumbered.status.sections, 1);
  }
  const Model small = ReorderForLocality(GenerateSlab(SlabOptions{}));  // under two sections of 4 batches
  EXPECT_EQ(RunThreaded(small, Deformed(small), o, 4, 3, false).status.sections, 1);
}

TEST(FusedSections, ACopiedWorkspaceStartsItsOwnThreads) {
  const Model model = SectionSlab(0.2);
  StepOptions o = FullNoCheck(Integrator::kSymplecticEuler);
  o.threads = 2;
  State s = Deformed(model);
  Workspace ws = MakeWorkspace(model, o);
  for (int i = 0; i < 20; ++i) Step(model, s, ws, Tools(i));
  State s2 = s;
  Workspace copy = ws;
  for (int i = 20; i < 60; ++i) Step(model, s, ws, Tools(i)), Step(model, s2, copy, Tools(i));
  EXPECT_EQ(HashState(s2), HashState(s));
  EXPECT_EQ(GetFusedPassStatus(copy).sections, 2);
}

}  // namespace
}  // namespace idms
