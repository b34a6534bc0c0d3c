// Tests of the Edit API: element removal keeps Model adjacency, surface, State filter arrays and
// Workspace in step (checked against a freshly finalized copy), and versions are followed.
#include "idms/sim/edit.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <set>
#include <utility>
#include <vector>

#include "idms/sim/generate.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "step_test_util.h"
#include "warning_guard.h"

namespace idms {
namespace {

std::pair<int32_t, int32_t> AtomsOf(const Model& m, int32_t e) {
  return {std::min(m.elem_atoms[2 * e], m.elem_atoms[2 * e + 1]),
          std::max(m.elem_atoms[2 * e], m.elem_atoms[2 * e + 1])};
}

std::set<int32_t> ElementsOf(const Model& m, int32_t a) {
  std::set<int32_t> out;
  for (int32_t j = 0; j < m.atom_elem_num[a]; ++j) out.insert(m.atom_elem[m.atom_elem_adr[a] + j]);
  return out;
}

// The adjacency after edits equals what FinalizeModel derives from the edited element list.
void ExpectConsistent(const Model& m, const State& s, const Workspace& ws) {
  Model fresh = m;
  FinalizeModel(fresh);
  ASSERT_EQ(fresh.num_elems, m.num_elems);
  for (int32_t a = 0; a < m.num_atoms; ++a) EXPECT_EQ(ElementsOf(m, a), ElementsOf(fresh, a)) << "atom " << a;
  EXPECT_EQ(m.elem_leq, fresh.elem_leq);
  EXPECT_EQ(m.elem_home, fresh.elem_home);
  EXPECT_EQ(static_cast<int32_t>(s.elem_len.size()), m.num_elems);
  EXPECT_EQ(m.num_tris * 3, static_cast<int32_t>(m.tri_atoms.size()));
  for (int32_t t = 0; t < m.num_tris; ++t) {
    for (int c = 0; c < 3; ++c) {
      const int32_t a = m.tri_atoms[3 * t + c];
      const auto* begin = &ws.atom_tri[ws.atom_tri_adr[a]];
      EXPECT_NE(std::find(begin, begin + ws.atom_tri_num[a], t), begin + ws.atom_tri_num[a]);
    }
  }
  for (int32_t e = 0; e < m.num_elems; ++e) EXPECT_EQ(ws.elem_cut[e], 0);
}

TEST(Edit, RemovingElementsKeepsEverythingInStep) {
  Model m = GenerateSlab(SlabOptions{});
  State s = MakeState(m);
  Workspace ws = MakeWorkspace(m, StepOptions{});
  // Give every element a distinct filter state to check it travels with its element.
  for (int32_t e = 0; e < m.num_elems; ++e) s.elem_rate[e] = static_cast<Real>(1000 + e);
  std::vector<std::pair<int32_t, int32_t>> removed;
  int32_t tris = 0;
  for (int32_t e : {0, 17, 140 - 3, 60, 5}) {
    const std::pair<int32_t, int32_t> pair = AtomsOf(m, e);
    const int32_t last = m.num_elems - 1;
    const Real last_rate = s.elem_rate[last];
    tris += RemoveElement(m, s, ws, e);
    removed.push_back(pair);
    if (e != last) {
      EXPECT_EQ(s.elem_rate[e], last_rate);  // the last element moved into slot e
    }
  }
  EXPECT_EQ(m.num_elems, 141 - 5);
  EXPECT_GT(tris, 0);
  for (int32_t e = 0; e < m.num_elems; ++e) {
    EXPECT_EQ(std::count(removed.begin(), removed.end(), AtomsOf(m, e)), 0);
  }
  ExpectConsistent(m, s, ws);
}

TEST(Edit, ApplyPendingEditsBumpsTheVersionOnlyWhenSomethingChanged) {
  Model m = GenerateSlab(SlabOptions{});
  State s = MakeState(m);
  test::WarningGuard warnings(s);
  Workspace ws = MakeWorkspace(m, StepOptions{});
  EXPECT_FALSE(ApplyPendingEdits(m, s, ws).topology_changed);
  EXPECT_EQ(m.topology_version, 0u);
  // A scalpel sweep across the middle of the fragment.
  ToolInput in;
  in.num_tools = 1;
  in.tools[0].kind = ToolKind::kScalpel;
  in.tools[0].pos[0] = 1.7, in.tools[0].pos[1] = -1, in.tools[0].pos[2] = 0.3;
  in.tools[0].blade[2] = -0.6;
  Step(m, s, ws, in);
  in.tools[0].pos[1] = 5;
  const StepReport r = Step(m, s, ws, in);
  ASSERT_GT(r.tools[0].cut_elements, 0);
  EXPECT_EQ(r.pending_cuts, r.tools[0].cut_elements);
  const EditReport e = ApplyPendingEdits(m, s, ws);
  EXPECT_EQ(e.elements_removed, r.tools[0].cut_elements);
  EXPECT_TRUE(e.topology_changed);
  EXPECT_EQ(m.topology_version, 1u);
  EXPECT_EQ(ws.topology_version, 1u);
  ExpectConsistent(m, s, ws);
  // Stepping continues on the edited model.
  for (int i = 0; i < 500; ++i) Step(m, s, ws, test::SphereAt(1.5, 1.732, 2.0 - 0.8 * i / 500));
}

TEST(EditDeathTest, AStaleWorkspaceIsABug) {
  Model m = GenerateSlab(SlabOptions{});
  State s = MakeState(m);
  Workspace ws = MakeWorkspace(m, StepOptions{});
  ++m.topology_version;  // edited behind the workspace's back
  EXPECT_DEATH(Step(m, s, ws, ToolInput{}), "topology_version");
}

}  // namespace
}  // namespace idms
