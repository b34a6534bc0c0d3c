// Draping (thesis 5.6.1): the form's force law, the step's external-force input it runs on,
// stripping and adding home elements, and a whole drape that must end on the sphere, at rest,
// hardened with a home element per external atom and saved as a model that loads back the same.
#include "idms/sim/drape.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <vector>

#include "alloc_counter.h"
#include "idms/sim/generate.h"
#include "idms/sim/model_io.h"
#include "idms/sim/summary.h"
#include "idms/sim/workspace.h"
#include "warning_guard.h"

namespace idms {
namespace {

double Norm(const double* v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

TEST(SphereFormForce, AttractsOutsideAndPushesOutDampedInside) {
  SphereForm form;
  form.center[0] = 1, form.center[1] = 2, form.center[2] = 3;
  form.radius = 2, form.k_out = 3, form.k_in = 50, form.b = 0.5;
  // Outside at r = 5 along +x: -k_f^o (r - R_f) d^, whatever the velocity.
  const Real out_p[3] = {6, 2, 3}, v[3] = {1, -2, 4};
  Real f[3] = {0.5, 0, 0};  // adds to what is there
  double energy = AddSphereFormForce(form, out_p, v, f);
  EXPECT_DOUBLE_EQ(f[0], 0.5 - 3 * 3);
  EXPECT_EQ(f[1], 0);
  EXPECT_EQ(f[2], 0);
  EXPECT_DOUBLE_EQ(energy, 0.5 * 3 * 9);
  // Inside at r = 1.5 along -z: k_f^i (R_f - r) d^ - b_f v.
  const Real in_p[3] = {1, 2, 1.5};
  Real g[3] = {0, 0, 0};
  energy = AddSphereFormForce(form, in_p, v, g);
  EXPECT_DOUBLE_EQ(g[0], -0.5 * 1);
  EXPECT_DOUBLE_EQ(g[1], -0.5 * -2);
  EXPECT_DOUBLE_EQ(g[2], -50 * 0.5 - 0.5 * 4);
  EXPECT_DOUBLE_EQ(energy, 0.5 * 50 * 0.25);
  // On the surface: no force, no energy.
  const Real on_p[3] = {1, 4, 3}, still[3] = {0, 0, 0};
  Real h[3] = {0, 0, 0};
  EXPECT_EQ(AddSphereFormForce(form, on_p, still, h), 0);
  EXPECT_EQ(h[0], 0);
  EXPECT_EQ(h[1], 0);
  EXPECT_EQ(h[2], 0);
}

TEST(StripHomeElements, RemovesHomeAtomsAndElementsKeepsTheRest) {
  const Model slab = GenerateSlab(SlabOptions{});  // 58 atoms, 141 elements, 22 home
  const Model bare = StripHomeElements(slab);
  EXPECT_EQ(bare.num_atoms, 58 - 22);
  EXPECT_EQ(bare.num_elems, 141 - 22);
  EXPECT_EQ(bare.num_external, 22);
  EXPECT_EQ(bare.num_tris, 28);
  for (int32_t a = 0; a < bare.num_atoms; ++a) EXPECT_FALSE(bare.atom_fixed[a]);
  for (uint8_t h : bare.elem_home) EXPECT_EQ(h, 0);
  // Atom order is kept (top atoms come first in the generator's order), so the surface is too.
  for (int32_t i = 0; i < 22; ++i) {
    for (int c = 0; c < 3; ++c) EXPECT_EQ(bare.atom_pos_eq[3 * i + c], slab.atom_pos_eq[3 * i + c]);
  }
  EXPECT_EQ(bare.tri_atoms, slab.tri_atoms);
  // Nothing to strip: the same model.
  const Model again = StripHomeElements(bare);
  EXPECT_EQ(again.num_atoms, bare.num_atoms);
  EXPECT_EQ(again.elem_atoms, bare.elem_atoms);
}

// The step's external-force input: a uniform force on a free slab (no home elements) is a pure
// translation the elements do not resist, so every atom accelerates at F / m; empty = nothing.
class ExternalForces : public ::testing::TestWithParam<Integrator> {};

TEST_P(ExternalForces, UniformForceAcceleratesEveryAtomWithoutAllocating) {
  const Model bare = StripHomeElements(GenerateSlab(SlabOptions{}));
  StepOptions o;
  o.full = true;
  o.integrator = GetParam();
  o.dt_s = 1e-3;
  o.stability.energy_check = false;  // the force does work the check cannot see
  State s = MakeState(bare);
  test::WarningGuard warnings(s);
  Workspace ws = MakeWorkspace(bare, o);
  // Without the input the free slab stays exactly at rest.
  Step(bare, s, ws, ToolInput{});
  for (int32_t i = 0; i < 3 * bare.num_atoms; ++i) ASSERT_EQ(s.atom_pos[i], bare.atom_pos_eq[i]);
  ws.atom_force_external.assign(3 * bare.num_atoms, Real(0));
  const double force[3] = {0.002, -0.004, 0.001};  // m = 0.002: a = (1, -2, 0.5)
  for (int32_t a = 0; a < bare.num_atoms; ++a) {
    for (int c = 0; c < 3; ++c) ws.atom_force_external[3 * a + c] = static_cast<Real>(force[c]);
  }
  const int64_t before = test::AllocationCount();
  const int ticks = 100;
  for (int i = 0; i < ticks; ++i) Step(bare, s, ws, ToolInput{});
  EXPECT_EQ(test::AllocationCount() - before, 0);
  for (int32_t a = 0; a < bare.num_atoms; ++a) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(s.atom_vel[3 * a + c], ticks * o.dt_s * force[c] / 0.002, 1e-6) << "atom " << a << " axis " << c;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Integrators, ExternalForces,
                         ::testing::Values(Integrator::kExplicitEuler, Integrator::kSymplecticEuler, Integrator::kRk4,
                                           Integrator::kImplicitEuler),
                         [](const auto& param_info) { return std::string(IntegratorName(param_info.param)); });

TEST(HardenDrape, RestPositionsFromStateAndAHomeElementPerExternalAtom) {
  const Model bare = StripHomeElements(GenerateSlab(SlabOptions{}));
  State s = MakeState(bare);
  for (int32_t i = 0; i < 3 * bare.num_atoms; ++i) s.atom_pos[i] += static_cast<Real>(0.123456 * (i % 7));
  const Model hard = HardenDrape(bare, s, 20, 0.3, 3, "hard");
  EXPECT_EQ(hard.name, "hard");
  ASSERT_EQ(hard.num_atoms, bare.num_atoms + bare.num_external);
  ASSERT_EQ(hard.num_elems, bare.num_elems + bare.num_external);
  for (int32_t i = 0; i < 3 * bare.num_atoms; ++i) {
    EXPECT_EQ(hard.atom_pos_eq[i], std::round(s.atom_pos[i] * 1000) / 1000);
  }
  int32_t homes = 0;
  for (int32_t e = 0; e < hard.num_elems; ++e) {
    if (!hard.elem_home[e]) continue;
    ++homes;
    const int32_t a = hard.elem_atoms[2 * e], h = hard.elem_atoms[2 * e + 1];
    EXPECT_TRUE(hard.atom_external[a]);
    EXPECT_TRUE(hard.atom_fixed[h]);
    EXPECT_EQ(hard.elem_leq[e], 0);
    EXPECT_EQ(hard.elem_k[e], 20);
    EXPECT_EQ(hard.elem_b[e], 0.3);
  }
  EXPECT_EQ(homes, bare.num_external);
  EXPECT_EQ(hard.tri_atoms, bare.tri_atoms);
}

// A small drape, shared by the tests below (it takes well under a second).
class SmallDrape : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    SlabOptions slab;
    slab.rows = 9, slab.cols = 8;
    options_ = new DrapeOptions;
    options_->form.radius = 6;
    options_->form.center[0] = 1, options_->form.center[1] = -2, options_->form.center[2] = 0.5;
    options_->name = "cap";
    progress_ = new std::vector<DrapeProgress>;
    result_ =
        new DrapeResult(Drape(GenerateSlab(slab), *options_, [](const DrapeProgress& p) { progress_->push_back(p); }));
  }
  static void TearDownTestSuite() {
    delete options_;
    delete result_;
    delete progress_;
  }
  static DrapeOptions* options_;
  static DrapeResult* result_;
  static std::vector<DrapeProgress>* progress_;
};
DrapeOptions* SmallDrape::options_ = nullptr;
DrapeResult* SmallDrape::result_ = nullptr;
std::vector<DrapeProgress>* SmallDrape::progress_ = nullptr;

TEST_F(SmallDrape, SettlesWithFallingEnergyAndReportsProgress) {
  const DrapeResult& r = *result_;
  EXPECT_TRUE(r.settled);
  EXPECT_LT(r.time_s, options_->max_time_s);
  EXPECT_LT(r.kinetic, options_->settle_kinetic);
  EXPECT_LT(r.max_speed, options_->settle_speed);
  EXPECT_EQ(r.warnings, 0);
  // The form's potential turns into motion the dampers drain: energy only falls (within the
  // explicit scheme's small per-step error), and ends far below where it started.
  EXPECT_LT(r.energy_end, 0.5 * r.energy_start);
  EXPECT_EQ(r.energy_max, r.energy_start);
  ASSERT_GE(progress_->size(), 3u);
  for (size_t i = 1; i < progress_->size(); ++i) {
    EXPECT_GT((*progress_)[i].time_s, (*progress_)[i - 1].time_s);
    EXPECT_LE((*progress_)[i].energy, (*progress_)[i - 1].energy * (1 + 1e-6) + 1e-9) << "report " << i;
  }
  EXPECT_TRUE(progress_->back().settled);
  EXPECT_EQ(progress_->front().time_s, 0);
}

TEST_F(SmallDrape, LiesOnTheSphereWithoutFolds) {
  const DrapeResult& r = *result_;
  const SphereForm& form = options_->form;
  // The lower layer rests on the form (sunk in by less than its k_in allows), the surface one
  // layer thickness (0.816 before the attraction squeezed it) further out.
  EXPECT_GT(r.internal_min, -0.05);
  EXPECT_LT(r.internal_max, 0.05);
  EXPECT_GT(r.external_min, 0.6);
  EXPECT_LT(r.external_max, 0.9);
  EXPECT_EQ(r.folded_triangles, 0);
  // The same from the saved rest positions: every free atom near R_f (+ thickness if external).
  const Model& m = r.model;
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    const double* p = &m.atom_pos_eq[3 * a];
    const double d[3] = {p[0] - form.center[0], p[1] - form.center[1], p[2] - form.center[2]};
    const double gap = Norm(d) - form.radius;
    if (m.atom_external[a]) {
      EXPECT_NEAR(gap, 0.75, 0.15) << "external atom " << a;
    } else if (!m.atom_fixed[a]) {
      EXPECT_NEAR(gap, 0, 0.05) << "internal atom " << a;
    }
  }
}

