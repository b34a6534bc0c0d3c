// Tests of the haptic window (sim/src/active_set.cc, thesis 5.5.2): which atoms move, which may
// touch a tool and which elements get forces, against the distances to the tool computed here;
// the settling and waking of atoms at the window's edge; and the between-steps invariant.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

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

using internal::BuildActiveSet;
using internal::ClearTickScratch;
using internal::WakeNeighbours;

double Dist(const State& s, int32_t a, const double c[3]) {
  const double dx = s.atom_pos[3 * a] - c[0], dy = s.atom_pos[3 * a + 1] - c[1], dz = s.atom_pos[3 * a + 2] - c[2];
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

std::vector<int32_t> List(const std::vector<int32_t>& buffer, int32_t n) {
  return std::vector<int32_t>(buffer.begin(), buffer.begin() + n);
}

// The slab of figure 3-1 with its Workspace filed at the State's positions and one tool resolved.
struct Window {
  Model model = GenerateSlab(SlabOptions{});
  State state = MakeState(model);
  StepOptions options;
  Workspace ws;

  explicit Window(double local_radius = 2.25) {
    options.local_radius = local_radius;
    ws = MakeWorkspace(model, options);
    ResyncWorkspace(model, state, ws);
  }
  void Tool(const ToolInput& input) {
    StepReport report;
    internal::ResolveTools(model, state, ws, input, &report);
  }
};

// Every per-atom and per-element mark at its between-steps value (Workspace's invariant).
void ExpectClean(const Workspace& ws) {
  EXPECT_EQ(ws.num_active, 0);
  EXPECT_EQ(ws.num_candidates, 0);
  EXPECT_EQ(ws.num_elems, 0);
  EXPECT_EQ(ws.num_boundary, 0);
  EXPECT_EQ(std::count(ws.atom_mark.begin(), ws.atom_mark.end(), 0), static_cast<int64_t>(ws.atom_mark.size()));
  EXPECT_EQ(std::count(ws.atom_cand.begin(), ws.atom_cand.end(), 0), static_cast<int64_t>(ws.atom_cand.size()));
  EXPECT_EQ(std::count(ws.atom_slot.begin(), ws.atom_slot.end(), -1), static_cast<int64_t>(ws.atom_slot.size()));
  EXPECT_EQ(std::count(ws.atom_extra_k.begin(), ws.atom_extra_k.end(), 0.0),
            static_cast<int64_t>(ws.atom_extra_k.size()));
  EXPECT_EQ(std::count(ws.elem_mark.begin(), ws.elem_mark.end(), 0), static_cast<int64_t>(ws.elem_mark.size()));
}

// Thesis 5.5.2: the free atoms within r_l of the MIO move, the external ones among them may touch
// it, and the elements with a moving endpoint get forces; all in id order, with slots.
TEST(ActiveSet, MembershipIsTheDistanceToTheTool) {
  for (double r_l : {1.0, 2.25, 3.5}) {
    SCOPED_TRACE(r_l);
    Window w(r_l);
    const double c[3] = {2.2, 1.9, 0.8};
    w.Tool(test::SphereAt(c[0], c[1], c[2]));  // r = 1.5
    BuildActiveSet(w.model, w.state, w.ws);
    const double reach = std::max(r_l, 1.5);  // the window is at least the MIO
    std::vector<int32_t> active, candidates;
    for (int32_t a = 0; a < w.model.num_atoms; ++a) {
      if (Dist(w.state, a, c) > reach) continue;
      if (!w.model.atom_fixed[a]) active.push_back(a);
      if (w.model.atom_external[a]) candidates.push_back(a);
    }
    ASSERT_FALSE(active.empty());
    EXPECT_EQ(List(w.ws.active, w.ws.num_active), active);
    EXPECT_EQ(List(w.ws.candidates, w.ws.num_candidates), candidates);
    EXPECT_EQ(List(w.state.active_atoms, w.state.num_active), active) << "handed to the next tick";
    for (int32_t i = 0; i < w.ws.num_active; ++i) EXPECT_EQ(w.ws.atom_slot[w.ws.active[i]], i);
    std::vector<int32_t> elems;
    for (int32_t e = 0; e < w.model.num_elems; ++e) {
      const int32_t a0 = w.model.elem_atoms[2 * e], a1 = w.model.elem_atoms[2 * e + 1];
      if (std::binary_search(active.begin(), active.end(), a0) || std::binary_search(active.begin(), active.end(), a1))
        elems.push_back(e);
    }
    std::vector<int32_t> listed = List(w.ws.elems, w.ws.num_elems);
    std::sort(listed.begin(), listed.end());
    EXPECT_EQ(listed, elems) << "each element with an active endpoint, once";
    ClearTickScratch(w.ws);
    ExpectClean(w.ws);
  }
}

TEST(ActiveSet, TheBoundaryOfTheWindowIsInclusive) {
  // Atom 1 of the spring sits at exactly r_l = 2 from a tool at the origin's side: inside; the
  // same tool 1e-9 further: outside.
  const Model model = test::OneSpring(15, 0.2, 0.002, /*leq=*/1.0);
  State s = MakeState(model);
  StepOptions o;
  o.local_radius = 2.0;
  Workspace ws = MakeWorkspace(model, o);
  ResyncWorkspace(model, s, ws);
  StepReport report;
  internal::ResolveTools(model, s, ws, test::SphereAt(3.0, 0, 0, /*r=*/0.5), &report);
  BuildActiveSet(model, s, ws);
  EXPECT_EQ(List(ws.active, ws.num_active), std::vector<int32_t>{1});
  EXPECT_EQ(List(ws.candidates, ws.num_candidates), std::vector<int32_t>{1});
  ClearTickScratch(ws);
  s.num_active = 0;  // not last tick's atom either
  internal::ResolveTools(model, s, ws, test::SphereAt(3.0 + 1e-9, 0, 0, 0.5), &report);
  BuildActiveSet(model, s, ws);
  EXPECT_EQ(ws.num_active, 0);
  EXPECT_EQ(ws.num_candidates, 0);
  EXPECT_EQ(ws.num_elems, 0);
  ClearTickScratch(ws);
}

TEST(ActiveSet, AScalpelMovesTheAtomsNearItsBlade) {
  Window w(1.0);
  ToolInput in;
  in.num_tools = 1;
  in.tools[0].kind = ToolKind::kScalpel;
  in.tools[0].pos[0] = 2.2, in.tools[0].pos[1] = 1.7, in.tools[0].pos[2] = 0.5;
  in.tools[0].blade[2] = -1.0;  // the blade runs from z = 0.5 down to z = -0.5
  w.Tool(in);
  BuildActiveSet(w.model, w.state, w.ws);
  std::vector<int32_t> active;
  for (int32_t a = 0; a < w.model.num_atoms; ++a) {
    if (w.model.atom_fixed[a]) continue;
    const Real* p = &w.state.atom_pos[3 * a];
    const double z = std::clamp(double(p[2]), -0.5, 0.5);  // nearest point of the blade
    const double d = std::sqrt((p[0] - 2.2) * (p[0] - 2.2) + (p[1] - 1.7) * (p[1] - 1.7) + (p[2] - z) * (p[2] - z));
    if (d <= 1.0) active.push_back(a);
  }
  ASSERT_FALSE(active.empty());
  EXPECT_EQ(List(w.ws.active, w.ws.num_active), active);
  EXPECT_EQ(w.ws.num_candidates, 0) << "a scalpel presses on nothing";
  ClearTickScratch(w.ws);
}

TEST(ActiveSet, PendingCutsGetNoForces) {
  Window w;
  w.Tool(test::SphereAt(2.5, 1.732, 1.0));
  BuildActiveSet(w.model, w.state, w.ws);
  ASSERT_GT(w.ws.num_elems, 0);
  const int32_t cut = w.ws.elems[0];
  ClearTickScratch(w.ws);
  w.ws.elem_cut[cut] = 1;
  BuildActiveSet(w.model, w.state, w.ws);
  const std::vector<int32_t> listed = List(w.ws.elems, w.ws.num_elems);
  EXPECT_EQ(std::count(listed.begin(), listed.end(), cut), 0);
  ClearTickScratch(w.ws);
  w.ws.elem_cut[cut] = 0;
}

TEST(ActiveSet, FullModeMovesEveryFreeAtom) {
  const Model model = GenerateSlab(SlabOptions{});
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, test::FullOptions(Integrator::kExplicitEuler, 1e-3));
  BuildActiveSet(model, s, ws);
  std::vector<int32_t> free, external, elems;
  for (int32_t a = 0; a < model.num_atoms; ++a) {
    if (!model.atom_fixed[a]) free.push_back(a);
    if (model.atom_external[a]) external.push_back(a);
  }
  for (int32_t e = 0; e < model.num_elems; ++e) {
    if (!model.atom_fixed[model.elem_atoms[2 * e]] || !model.atom_fixed[model.elem_atoms[2 * e + 1]])
      elems.push_back(e);
  }
  EXPECT_EQ(List(ws.active, ws.num_active), free);
  EXPECT_EQ(List(ws.candidates, ws.num_candidates), external);
  std::vector<int32_t> listed = List(ws.elems, ws.num_elems);
  std::sort(listed.begin(), listed.end());
  EXPECT_EQ(listed, elems);
  ClearTickScratch(ws);
  ExpectClean(ws);
}

