// Tests of the tools: the MIO contact laws (thesis 5.5.1), the device force as the reaction,
// tweezers grasping (6.1.3) and scalpel cuts (3.2.6), and segment/sweep geometry.
#include "idms/sim/tool.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <set>
#include <utility>

#include "idms/sim/edit.h"
#include "idms/sim/generate.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "step_test_util.h"
#include "warning_guard.h"

namespace idms {
namespace {

using test::SphereAt;

TEST(ToolContact, ThesisLawHasTheExtraOneOverDistance) {
  const double d[3] = {0, 0, -1.0};  // atom 1.0 below the centre of an r = 1.5 sphere
  const ContactForce f = SphereContact(ContactLaw::kThesis, 400, 1.5, 0.05, d);
  ASSERT_TRUE(f.touching);
  EXPECT_DOUBLE_EQ(f.f[2], -400 * 0.5 / 1.0);  // k (r - |d|) / |d| along d^
  const double d2[3] = {0, 0.75, 0};
  EXPECT_DOUBLE_EQ(SphereContact(ContactLaw::kThesis, 400, 1.5, 0.05, d2).f[1], 400 * 0.75 / 0.75);
  EXPECT_DOUBLE_EQ(SphereContact(ContactLaw::kThesis, 400, 1.5, 0.05, d2).stiffness, 400 * 1.5 / (0.75 * 0.75));
}

TEST(ToolContact, LinearLawIsPlainPenetration) {
  const double d[3] = {0.6, 0, 0.8};  // |d| = 1
  const ContactForce f = SphereContact(ContactLaw::kLinear, 400, 1.5, 0.05, d);
  EXPECT_DOUBLE_EQ(f.f[0], 400 * 0.5 * 0.6);
  EXPECT_DOUBLE_EQ(f.f[2], 400 * 0.5 * 0.8);
  EXPECT_DOUBLE_EQ(f.stiffness, 400);
  EXPECT_DOUBLE_EQ(f.energy, 0.5 * 400 * 0.25);
}

TEST(ToolContact, OutsideNonFiniteAndCentredAreSafe) {
  const double out[3] = {0, 0, 1.5}, nan[3] = {std::nan(""), 0, 0};
  EXPECT_FALSE(SphereContact(ContactLaw::kThesis, 400, 1.5, 0.05, out).touching);
  EXPECT_FALSE(SphereContact(ContactLaw::kThesis, 400, 1.5, 0.05, nan).touching);
  const double centre[3] = {0, 0, 0};
  const ContactForce f = SphereContact(ContactLaw::kThesis, 400, 1.5, 0.05, centre);
  EXPECT_TRUE(f.touching);
  EXPECT_EQ(f.f[0], 0);
  EXPECT_DOUBLE_EQ(f.f[2], 400 * (1.5 - 0.075) / 0.075);  // clamped at d_min = 0.05 r, along +z
  EXPECT_TRUE(std::isfinite(f.energy));
}

TEST(ToolContact, EnergyIsThePotentialOfTheForce) {
  for (ContactLaw law : {ContactLaw::kThesis, ContactLaw::kLinear}) {
    for (double dist : {0.05, 0.3, 0.9, 1.4}) {
      const double h = 1e-6, a[3] = {0, 0, dist - h}, b[3] = {0, 0, dist + h}, c[3] = {0, 0, dist};
      const double de =
          (SphereContact(law, 400, 1.5, 0.05, b).energy - SphereContact(law, 400, 1.5, 0.05, a).energy) / (2 * h);
      EXPECT_NEAR(-de, SphereContact(law, 400, 1.5, 0.05, c).f[2], 1e-4 * (1 + std::fabs(de))) << dist;
    }
  }
}

TEST(ToolGeometry, SegmentTriangleAndSweep) {
  const double a[3] = {0, 0, 0}, b[3] = {1, 0, 0}, c[3] = {0, 1, 0};
  const double p[3] = {0.2, 0.2, 1}, q[3] = {0.2, 0.2, -1}, q_short[3] = {0.2, 0.2, 0.5};
  EXPECT_TRUE(SegmentCrossesTriangle(p, q, a, b, c));
  EXPECT_FALSE(SegmentCrossesTriangle(p, q_short, a, b, c));
  const double far_p[3] = {2, 2, 1}, far_q[3] = {2, 2, -1};
  EXPECT_FALSE(SegmentCrossesTriangle(far_p, far_q, a, b, c));
  const double in_plane_p[3] = {-1, 0.2, 0}, in_plane_q[3] = {2, 0.2, 0};
  EXPECT_FALSE(SegmentCrossesTriangle(in_plane_p, in_plane_q, a, b, c));  // grazing = no cut
  // A vertical blade z in [-1, 1] at x = 0 moving from y = -1 to y = 1 cuts an element along x.
  const double a0[3] = {0, -1, 1}, b0[3] = {0, -1, -1}, a1[3] = {0, 1, 1}, b1[3] = {0, 1, -1};
  const double e0[3] = {-0.5, 0.3, 0}, e1[3] = {0.5, 0.3, 0};
  EXPECT_TRUE(SegmentCrossesSweep(e0, e1, a0, b0, a1, b1));
  const double f0[3] = {-0.5, 1.3, 0}, f1[3] = {0.5, 1.3, 0};
  EXPECT_FALSE(SegmentCrossesSweep(f0, f1, a0, b0, a1, b1));
  EXPECT_FALSE(SegmentCrossesSweep(e0, e1, a0, b0, a0, b0));  // a blade that did not move
}

TEST(ToolDeviceForce, IsMinusTheSumOfForcesOnAtoms) {
  // One free atom on a soft spring, inside the sphere: the reaction equals -(contact force).
  Model m = test::OneSpring(15, 0.2, 0.002, 1.0);
  StepOptions o;
  o.full = true;
  o.max_device_force = 1e9;
  o.max_device_force_rate = 1e12;
  o.stability.predict = false;  // one substep: the force at the tick's start
  State s = MakeState(m);
  Workspace ws = MakeWorkspace(m, o);
  const StepReport r = Step(m, s, ws, SphereAt(1.0, 0, 1.2));  // atom at (1, 0, 0): |d| = 1.2
  const double d[3] = {0, 0, -1.2};
  const ContactForce cf = SphereContact(ContactLaw::kThesis, 400, 1.5, 0.05, d);
  EXPECT_NEAR(r.tools[0].force[2], -cf.f[2], 1e-9);
  EXPECT_NEAR(r.tools[0].force[0], 0, 1e-12);
  EXPECT_EQ(r.tools[0].contacts, 1);
}

// The fragment of thesis 6.1 with a tweezers MIO over top atom 11 (2.5, 1.732, 0).
StepOptions UnclampedOptions() {
  StepOptions o;
  o.max_device_force = 1e3;  // plucking pulls harder and faster than a PHANToM could
  o.max_device_force_rate = 1e7;
  o.local_radius = 2.25;  // thesis 6.2's haptic window: 2.8 above the surface is outside it
  return o;
}

struct TweezersFixture {
  Model model = GenerateSlab(SlabOptions{});
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, UnclampedOptions());
  StepReport Tick(double z, bool closed) {
    ToolInput in = SphereAt(2.5, 1.732, z);
    in.tools[0].kind = ToolKind::kTweezers;
    in.tools[0].closed = closed;
    return Step(model, state, ws, in);
  }
};

TEST(ToolTweezers, ClosingInContactGraspsTheNearestAtomAndPlucks) {
  TweezersFixture f;
  test::WarningGuard warnings(f.state);
  StepReport r;
  for (int i = 0; i < 400; ++i) r = f.Tick(1.3, false);
  ASSERT_GT(r.tools[0].contacts, 0);
  EXPECT_EQ(r.tools[0].grasp_atom, -1);
  r = f.Tick(1.3, true);
  ASSERT_EQ(r.tools[0].grasp_atom, 11);
  const ToolState& ts = f.state.tools[0];
  const Real* p = &f.state.atom_pos[3 * 11];
  // The element starts compressed by the contact force it takes over: k (l_eq - l) = |f_contact|.
  const double l =
      std::sqrt((p[0] - 2.5) * (p[0] - 2.5) + (p[1] - 1.732) * (p[1] - 1.732) + (p[2] - 1.3) * (p[2] - 1.3));
  EXPECT_GT(ts.grasp_leq, l);
  EXPECT_LT(ts.grasp_leq, 1.5 + 1e-9);
  EXPECT_EQ(ts.grasp_k, 400);
  // Lift: the atom follows up, the device is pulled down (the grasp element's force).
  for (int i = 0; i < 1500; ++i) r = f.Tick(1.3 + 1.5 * std::min(1.0, i / 1000.0), true);
  EXPECT_GT(f.state.atom_pos[3 * 11 + 2], 0.5);
  EXPECT_LT(r.tools[0].force[2], -1.0);
  EXPECT_EQ(r.tools[0].contacts, 0);
  // Open: the force falls to zero at once (thesis fig. 6-8) and the atom returns to rest.
  r = f.Tick(2.8, false);
  EXPECT_EQ(r.tools[0].grasp_atom, -1);
  EXPECT_EQ(r.tools[0].force[2], 0);
  for (int i = 0; i < 1500; ++i) f.Tick(2.8, false);
  // Back to rest everywhere: the atoms around it that froze while it was held are woken.
  for (int32_t a = 0; a < f.model.num_atoms; ++a) {
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(f.state.atom_pos[3 * a + c], f.model.atom_pos_eq[3 * a + c], 1e-3);
  }
  EXPECT_EQ(f.state.num_active, 0);
}

// Issue 11: in the pluck script the device force fell from 0.548 N to 0.004 N in the tick the
// tweezers closed (the grasped atom's contact force dropped, the new element starting at zero)
// and overshot to 0.75 N within 6 ms. The hand-over must be no bigger a step than the contact
// itself makes in a tick, and must not overshoot.
TEST(ToolTweezers, TheHandOverFromContactToGraspIsContinuous) {
  Model m = GenerateSlab(SlabOptions{});
  StepOptions o;
  o.local_radius = 2.25;
  State s = MakeState(m);
  Workspace ws = MakeWorkspace(m, o);
  const ScriptGeometry geometry = MakeScriptGeometry(m, 1.5);
  std::vector<double> force;  // |device force| per tick
  int64_t close_tick = -1;
  for (int64_t n = 0; n < std::llround(ScriptDuration(Script::kPluck) / o.dt_s); ++n) {
    const ScriptSample sample = SampleScript(Script::kPluck, geometry, (n + 1) * o.dt_s);
    ToolInput in = SphereAt(sample.pos[0], sample.pos[1], sample.pos[2]);
    in.tools[0].kind = ToolKind::kTweezers;
    in.tools[0].closed = sample.closed;
    if (sample.closed && close_tick < 0) close_tick = n;
    const StepReport r = Step(m, s, ws, in);
    const double* f = r.tools[0].force;
    force.push_back(std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]));
    if (close_tick == n) {
      ASSERT_GE(r.tools[0].grasp_atom, 0) << "the tweezers close in contact";
    }
  }
  ASSERT_GT(close_tick, 200);
  const double before = force[close_tick - 1];
  ASSERT_GT(before, 0.3) << "pressing when the tweezers close";
  double contact_step = 0;  // the largest change the contact makes in a tick just before
  for (int64_t n = close_tick - 200; n < close_tick; ++n)
    contact_step = std::max(contact_step, std::abs(force[n] - force[n - 1]));
  EXPECT_LE(std::abs(force[close_tick] - before), contact_step) << before << " N -> " << force[close_tick] << " N";
  double peak = 0;
  for (int64_t n = close_tick; n < close_tick + 10; ++n) peak = std::max(peak, force[n]);
  EXPECT_LE(peak, before + 10 * contact_step) << "no overshoot after the hand-over";
}