TEST_F(SmallDrape, HardenedWithAHomeElementPerExternalAtomAndAtRest) {
  const Model& m = result_->model;
  const Model bare = StripHomeElements(GenerateSlab(SlabOptions{.rows = 9, .cols = 8}));
  EXPECT_EQ(m.name, "cap");
  EXPECT_EQ(m.num_external, bare.num_external);
  EXPECT_EQ(m.num_atoms, bare.num_atoms + bare.num_external);
  EXPECT_EQ(m.tri_atoms, bare.tri_atoms);
  std::vector<int> homes(m.num_atoms, 0);
  for (int32_t e = 0; e < m.num_elems; ++e) {
    if (m.elem_home[e]) ++homes[m.elem_atoms[2 * e]];
  }
  for (int32_t a : m.external_atoms) EXPECT_EQ(homes[a], 1) << "external atom " << a;
  // The equilibrium is the new rest shape: full steps of the hardened model move nothing (but
  // rounding: the step forms k (1 - l_eq / l) as k (1 - l_eq * (1 / l)), which is not always 0
  // at l = l_eq).
  StepOptions o;
  o.full = true;
  State s = MakeState(m);
  Workspace ws = MakeWorkspace(m, o);
  for (int i = 0; i < 50; ++i) Step(m, s, ws, ToolInput{});
  for (int32_t i = 0; i < 3 * m.num_atoms; ++i) ASSERT_NEAR(s.atom_pos[i], m.atom_pos_eq[i], 1e-12);
}

