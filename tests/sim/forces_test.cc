// Tests of the force stage (sim/src/forces.cc) against hand calculation: an element's spring and
// dashpot force (eqs. 4.3-4.9) with the exact and the filtered (eq. 4.6) length rate, the filter's
// restart, field forces (eq. 4.2), both MIO contact laws and the grasp element (5.5.1, 6.1.3), and
// the energies the stability check compares.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "idms/sim/model.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"
#include "idms/sim/tool.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"
#include "step_test_util.h"

namespace idms {
namespace {

using internal::EvaluateForces;

// Two free atoms joined by one element: rest at (0,0,0) and (2,0,0), so l_eq = 2.
Model TwoAtoms(double k, double b, double mass = 0.5) {
  return test::TwoAtomModel({.name = "pair", .end = {2, 0, 0}, .first_fixed = false, .external = {1, 1}}, k, b, mass);
}

// The model's Workspace in full mode with its lists built (every free atom active).
Workspace FullWorkspace(const Model& m, State& s, const StepOptions& o) {
  Workspace ws = MakeWorkspace(m, o);
  internal::BuildActiveSet(m, s, ws);
  return ws;
}

StepOptions Options(double dt = 1e-3) { return test::FullOptions(Integrator::kExplicitEuler, dt); }

void ExpectForce(const Workspace& ws, int32_t a, double fx, double fy, double fz, double tol = 1e-12) {
  EXPECT_NEAR(ws.atom_force[3 * a], fx, tol * (1 + std::fabs(fx))) << "atom " << a;
  EXPECT_NEAR(ws.atom_force[3 * a + 1], fy, tol * (1 + std::fabs(fy))) << "atom " << a;
  EXPECT_NEAR(ws.atom_force[3 * a + 2], fz, tol * (1 + std::fabs(fz))) << "atom " << a;
}

// Atom 1 at (3, 4, 0): s = (3, 4, 0), l = 5, s^ = (0.6, 0.8, 0) (eqs. 4.3-4.5); stretched by 3.
// With v1 = (1, 2, 3): l' = s^ . (v1 - v0) = 2.2. Eq. 4.7: k (l - l_eq) = 10 * 3 = 30; eq. 4.8:
// b l' = 0.5 * 2.2 = 1.1; eq. 4.9: 31.1 along s^ on atom 0, the opposite on atom 1.
TEST(Forces, ElementForceIsEquations43To49WithTheExactRate) {
  const Model m = TwoAtoms(10, 0.5);
  State s = MakeState(m);
  s.atom_pos[3] = 3, s.atom_pos[4] = 4;
  s.atom_vel[3] = 1, s.atom_vel[4] = 2, s.atom_vel[5] = 3;
  Workspace ws = FullWorkspace(m, s, Options());
  EvaluateForces(m, s, ws, /*filtered=*/false, 1e-3);
  ExpectForce(ws, 0, 31.1 * 0.6, 31.1 * 0.8, 0);
  ExpectForce(ws, 1, -31.1 * 0.6, -31.1 * 0.8, 0);
  // The exact rate leaves the filter's state alone (MakeState's restart mark).
  EXPECT_EQ(s.elem_len[0], kFilterRestart);
  EXPECT_EQ(s.elem_rate[0], 0);
  // Compressed to l = 1 along -z, closing at 4 units/s: k (1 - 2) + b (-4) = -12 along s^ = -z.
  s.atom_pos[3] = 0, s.atom_pos[4] = 0, s.atom_pos[5] = -1;
  s.atom_vel[3] = 0, s.atom_vel[4] = 0, s.atom_vel[5] = 4;
  EvaluateForces(m, s, ws, false, 1e-3);
  ExpectForce(ws, 0, 0, 0, 12);
  ExpectForce(ws, 1, 0, 0, -12);
}

// Eq. 4.6: l' = lambda (l_n - l_{n-1}) / T + (1 - lambda) l'_{n-1}, then l_{n-1} = l_n.
TEST(Forces, FilteredRateIsEquation46) {
  const double T = 1e-3, lambda = 0.25;
  const Model m = TwoAtoms(10, 0.5);
  State s = MakeState(m);
  s.atom_pos[3] = 3, s.atom_pos[4] = 4;  // l = 5
  s.atom_vel[3] = 100;                   // the filter does not look at velocities
  s.elem_len[0] = 4.9;
  s.elem_rate[0] = 1.0;
  StepOptions o = Options(T);
  o.lambda = lambda;
  Workspace ws = FullWorkspace(m, s, o);
  EvaluateForces(m, s, ws, /*filtered=*/true, T);
  const double rate = lambda * (5 - 4.9) / T + (1 - lambda) * 1.0;  // 25.75
  EXPECT_NEAR(s.elem_rate[0], rate, 1e-9);
  EXPECT_EQ(s.elem_len[0], 5);
  const double mag = 10 * 3 + 0.5 * rate;
  ExpectForce(ws, 0, mag * 0.6, mag * 0.8, 0, 1e-9);
  ExpectForce(ws, 1, -mag * 0.6, -mag * 0.8, 0, 1e-9);
}

// A restart mark (elem_len = -1) starts the filter from rest at the current length: rate 0.
TEST(Forces, ARestartMarkStartsTheFilterFromRest) {
  const Model m = TwoAtoms(10, 0.5);
  State s = MakeState(m);
  s.atom_pos[3] = 3, s.atom_pos[4] = 4;
  s.elem_len[0] = -1;
  s.elem_rate[0] = 7.0;
  Workspace ws = FullWorkspace(m, s, Options());
  EvaluateForces(m, s, ws, /*filtered=*/true, 1e-3);
  EXPECT_EQ(s.elem_rate[0], 0);
  EXPECT_EQ(s.elem_len[0], 5);
  ExpectForce(ws, 0, 30 * 0.6, 30 * 0.8, 0);
}

// Coincident atoms: no direction, so no rate; the element pushes them apart with k l_eq along its
// rest direction, and its filter is marked to restart (elem_len = -1, rate 0).
TEST(Forces, ADegenerateElementPushesAlongItsRestDirectionAndRestarts) {
  const Model m = TwoAtoms(10, 0.5);
  State s = MakeState(m);
  s.atom_pos[3] = 0;  // atom 1 on atom 0
  s.atom_vel[3] = 5;
  s.elem_rate[0] = 3.0;
  Workspace ws = FullWorkspace(m, s, Options());
  EvaluateForces(m, s, ws, /*filtered=*/true, 1e-3);
  ExpectForce(ws, 0, -20, 0, 0);  // k l_eq = 20, atom 0 pushed along -x
  ExpectForce(ws, 1, 20, 0, 0);
  EXPECT_EQ(s.elem_len[0], -1) << "restart mark";
  EXPECT_EQ(s.elem_rate[0], 0);
  // Apart again: the filter restarts from rest at the new length.
  s.atom_pos[3] = 1;
  EvaluateForces(m, s, ws, true, 1e-3);
  EXPECT_EQ(s.elem_rate[0], 0);
  EXPECT_EQ(s.elem_len[0], 1);
  ExpectForce(ws, 0, -10, 0, 0);  // k (1 - 2) along +x
}

// Forces land on active endpoints only; a fixed endpoint pushes back but is not moved.
TEST(Forces, OnlyActiveAtomsReceiveForces) {
  const Model m = test::OneSpring(15, 0, 0.002);  // atom 0 fixed
  State s = MakeState(m);
  s.atom_pos[3] = 1.5;
  Workspace ws = FullWorkspace(m, s, Options());
  const Real sentinel = 12345;
  for (int c = 0; c < 3; ++c) ws.atom_force[c] = sentinel;
  EvaluateForces(m, s, ws, false, 1e-3);
  ExpectForce(ws, 1, -15 * 0.5, 0, 0);
  for (int c = 0; c < 3; ++c) EXPECT_EQ(ws.atom_force[c], sentinel) << "the fixed atom's entry is not written";
}

// Eq. 4.2: m g and -c m v written over the accumulator; the caller's external forces come last,
// in EvaluateForces (and in the fused kernel's integration), not here.
TEST(Forces, FieldForcesAreGravityAndAirExternalForcesComeLast) {
  const Model m = TwoAtoms(10, 0, /*mass=*/0.5);
  State s = MakeState(m);
  s.atom_vel[0] = 2, s.atom_vel[5] = -4;
  StepOptions o = Options();
  o.gravity = true;
  o.gravity_accel[0] = 1, o.gravity_accel[1] = 0, o.gravity_accel[2] = -9.81;
  o.air_damping = 3;
  Workspace ws = FullWorkspace(m, s, o);
  ws.atom_force_external = {0.25, 0, 0, 0, 0, 1};
  // Stride 4 into a caller's accumulator, garbage beforehand: overwritten, lane 3 untouched.
  Real acc[8];
  for (Real& v : acc) v = 99;
  internal::FieldForces(m, s, ws, acc, 4);
  EXPECT_DOUBLE_EQ(acc[0], 0.5 * 1 - 3 * 0.5 * 2);
  EXPECT_DOUBLE_EQ(acc[1], 0);
  EXPECT_DOUBLE_EQ(acc[2], 0.5 * -9.81);
  EXPECT_EQ(acc[3], 99);
  EXPECT_DOUBLE_EQ(acc[4], 0.5);
  EXPECT_DOUBLE_EQ(acc[5], 0);
  EXPECT_DOUBLE_EQ(acc[6], 0.5 * -9.81 - 3 * 0.5 * -4);
  EXPECT_EQ(acc[7], 99);
  // EvaluateForces adds the (unstretched) element, nothing, and the external forces.
  EvaluateForces(m, s, ws, false, 1e-3);
  ExpectForce(ws, 1, 0.5, 0, 0.5 * -9.81 + 6 + 1);
}

// One sphere MIO over atom 1 of the pair, centre c = p1 + (0, 0, h): |d| = h below the centre.
struct Contact {
  Model m = TwoAtoms(10, 0);
  State s = MakeState(m);
  Workspace ws;
  Contact(ContactLaw law, double h, double r = 1.5, double k = 400) {
    ws = MakeWorkspace(m, Options());
    StepReport report;
    internal::ResolveTools(m, s, ws, test::SphereAt(2, 0, h, r, k, law), &report);
    internal::BuildActiveSet(m, s, ws);
    for (int c = 0; c < 3; ++c) ws.atom_force[c] = ws.atom_force[3 + c] = 0;
    internal::ToolForces(s, ws, ws.atom_force.data(), 3);
  }
};

// Thesis 5.5.1 as written: f = k (r - |d|) / |d| along d^; the linear law: k (r - |d|) along d^.
// At |d| = 0.5, r = 1.5, k = 400: 800 and 400 downwards; the tool's sum is the same.
TEST(Forces, ToolForcesFollowBothContactLaws) {
  const Contact thesis(ContactLaw::kThesis, 0.5), linear(ContactLaw::kLinear, 0.5);
  ExpectForce(thesis.ws, 1, 0, 0, -800);
  ExpectForce(linear.ws, 1, 0, 0, -400);
  EXPECT_DOUBLE_EQ(thesis.ws.tools[0].eval_force[2], -800);
  EXPECT_DOUBLE_EQ(linear.ws.tools[0].eval_force[2], -400);
  ExpectForce(thesis.ws, 0, 0, 0, 0);  // 2 units away: outside
  // Below d_min = 0.05 r the thesis law holds |d| at d_min: k (r - d_min) / d_min.
  const Contact close(ContactLaw::kThesis, 0.01);
  const double dmin = 0.05 * 1.5;
  ExpectForce(close.ws, 1, 0, 0, -400 * (1.5 - dmin) / dmin);
  // Outside the sphere: nothing at all.
  const Contact outside(ContactLaw::kLinear, 1.5 + 1e-9);
  ExpectForce(outside.ws, 1, 0, 0, 0);
  EXPECT_EQ(outside.ws.tools[0].eval_force[2], 0);
}

// A grasped atom feels the grasp element k (l - l_eq) along the centre, not the contact law.
TEST(Forces, AGraspedAtomFeelsTheGraspElementOnly) {
  Contact f(ContactLaw::kThesis, 0.5);
  ActiveTool& at = f.ws.tools[0];
  at.grasp_atom = 1, at.grasp_leq = 0.2, at.grasp_k = 100;
  for (int c = 0; c < 6; ++c) f.ws.atom_force[c] = 0;
  internal::ToolForces(f.s, f.ws, f.ws.atom_force.data(), 3);
  ExpectForce(f.ws, 1, 0, 0, 100 * (0.5 - 0.2));  // pulled up towards the centre
  EXPECT_DOUBLE_EQ(at.eval_force[2], 30);
}

// The energies the stability check compares, by hand: kinetic, elastic, contact and gravity.
TEST(Forces, ActiveEnergyIsKineticElasticContactAndGravity) {
  const double r = 1.5, k_tool = 400, h = 0.5;
  Contact f(ContactLaw::kLinear, h, r, k_tool);
  // Both atoms out of the sphere's reach: atom 1 to (3, 4, 0), atom 0 to (0, 0, -h), moving.
  f.s.atom_pos[3] = 3, f.s.atom_pos[4] = 4;
  f.s.atom_pos[2] = -h;
  f.s.atom_vel[0] = 2;
  const double stretch = std::sqrt(3.0 * 3 + 4 * 4 + h * h) - 2;
  const internal::Energy e = internal::ActiveEnergy(f.m, f.s, f.ws);
  EXPECT_NEAR(e.h, 0.5 * 0.5 * 2 * 2 + 0.5 * 10 * stretch * stretch, 1e-12);
  EXPECT_NEAR(internal::ElasticEnergy(f.m, f.s), 0.5 * 10 * stretch * stretch, 1e-12);
  // Back under the tool, at rest: only the linear law's penalty 1/2 k (r - |d|)^2.
  f.s = MakeState(f.m);
  const internal::Energy contact = internal::ActiveEnergy(f.m, f.s, f.ws);
  EXPECT_NEAR(contact.h, 0.5 * k_tool * (r - h) * (r - h), 1e-12);
  EXPECT_GT(contact.noise, 0);
  // Non-finite positions make it NaN, so the check rejects the attempt.
  f.s.atom_pos[0] = std::numeric_limits<Real>::quiet_NaN();
  EXPECT_TRUE(std::isnan(internal::ActiveEnergy(f.m, f.s, f.ws).h));
}

TEST(Forces, GravityEnergyIsRelativeToRestAndSplitsOutWithTheTools) {
  const Model m = TwoAtoms(10, 0, 0.5);
  State s = MakeState(m);
  StepOptions o = Options();
  o.gravity = true;  // (0, 0, -9.81)
  Workspace ws = FullWorkspace(m, s, o);
  s.atom_pos[2] = -0.1, s.atom_pos[5] = -0.1;  // both dropped 0.1: no stretch
  const internal::Energy e = internal::ActiveEnergy(m, s, ws);
  EXPECT_NEAR(e.h, -2 * 0.5 * 9.81 * 0.1, 1e-12);
  EXPECT_NEAR(e.scale, 2 * 0.5 * 9.81 * 0.1, 1e-12);
  // ToolAndGravityEnergy adds the same gravity term (no tool here) to what it is given.
  internal::Energy part;
  internal::ToolAndGravityEnergy(m, s, ws, &part);
  EXPECT_NEAR(part.h, e.h, 1e-15);
  EXPECT_NEAR(part.scale, e.scale, 1e-15);
}

// The energy of every element, active or not: none at rest, 1/2 k (l - l_eq)^2 stretched.
TEST(Forces, ElasticEnergyCoversEveryElement) {
  const Model m = test::OneSpring(15, 0.2, 0.002, 1.0);
  State s = MakeState(m);
  EXPECT_EQ(internal::ElasticEnergy(m, s), 0);
  s.atom_pos[3] = 0.7, s.atom_pos[4] = 0.4;  // l = sqrt(0.65)
  const double stretch = std::sqrt(0.65) - 1;
  EXPECT_NEAR(internal::ElasticEnergy(m, s), 0.5 * 15 * stretch * stretch, 1e-15);
}

}  // namespace
}  // namespace idms