TEST(ToolTweezers, GraspingIsEdgeTriggeredAndNeedsContact) {
  TweezersFixture f;
  StepReport r = f.Tick(3.0, true);  // closed in the air: nothing to hold
  EXPECT_EQ(r.tools[0].grasp_atom, -1);
  for (int i = 0; i < 300; ++i) r = f.Tick(1.3, true);  // still closed on contact: no grasp
  EXPECT_GT(r.tools[0].contacts, 0);
  EXPECT_EQ(r.tools[0].grasp_atom, -1);
  r = f.Tick(1.3, false);
  r = f.Tick(1.3, true);  // a fresh closing grasps
  EXPECT_EQ(r.tools[0].grasp_atom, 11);
}

std::pair<int32_t, int32_t> MinMax(int32_t a, int32_t b) { return {std::min(a, b), std::max(a, b)}; }

// A vertical blade (z from 0.5 down to -0.5) drawn along y through x = 2.2, between the top
// atoms at x = 2 and x = 2.5: every element crossing the plane x = 2.2 within the blade's reach
// must go, and nothing else.
void ExpectCutAlongX22(bool full) {
  Model model = GenerateSlab(SlabOptions{});
  const Model before = model;
  StepOptions o;
  o.full = full;
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, o);
  ToolInput in;
  in.num_tools = 1;
  in.tools[0].kind = ToolKind::kScalpel;
  in.tools[0].pos[0] = 2.2, in.tools[0].pos[2] = 0.5;
  in.tools[0].blade[2] = -1.0;
  int32_t removed = 0, dropped = 0;
  uint64_t changes = 0;
  for (int i = 0; i <= 50; ++i) {
    in.tools[0].pos[1] = -1.0 + 6.0 * i / 50;
    Step(model, s, ws, in);
    const EditReport e = ApplyPendingEdits(model, s, ws);
    removed += e.elements_removed;
    dropped += e.triangles_removed;
    changes += e.topology_changed;
  }
  // Expected: elements whose endpoints straddle x = 2.2 and whose crossing point has z >= -0.5.
  std::multiset<std::pair<int32_t, int32_t>> kept;
  int32_t expected_cut = 0;
  for (int32_t e = 0; e < before.num_elems; ++e) {
    const double* p = &before.atom_pos_eq[3 * before.elem_atoms[2 * e]];
    const double* q = &before.atom_pos_eq[3 * before.elem_atoms[2 * e + 1]];
    const bool straddles = (p[0] - 2.2) * (q[0] - 2.2) < 0;
    const double t = straddles ? (2.2 - p[0]) / (q[0] - p[0]) : 0;
    const bool cut = straddles && p[2] + t * (q[2] - p[2]) >= -0.5;
    expected_cut += cut;
    if (!cut) kept.insert(MinMax(before.elem_atoms[2 * e], before.elem_atoms[2 * e + 1]));
  }
  EXPECT_EQ(removed, expected_cut);
  EXPECT_GT(removed, 5);
  ASSERT_EQ(model.num_elems, before.num_elems - removed);
  std::multiset<std::pair<int32_t, int32_t>> now;
  for (int32_t e = 0; e < model.num_elems; ++e)
    now.insert(MinMax(model.elem_atoms[2 * e], model.elem_atoms[2 * e + 1]));
  EXPECT_EQ(now, kept);
  // Triangles that lost an edge are gone; every remaining triangle edge is still an element.
  EXPECT_GT(dropped, 0);
  EXPECT_EQ(model.num_tris, before.num_tris - dropped);
  for (int32_t t = 0; t < model.num_tris; ++t) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(now.count(MinMax(model.tri_atoms[3 * t + c], model.tri_atoms[3 * t + (c + 1) % 3])), 1u);
    }
  }
  // One version bump per edit batch that changed something.
  EXPECT_GT(changes, 0u);
  EXPECT_EQ(model.topology_version, before.topology_version + changes);
}