// Atoms that left the window keep moving while unsettled, for at most settle_time_s; a settled
// one is immobilised (v = 0 exactly) at once.
TEST(ActiveSet, AtomsLeavingTheWindowLingerWhileUnsettled) {
  Window w;
  const int32_t linger = static_cast<int32_t>(std::ceil(w.options.settle_time_s / w.options.dt_s - 1e-9));
  w.Tool(test::SphereAt(2.5, 1.732, 1.0));
  BuildActiveSet(w.model, w.state, w.ws);
  ASSERT_GE(w.ws.num_active, 2);
  const int32_t moving = w.ws.active[0], still = w.ws.active[1];
  EXPECT_EQ(w.state.atom_linger[moving], linger);
  ClearTickScratch(w.ws);
  // The tool leaves; one atom is fast (above settle_speed), one slow (below it), at rest lengths.
  w.state.atom_vel[3 * moving] = 10 * w.options.settle_speed;
  w.state.atom_vel[3 * still + 1] = 0.5 * w.options.settle_speed;
  w.Tool(test::SphereAt(50, 50, 50));
  BuildActiveSet(w.model, w.state, w.ws);
  EXPECT_EQ(List(w.ws.active, w.ws.num_active), std::vector<int32_t>{moving});
  EXPECT_EQ(w.state.atom_linger[moving], linger - 1);
  EXPECT_EQ(w.state.atom_vel[3 * still + 1], 0) << "settled: immobilised";
  EXPECT_EQ(w.state.atom_linger[still], 0);
  ClearTickScratch(w.ws);
  // Its linger spent, even a moving atom is immobilised.
  w.state.atom_linger[moving] = 0;
  BuildActiveSet(w.model, w.state, w.ws);
  EXPECT_EQ(w.ws.num_active, 0);
  EXPECT_EQ(w.state.atom_vel[3 * moving], 0);
  ClearTickScratch(w.ws);
}

