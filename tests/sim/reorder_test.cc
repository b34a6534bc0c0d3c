// Tests of ReorderForLocality: a valid renumbering of the same model, the walk order the fused
// pass wants, locality, the same dynamics, and a fem/plg pair that reads back.
#include "idms/sim/reorder.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "idms/sim/generate.h"
#include "idms/sim/model_io.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"

namespace idms {
namespace {

Model Slab() {
  SlabOptions so;
  so.rows = 14, so.cols = 15;
  so.inclusions.push_back(Inclusion{{6, 5, -0.5}, 2.5, 4.0, 2.0});
  return GenerateSlab(so);
}

// Largest |a0 - a1| over the elements.
int32_t Bandwidth(const Model& m) {
  int32_t band = 0;
  for (int32_t e = 0; e < m.num_elems; ++e)
    band = std::max(band, std::abs(m.elem_atoms[2 * e] - m.elem_atoms[2 * e + 1]));
  return band;
}

TEST(Reorder, IsTheSameModelRenumbered) {
  const Model m = Slab();
  Reordering map;
  const Model r = ReorderForLocality(m, {}, &map);
  ASSERT_EQ(r.num_atoms, m.num_atoms);
  ASSERT_EQ(r.num_elems, m.num_elems);
  ASSERT_EQ(r.num_tris, m.num_tris);
  EXPECT_EQ(r.num_external, m.num_external);
  // Bijections, and every atom and element carries its data to its new id.
  std::vector<int32_t> seen(m.num_atoms, 0);
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    const int32_t n = map.atom_new_id[a];
    ASSERT_TRUE(n >= 0 && n < m.num_atoms && !seen[n]++);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(r.atom_pos_eq[3 * n + c], m.atom_pos_eq[3 * a + c]);
    EXPECT_EQ(r.atom_mass[n], m.atom_mass[a]);
    EXPECT_EQ(r.atom_fixed[n], m.atom_fixed[a]);
    EXPECT_EQ(r.atom_external[n], m.atom_external[a]);
  }
  std::vector<int32_t> seen_e(m.num_elems, 0);
  for (int32_t e = 0; e < m.num_elems; ++e) {
    const int32_t n = map.elem_new_id[e];
    ASSERT_TRUE(n >= 0 && n < m.num_elems && !seen_e[n]++);
    EXPECT_EQ(r.elem_atoms[2 * n], map.atom_new_id[m.elem_atoms[2 * e]]);
    EXPECT_EQ(r.elem_atoms[2 * n + 1], map.atom_new_id[m.elem_atoms[2 * e + 1]]);
    EXPECT_EQ(r.elem_k[n], m.elem_k[e]);
    EXPECT_EQ(r.elem_b[n], m.elem_b[e]);
    EXPECT_EQ(r.elem_leq[n], m.elem_leq[e]);
    EXPECT_EQ(r.elem_home[n], m.elem_home[e]);
  }
  for (int32_t i = 0; i < 3 * m.num_tris; ++i) EXPECT_EQ(r.tri_atoms[i], map.atom_new_id[m.tri_atoms[i]]);
}

TEST(Reorder, GivesTheFusedPassItsWalkOrderAndLocality) {
  const Model m = Slab();
  for (const bool atoms : {false, true}) {
    const Model r = ReorderForLocality(m, ReorderOptions{.atoms = atoms});
    StepOptions o;
    o.full = true;
    o.stability.energy_check = false;
    State s = MakeState(r);
    Workspace ws = MakeWorkspace(r, o);
    Step(r, s, ws, ToolInput{});
    EXPECT_TRUE(GetFusedPassStatus(ws).live);
    EXPECT_TRUE(GetFusedPassStatus(ws).identity) << "atoms renumbered: " << atoms;
  }
  // The generator's order ties top atoms to home and apex atoms a third of the model away.
  EXPECT_LT(4 * Bandwidth(ReorderForLocality(m)), Bandwidth(m));
}

TEST(Reorder, SameDynamicsToRounding) {
  // The same press on the original and the renumbered model: only the order of sums differs.
  const Model m = Slab();
  Reordering map;
  const Model r = ReorderForLocality(m, {}, &map);
  StepOptions o;
  o.full = true;
  o.integrator = Integrator::kSymplecticEuler;
  o.stability.energy_check = false;
  State sm = MakeState(m), sr = MakeState(r);
  Workspace wm = MakeWorkspace(m, o), wr = MakeWorkspace(r, o);
  ToolInput in;
  in.num_tools = 1;
  in.tools[0].kind = ToolKind::kSphere;
  double max_force_diff = 0;
  for (int i = 0; i < 600; ++i) {
    in.tools[0].pos[0] = 6, in.tools[0].pos[1] = 5, in.tools[0].pos[2] = 1.8 - 1.0 * std::min(1.0, i / 400.0);
    const StepReport a = Step(m, sm, wm, in), b = Step(r, sr, wr, in);
    max_force_diff = std::max(max_force_diff, std::fabs(a.tools[0].force[2] - b.tools[0].force[2]));
  }
  double max_pos_diff = 0, max_disp = 0;
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    const int32_t n = map.atom_new_id[a];
    for (int c = 0; c < 3; ++c) {
      max_pos_diff = std::max(max_pos_diff, std::fabs(double(sm.atom_pos[3 * a + c]) - sr.atom_pos[3 * n + c]));
      max_disp = std::max(max_disp, std::fabs(sm.atom_pos[3 * a + c] - m.atom_pos_eq[3 * a + c]));
    }
  }
  EXPECT_GT(max_disp, 0.1);
  const double eps = sizeof(Real) == 4 ? 1e-4 : 1e-10;
  EXPECT_LT(max_pos_diff, eps);
  EXPECT_LT(max_force_diff, 1e3 * eps);
}

TEST(Reorder, WritesAFemPlgPairThatReadsBack) {
  const Model r = ReorderForLocality(Slab());
  const std::string prefix = (std::filesystem::path(::testing::TempDir()) / "reordered").string();
  std::string error;
  ASSERT_TRUE(SaveModel(r, prefix, &error)) << error;
  Model back;
  LoadError load_error;
  ASSERT_TRUE(LoadModel(prefix + ".fem", prefix + ".plg", ReadOptions{}, &back, &load_error)) << load_error.ToString();
  EXPECT_EQ(back.num_atoms, r.num_atoms);
  EXPECT_EQ(back.elem_atoms, r.elem_atoms);
  EXPECT_EQ(back.tri_atoms, r.tri_atoms);
}

TEST(ReorderCli, WritesTheRenumberedPairAndRejectsAMissingModel) {
  const std::string bin = IDMS_BIN_DIR "/idms-sim";
  ASSERT_TRUE(std::filesystem::exists(bin)) << bin << " is missing: build the idms-sim target first";
  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) / ("idms_reorder_cli_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string in = (dir / "in").string(), out = (dir / "out").string();
  std::string error;
  ASSERT_TRUE(SaveModel(Slab(), in, &error)) << error;
  auto run = [&](const std::string& args) {
    const int status = std::system(("'" + bin + "' " + args + " >/dev/null 2>&1").c_str());
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  };
  ASSERT_EQ(run("reorder --model '" + in + "' --out '" + out + "'"), 0);
  Model back;
  LoadError load_error;
  ASSERT_TRUE(LoadModel(out + ".fem", out + ".plg", ReadOptions{}, &back, &load_error)) << load_error.ToString();
  EXPECT_EQ(back.elem_atoms, ReorderForLocality(Slab()).elem_atoms);
  EXPECT_NE(run("reorder --model '" + (dir / "missing").string() + "' --out '" + out + "'"), 0);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace idms
