// The step's stability control under stiff and extreme cases (issue 3, thesis 4.2 and past it):
// every case must give finite atoms and device force, bounded energy, and a counted warning
// wherever a fallback or rollback happened.
#include <gtest/gtest.h>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <tuple>

#include "idms/sim/generate.h"
#include "idms/sim/integrate.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "step_test_util.h"
#include "warning_guard.h"

namespace idms {
namespace {

using test::SphereAt;

constexpr double kToolK = 1e5;  // the stiff tool
constexpr double kMaxForce = 10;

bool AllFinite(const State& s) {
  for (Real v : s.atom_pos) {
    if (!std::isfinite(v)) return false;
  }
  for (Real v : s.atom_vel) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

// Energy no physical outcome can exceed: every element stretched by the tool's diameter and
// every atom at the tool's deepest penalty. A divergence passes it within a few ticks.
double EnergyCeiling(const Model& m, double tool_k, double r) {
  double elastic = 0;
  for (double k : m.elem_k) elastic += 0.5 * k * (2 * r) * (2 * r);
  const double penalty = tool_k * (r * std::log(1 / 0.05) - r * 0.95);
  return elastic + m.num_atoms * penalty;
}

// Tool path by tick (not by time, so every dt sees the same motion per tick): press 0.5 units
// into the top atom, stroke along x, lift away, and let the window settle.
ToolInput ToolAtTick(int i, ContactLaw law) {
  double x = 1.5, z;
  if (i < 300) {
    z = 2.0 - 1.0 * i / 300.0;
  } else if (i < 500) {
    z = 1.0, x = 1.5 + 1.0 * (i - 300) / 200.0;
  } else {
    z = 5.0, x = 2.5;
  }
  return SphereAt(x, 1.732, z, 1.5, kToolK, law);
}

struct RunStats {
  bool finite = true;
  double max_energy = 0, energy_at_lift = 0, final_energy = 0, max_force = 0;
  int fallback_ticks = 0, retried_ticks = 0, unrecovered_ticks = 0;
};

RunStats RunCase(const Model& model, const StepOptions& options, ContactLaw law, State* state_out = nullptr) {
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, options);
  RunStats out;
  for (int i = 0; i < 900; ++i) {
    const StepReport r = Step(model, s, ws, ToolAtTick(i, law));
    const double* f = r.tools[0].force;
    const double mag = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    out.finite = out.finite && std::isfinite(mag);
    out.max_force = std::max(out.max_force, mag);
    out.fallback_ticks += r.fallback;
    out.retried_ticks += r.attempts > 1;
    out.unrecovered_ticks += r.unrecovered;
    const double h = ModelEnergy(model, s, ws);
    out.finite = out.finite && std::isfinite(h);
    out.max_energy = std::max(out.max_energy, h);
    if (i == 520) out.energy_at_lift = h;  // tool gone; only the settling window moves
    out.final_energy = h;
  }
  out.finite = out.finite && AllFinite(s);
  if (state_out != nullptr) *state_out = s;
  return out;
}

using Extreme = std::tuple<double, double, double, double, Integrator>;  // k, m, dt, b, integrator

class StepStabilitySweep : public ::testing::TestWithParam<Extreme> {};

TEST_P(StepStabilitySweep, FiniteBoundedAndWarnedWhereItFellBack) {
  const auto [k, mass, dt, b, integrator] = GetParam();
  SlabOptions so;
  so.k = so.home_k = k;
  so.b = so.home_b = b;
  so.mass = mass;
  const Model model = GenerateSlab(so);
  StepOptions o;
  o.dt_s = dt;
  o.integrator = integrator;
  o.max_device_force = kMaxForce;
  State s;
  // What a sweep to these extremes may count: fallbacks, retries and unrecovered ticks (held to
  // the ticks below) and the device limits; not bad input, a stalled CG or grown buffers.
  test::WarningGuard warnings(s);
  warnings.Allow(&WarningCounters::implicit_fallback)
      .Allow(&WarningCounters::rollback)
      .Allow(&WarningCounters::unrecovered)
      .Allow(&WarningCounters::device_force_clamped)
      .Allow(&WarningCounters::device_force_rate_limited);
  const RunStats st = RunCase(model, o, ContactLaw::kThesis, &s);
  EXPECT_TRUE(st.finite);
  EXPECT_LE(st.max_force, kMaxForce * (1 + 1e-12));
  EXPECT_LT(st.max_energy, EnergyCeiling(model, kToolK, 1.5));
  // Once the tool is gone the settling region's energy does not grow (within the bounded
  // oscillation of the symplectic and RK4 schemes' energy error when damping is light).
  EXPECT_LE(st.final_energy, st.energy_at_lift * 1.1 + 1e-12);
  // Every fallback and retry is a counted warning.
  EXPECT_EQ(s.warnings.implicit_fallback, st.fallback_ticks);
  EXPECT_GE(s.warnings.rollback, st.retried_ticks);
  EXPECT_EQ(s.warnings.unrecovered, st.unrecovered_ticks);
  // Explicit Euler without damping has no stable step at all (thesis 4.2): it must fall back.
  if (integrator == Integrator::kExplicitEuler && b == 0) {
    EXPECT_GT(st.fallback_ticks, 0);
  }
}

INSTANTIATE_TEST_SUITE_P(Sweep, StepStabilitySweep,
                         ::testing::Combine(::testing::Values(15.0, 1e3, 1e6), ::testing::Values(1e-6, 1e-3, 1.0),
                                            ::testing::Values(1e-4, 1e-3, 5e-3), ::testing::Values(0.0, 0.2),
                                            ::testing::Values(Integrator::kExplicitEuler, Integrator::kSymplecticEuler,
                                                              Integrator::kRk4, Integrator::kImplicitEuler)),
                         [](const auto& param_info) {
                           const Extreme& e = param_info.param;
                           char name[96];
                           std::snprintf(name, sizeof name, "k%g_m%g_dt%g_b%g_%s", std::get<0>(e), std::get<1>(e),
                                         std::get<2>(e), std::get<3>(e), IntegratorName(std::get<4>(e)));
                           std::string out(name);
                           for (char& c : out) c = std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
                           return out;
                         });

TEST(StepStability, LinearContactLawAtToolStiffness1e5) {
  const Model model = GenerateSlab(SlabOptions{});
  for (Integrator integrator : {Integrator::kExplicitEuler, Integrator::kSymplecticEuler, Integrator::kRk4}) {
    StepOptions o;
    o.integrator = integrator;
    State s;
    const RunStats st = RunCase(model, o, ContactLaw::kLinear, &s);
    EXPECT_TRUE(st.finite);
    EXPECT_LT(st.max_energy, EnergyCeiling(model, kToolK, 1.5));
    // k_tool / m = 5e7: explicit schemes need ~70 substeps, past max_substeps: implicit fallback.
    EXPECT_GT(st.fallback_ticks, 0);
    EXPECT_EQ(s.warnings.implicit_fallback, st.fallback_ticks);
  }
}

// Issue 11: a free atom on top atom 10, tied to it by a zero-length element, under the fast
// stroke with `idms-sim run`'s settings (local simulation, explicit Euler). The energy check's
// memory of what contact gained once outlived the tolerance that allowed it: when contact ended
// and the tolerance shrank with the energy scale, every tick failed (946 rollbacks, 473
// unrecovered ticks) with the tool far away. A check that is right has nothing to say there.
TEST(StepStability, TheEnergyCheckForgetsContactWithTheToleranceThatAllowedIt) {
  Model m = GenerateSlab(SlabOptions{});
  const int32_t twin = m.num_atoms;
  m.atom_pos_eq.insert(m.atom_pos_eq.end(), {m.atom_pos_eq[30], m.atom_pos_eq[31], m.atom_pos_eq[32]});
  m.atom_mass.push_back(0.002);
  m.atom_fixed.push_back(0);
  m.atom_external.push_back(0);
  m.elem_atoms.insert(m.elem_atoms.end(), {10, twin});
  m.elem_k.push_back(15);
  m.elem_b.push_back(0.2);
  FinalizeModel(m);
  StepOptions o;
  o.integrator = Integrator::kExplicitEuler;
  o.local_radius = 2.25;
  State s = MakeState(m);
  Workspace ws = MakeWorkspace(m, o);
  const ScriptGeometry geometry = MakeScriptGeometry(m, 1.5);
  const int64_t ticks = std::llround(ScriptDuration(Script::kStrokeFast) / o.dt_s);
  int64_t last_contact = -1, failures_after_contact = 0;
  for (int64_t n = 0; n < ticks; ++n) {
    const ScriptSample sample = SampleScript(Script::kStrokeFast, geometry, (n + 1) * o.dt_s);
    const StepReport r = Step(m, s, ws, SphereAt(sample.pos[0], sample.pos[1], sample.pos[2]));
    if (r.tools[0].contacts > 0) last_contact = n;
    if (last_contact >= 0 && n > last_contact + 50 && (r.attempts > 1 || r.unrecovered)) ++failures_after_contact;
  }
  ASSERT_GE(last_contact, 0) << "the stroke should touch the surface";
  EXPECT_EQ(failures_after_contact, 0) << "rollbacks with the tool off the surface";
  EXPECT_EQ(s.warnings.unrecovered, 0);
  EXPECT_LE(s.warnings.rollback, 10);
}

// The hex fragment plus a free atom on the same spot as top atom 5, tied to it by a
// zero-length element (the home elements are zero-length too); top atom 0 starts on top of atom
// 1 (their element has l = 0 < l_eq); the tool is centred exactly on atom 5.
TEST(StepStability, CoincidentAtomsAndZeroLengthElements) {
  Model m = GenerateSlab(SlabOptions{});
  const int32_t twin = m.num_atoms;
  m.atom_pos_eq.insert(m.atom_pos_eq.end(), {m.atom_pos_eq[15], m.atom_pos_eq[16], m.atom_pos_eq[17]});
  m.atom_mass.push_back(0.002);
  m.atom_fixed.push_back(0);
  m.atom_external.push_back(0);
  m.elem_atoms.insert(m.elem_atoms.end(), {5, twin, twin, 6});
  m.elem_k.insert(m.elem_k.end(), {15, 15});
  m.elem_b.insert(m.elem_b.end(), {0.2, 0.2});
  FinalizeModel(m);
  ASSERT_EQ(m.elem_leq[m.num_elems - 2], 0.0);
  const double* p5 = &m.atom_pos_eq[15];
  for (Integrator integrator :
       {Integrator::kExplicitEuler, Integrator::kSymplecticEuler, Integrator::kRk4, Integrator::kImplicitEuler}) {
    SCOPED_TRACE(IntegratorName(integrator));
    StepOptions o;
    o.integrator = integrator;
    o.full = true;  // nothing frozen: the energy must settle everywhere
    State s = MakeState(m);
    for (int c = 0; c < 3; ++c) s.atom_pos[c] = s.atom_pos[3 + c];  // atom 0 onto atom 1
    Workspace ws = MakeWorkspace(m, o);
    for (int i = 0; i < 500; ++i) {
      const StepReport r = Step(m, s, ws, SphereAt(p5[0], p5[1], p5[2]));
      ASSERT_TRUE(std::isfinite(r.tools[0].force[2])) << "tick " << i;
      ASSERT_TRUE(AllFinite(s)) << "tick " << i;
    }
    // The coincident pair separated along its rest direction.
    EXPECT_GT(std::fabs(s.atom_pos[0] - s.atom_pos[3]), 0.5);
    for (int i = 0; i < 3000; ++i) Step(m, s, ws, SphereAt(0, 0, 10));
    EXPECT_TRUE(AllFinite(s));
    EXPECT_LT(ModelEnergy(m, s, ws), 1e-3);
  }
}

TEST(StepStability, ToolJumpingTenUnitsInOneTick) {
  const Model model = GenerateSlab(SlabOptions{});
  for (Integrator integrator :
       {Integrator::kExplicitEuler, Integrator::kSymplecticEuler, Integrator::kRk4, Integrator::kImplicitEuler}) {
    SCOPED_TRACE(IntegratorName(integrator));
    StepOptions o;
    o.integrator = integrator;
    State s = MakeState(model);
    Workspace ws = MakeWorkspace(model, o);
    double last_force = 0;
    for (int i = 0; i < 2000; ++i) {
      // Rest in contact, teleport 10 units down through the slab, then 10 units sideways back
      // to the surface, then away.
      const double z = i < 500 ? 1.2 : i < 1000 ? -8.8 : i < 1500 ? 1.0 : 6.0;
      const double x = i < 1000 ? 1.5 : 11.5 - 10.0 * (i >= 1001);
      const StepReport r = Step(model, s, ws, SphereAt(x, 1.732, z, 1.5, kToolK));
      const double f = std::sqrt(r.tools[0].force[0] * r.tools[0].force[0] + r.tools[0].force[1] * r.tools[0].force[1] +
                                 r.tools[0].force[2] * r.tools[0].force[2]);
      ASSERT_TRUE(std::isfinite(f)) << "tick " << i;
      ASSERT_LE(f, o.max_device_force * (1 + 1e-12));
      // Growth is rate-limited: at most max_device_force_rate * dt more than last tick.
      ASSERT_LE(f, last_force + o.max_device_force_rate * o.dt_s + 1e-9) << "tick " << i;
      last_force = f;
    }
    EXPECT_TRUE(AllFinite(s));
    EXPECT_LT(ModelEnergy(model, s, ws), EnergyCeiling(model, kToolK, 1.5));
    EXPECT_GT(s.warnings.device_force_clamped + s.warnings.device_force_rate_limited, 0);
  }
}

TEST(StepStability, NonFiniteToolInputHoldsTheLastPose) {
  const Model model = GenerateSlab(SlabOptions{});
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, StepOptions{});
  StepReport r;
  for (int i = 0; i < 300; ++i) r = Step(model, s, ws, SphereAt(1.5, 1.732, 1.3));
  const double held = r.tools[0].force[2];
  ASSERT_GT(held, 0.5);
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  ToolInput bad[4] = {SphereAt(nan, 1.732, 1.3), SphereAt(1.5, inf, 1.3), SphereAt(1.5, 1.732, 1.3, nan),
                      SphereAt(1.5, 1.732, 1.3, 1.5, -inf)};
  for (const ToolInput& in : bad) {
    r = Step(model, s, ws, in);
    EXPECT_TRUE(r.tools[0].input_held);
    EXPECT_TRUE(std::isfinite(r.tools[0].force[2]));
    EXPECT_NEAR(r.tools[0].force[2], held, 0.05 * held);  // the held pose keeps pressing
  }
  EXPECT_EQ(s.warnings.bad_tool_input, 4);
  EXPECT_TRUE(AllFinite(s));
  // A tool whose first sample is already bad is ignored.
  State fresh = MakeState(model);
  Workspace ws2 = MakeWorkspace(model, StepOptions{});
  r = Step(model, fresh, ws2, SphereAt(nan, nan, nan));
  EXPECT_EQ(r.tools[0].force[2], 0);
  EXPECT_EQ(r.active_atoms, 0);
  EXPECT_EQ(fresh.warnings.bad_tool_input, 1);
}

TEST(StepStability, NonFiniteStateIsRepairedNotPropagated) {
  const Model model = GenerateSlab(SlabOptions{});
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, StepOptions{});
  for (int i = 0; i < 100; ++i) Step(model, s, ws, SphereAt(1.5, 1.732, 1.3));
  s.atom_vel[3 * 6 + 2] = std::numeric_limits<Real>::quiet_NaN();  // top atom 6, in the window
  s.elem_rate[0] = std::numeric_limits<Real>::infinity();
  StepReport r;
  for (int i = 0; i < 100; ++i) r = Step(model, s, ws, SphereAt(1.5, 1.732, 1.3));
  EXPECT_TRUE(AllFinite(s));
  EXPECT_TRUE(std::isfinite(r.tools[0].force[2]));
  EXPECT_GE(s.warnings.state_repaired, 1);
}