TEST(ToolScalpel, CutsExactlyTheElementsItsSweepCrossesLocal) { ExpectCutAlongX22(false); }
TEST(ToolScalpel, CutsExactlyTheElementsItsSweepCrossesFull) { ExpectCutAlongX22(true); }

TEST(ToolScalpel, CutTissueOpensUnderASphereWhileTheScalpelCuts) {
  // Two tools at once: a sphere presses at x = 1.5 while a scalpel cuts along x = 2.2.
  Model model = GenerateSlab(SlabOptions{});
  State s = MakeState(model);
  test::WarningGuard warnings(s);
  Workspace ws = MakeWorkspace(model, StepOptions{});
  ToolInput in = SphereAt(1.5, 1.732, 1.2);
  in.num_tools = 2;
  in.tools[1].kind = ToolKind::kScalpel;
  in.tools[1].pos[0] = 2.2, in.tools[1].pos[2] = 0.5;
  in.tools[1].blade[2] = -1.0;
  const uint64_t version = model.topology_version;
  StepReport r;
  for (int i = 0; i < 1000; ++i) {
    in.tools[0].pos[2] = std::max(1.2, 2.0 - i / 500.0);
    in.tools[1].pos[1] = -1.0 + 6.0 * std::min(1.0, i / 500.0);
    r = Step(model, s, ws, in);
    ApplyPendingEdits(model, s, ws);
  }
  EXPECT_GT(model.topology_version, version);
  EXPECT_GT(r.tools[0].force[2], 0.5);
  EXPECT_EQ(r.tools[1].force[2], 0);  // the blade applies no contact force
}

}  // namespace
}  // namespace idms