// A frozen free atom next to the window that moves faster than settle_speed is listed for the
// next tick; one at rest is not. (A velocity, not a displacement: that would unsettle its
// neighbours' forces too.)
TEST(ActiveSet, WakeNeighboursListsUnsettledAtomsNextToTheWindow) {
  Window w(1.0);
  w.Tool(test::SphereAt(0, 0, 1.0));  // over top atom 0, the corner
  BuildActiveSet(w.model, w.state, w.ws);
  const std::vector<int32_t> active = List(w.ws.active, w.ws.num_active);
  // The free endpoints of the active elements outside the window.
  std::vector<int32_t> boundary;
  for (int32_t i = 0; i < w.ws.num_elems; ++i) {
    for (int c = 0; c < 2; ++c) {
      const int32_t b = w.model.elem_atoms[2 * w.ws.elems[i] + c];
      if (!w.model.atom_fixed[b] && !std::binary_search(active.begin(), active.end(), b)) boundary.push_back(b);
    }
  }
  std::sort(boundary.begin(), boundary.end());
  boundary.erase(std::unique(boundary.begin(), boundary.end()), boundary.end());
  ASSERT_GE(boundary.size(), 2u);
  const int32_t moving_out = boundary[0];
  w.state.atom_vel[3 * moving_out + 2] = -2 * w.options.settle_speed;
  const int32_t listed_before = w.state.num_active;
  WakeNeighbours(w.model, w.state, w.ws);
  ASSERT_EQ(w.state.num_active, listed_before + 1) << "only the moving_out atom wakes";
  EXPECT_EQ(w.state.active_atoms[listed_before], moving_out);
  EXPECT_EQ(w.state.atom_linger[moving_out],
            static_cast<int32_t>(std::ceil(w.options.settle_time_s / w.options.dt_s - 1e-9)));
  std::vector<int32_t> checked = List(w.ws.boundary, w.ws.num_boundary);
  std::sort(checked.begin(), checked.end());
  EXPECT_EQ(checked, boundary) << "each boundary atom checked once";
  for (int32_t b : boundary) EXPECT_EQ(w.ws.atom_mark[b], 2);
  ClearTickScratch(w.ws);
  ExpectClean(w.ws);
  // The next build keeps it while it is unsettled.
  w.Tool(test::SphereAt(0, 0, 1.0));
  BuildActiveSet(w.model, w.state, w.ws);
  const std::vector<int32_t> next = List(w.ws.active, w.ws.num_active);
  EXPECT_TRUE(std::binary_search(next.begin(), next.end(), moving_out));
  ClearTickScratch(w.ws);
}