TEST_F(SmallDrape, RoundTripsThroughFiles) {
  const std::string prefix = (std::filesystem::path(::testing::TempDir()) / "drape_cap").string();
  std::string error;
  ASSERT_TRUE(SaveModel(result_->model, prefix, &error)) << error;
  Model loaded;
  LoadError load_error;
  ASSERT_TRUE(LoadModel(prefix + ".fem", prefix + ".plg", {}, &loaded, &load_error)) << load_error.ToString();
  EXPECT_EQ(loaded.atom_pos_eq, result_->model.atom_pos_eq);
  EXPECT_EQ(loaded.elem_atoms, result_->model.elem_atoms);
  EXPECT_EQ(loaded.elem_leq, result_->model.elem_leq);
  EXPECT_EQ(loaded.tri_atoms, result_->model.tri_atoms);
  EXPECT_EQ(Summarize(loaded).home_elements, result_->model.num_external);
  EXPECT_EQ(WriteFem(loaded), WriteFem(result_->model));
  std::filesystem::remove(prefix + ".fem");
  std::filesystem::remove(prefix + ".plg");
}

TEST(Drape, DeterministicAndStableStepBoundShrinksWithTheForm) {
  SlabOptions slab;
  slab.rows = 5, slab.cols = 4;
  DrapeOptions o;
  o.form.radius = 5;
  o.max_time_s = 0.5;
  const Model a = Drape(GenerateSlab(slab), o).model, b = Drape(GenerateSlab(slab), o).model;
  EXPECT_EQ(WriteFem(a), WriteFem(b));
  const Model bare = StripHomeElements(GenerateSlab(slab));
  SphereForm soft = o.form, stiff = o.form;
  stiff.k_in = 100 * soft.k_in;
  EXPECT_LT(DrapeStableDt(bare, stiff, o.step), DrapeStableDt(bare, soft, o.step));
  EXPECT_GE(DrapeStableDt(bare, soft, o.step), o.step.dt_s);  // the default tick is stable
}