TEST(StepStability, WithoutFallbackAnUnstableSchemeFreezesInsteadOfExploding) {
  SlabOptions so;
  so.b = so.home_b = 0;  // explicit Euler is unstable for every step
  const Model model = GenerateSlab(so);
  StepOptions o;
  o.integrator = Integrator::kExplicitEuler;
  o.stability.implicit_fallback = false;
  o.stability.max_substeps = 2;
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, o);
  for (int i = 0; i < 3000; ++i) {
    const StepReport r = Step(model, s, ws, SphereAt(1.5, 1.732, 1.2 + 0.2 * std::sin(i * 0.01)));
    ASSERT_TRUE(std::isfinite(r.tools[0].force[2]));
  }
  EXPECT_TRUE(AllFinite(s));
  EXPECT_GT(s.warnings.substep_limit, 0);
  EXPECT_EQ(s.warnings.implicit_fallback, 0);
  EXPECT_LT(ModelEnergy(model, s, ws), EnergyCeiling(model, 400, 1.5));
}

TEST(StepStability, PredictionMatchesTheClosedFormsPerIntegrator) {
  const AtomBound bound{1e6, 100};  // omega = 1000 /s, c = 100 /s
  EXPECT_DOUBLE_EQ(StableDt(Integrator::kExplicitEuler, bound), EulerStableDt(bound));
  EXPECT_DOUBLE_EQ(StableDt(Integrator::kSymplecticEuler, bound), SymplecticStableDt(bound));
  EXPECT_DOUBLE_EQ(StableDt(Integrator::kRk4, bound), 2.5 / 1000);
  EXPECT_TRUE(std::isinf(StableDt(Integrator::kImplicitEuler, bound)));
  // With the default slab and tool the thesis's 1 kHz needs at most three Euler substeps (the
  // eq. 4.6 filter's lag halves the analytic limit; Gershgorin overestimates omega).
  const Model model = GenerateSlab(SlabOptions{});
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, StepOptions{});
  const StepReport r = Step(model, s, ws, SphereAt(1.5, 1.732, 1.3));
  EXPECT_GT(r.predicted_dt_s, 0.35e-3);
  EXPECT_LE(r.substeps, 3);
}

}  // namespace
}  // namespace idms