TEST(ActiveSet, TheThesisWindowWakesNothing) {
  Window w(1.0);
  w.options.settle_time_s = 0;
  w.options.wake_neighbours = false;
  w.ws = MakeWorkspace(w.model, w.options);
  ResyncWorkspace(w.model, w.state, w.ws);
  for (int32_t a = 0; a < w.model.num_atoms; ++a) w.state.atom_pos[3 * a + 2] -= 0.05 * (a % 3);
  w.Tool(test::SphereAt(0, 0, 1.0));
  BuildActiveSet(w.model, w.state, w.ws);
  const int32_t listed = w.state.num_active;
  WakeNeighbours(w.model, w.state, w.ws);
  EXPECT_EQ(w.state.num_active, listed);
  EXPECT_EQ(w.ws.num_boundary, 0);
  ClearTickScratch(w.ws);
}

// ClearTickScratch restores the invariant whatever the tick left (tool stiffness on candidates,
// wake marks), so that the next tick's lists start empty; Step relies on it.
TEST(ActiveSet, ClearTickScratchRestoresTheBetweenStepsInvariant) {
  Window w;
  w.Tool(test::SphereAt(2.5, 1.732, 0.5));
  BuildActiveSet(w.model, w.state, w.ws);
  ASSERT_GT(w.ws.num_candidates, 0);
  for (int32_t i = 0; i < w.ws.num_candidates; ++i) w.ws.atom_extra_k[w.ws.candidates[i]] = 400;
  WakeNeighbours(w.model, w.state, w.ws);
  ClearTickScratch(w.ws);
  ExpectClean(w.ws);
  // And a Step through the same workspace still steps, with no warning.
  test::WarningGuard warnings(w.state);
  w.state.num_active = 0;
  const StepReport r = Step(w.model, w.state, w.ws, test::SphereAt(2.5, 1.732, 1.49));  // a light touch
  EXPECT_GT(r.active_atoms, 0);
  EXPECT_GT(r.tools[0].contacts, 0);
}

}  // namespace
}  // namespace idms