TEST(Drape, OnTwoThreadsTheRenumberedSlabGivesTheSameDrape) {
  // Stage 2 on two threads runs the slab renumbered (the sections need it) and maps the end state
  // back: the same slab within rounding of the sums' order, in the slab's own numbering.
  SlabOptions slab;
  slab.rows = 16, slab.cols = 16;
  DrapeOptions o;
  o.form.radius = 8;
  o.max_time_s = 0.6;
  const DrapeResult one = Drape(GenerateSlab(slab), o);
  o.step.threads = 2;
  const DrapeResult two = Drape(GenerateSlab(slab), o);
  EXPECT_EQ(two.warnings, 0);
  ASSERT_EQ(two.model.num_atoms, one.model.num_atoms);
  ASSERT_EQ(two.model.num_elems, one.model.num_elems);
  double max_diff = 0, travel = 0;
  for (size_t i = 0; i < one.model.atom_pos_eq.size(); ++i) {
    max_diff = std::max(max_diff, std::fabs(two.model.atom_pos_eq[i] - one.model.atom_pos_eq[i]));
  }
  const Model start = GenerateSlab(slab);
  for (int32_t a = 0; a < start.num_atoms && a < one.model.num_atoms; ++a) {
    travel = std::max(travel, std::fabs(one.model.atom_pos_eq[3 * a + 2] - start.atom_pos_eq[3 * a + 2]));
  }
  EXPECT_GT(travel, 0.5) << "the slab did not drape";
  EXPECT_LT(max_diff, 2e-3) << "of " << travel;
  EXPECT_EQ(two.model.elem_atoms, one.model.elem_atoms) << "the slab's own numbering";
}

}  // namespace
}  // namespace idms
