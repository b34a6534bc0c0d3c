// The slab generator against thesis appendix B.1.2 and figure 3-1.
#include "idms/sim/generate.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <utility>

#include "idms/sim/model_io.h"
#include "idms/sim/summary.h"

namespace idms {
namespace {

// hex_4x5_home.plg exactly as printed in appendix B.1.2 (including its stray blank line).
constexpr const char* kAppendixPlg = R"(hex 22 28

0.500 0.000 0.000
1.500 0.000 0.000
2.500 0.000 0.000
3.500 0.000 0.000
0.000 0.866 0.000
1.000 0.866 0.000
2.000 0.866 0.000
3.000 0.866 0.000
4.000 0.866 0.000
0.500 1.732 0.000
1.500 1.732 0.000
2.500 1.732 0.000
3.500 1.732 0.000
0.000 2.598 0.000
1.000 2.598 0.000
2.000 2.598 0.000
3.000 2.598 0.000
4.000 2.598 0.000
0.500 3.464 0.000
1.500 3.464 0.000
2.500 3.464 0.000
3.500 3.464 0.000

3 0 1 5
3 1 2 6
3 2 3 7
3 4 5 9
3 5 4 0
3 5 6 10
3 6 5 1
3 6 7 11
3 7 6 2
3 7 8 12
3 8 7 3
3 9 10 14
3 10 9 5
3 10 11 15
3 11 10 6
3 11 12 16
3 12 11 7

3 13 14 18
3 14 13 9
3 14 15 19
3 15 14 10
3 15 16 20
3 16 15 11
3 16 17 21
3 17 16 12
3 18 14 19
3 19 15 20
3 20 16 21
)";

double Dist(const Model& m, int32_t a, int32_t b) {
  double d2 = 0;
  for (int c = 0; c < 3; ++c) d2 += std::pow(m.atom_pos_eq[3 * a + c] - m.atom_pos_eq[3 * b + c], 2);
  return std::sqrt(d2);
}

TEST(GenerateSlab, ReproducesAppendixSurfaceExactly) {
  const Model model = GenerateSlab(SlabOptions{});
  SurfaceMesh appendix;
  LoadError error;
  ASSERT_TRUE(ParsePlg(kAppendixPlg, "appendix.plg", &appendix, &error)) << error.ToString();

  ASSERT_EQ(model.num_external, appendix.num_verts());
  for (int32_t v = 0; v < appendix.num_verts(); ++v) {
    for (int c = 0; c < 3; ++c)
      EXPECT_EQ(model.atom_pos_eq[3 * model.external_atoms[v] + c], appendix.vert_pos[3 * v + c]);
  }
  ASSERT_EQ(model.num_tris, appendix.num_tris());
  for (size_t i = 0; i < appendix.tri_verts.size(); ++i) {
    EXPECT_EQ(model.atom_external_id[model.tri_atoms[i]], appendix.tri_verts[i]) << "triangle " << i / 3;
  }
  // The appendix's own file attaches to the generated fem.
  Model attached = model;
  EXPECT_TRUE(AttachSurface(appendix, "appendix.plg", 1e-9, &attached, &error)) << error.ToString();
}

TEST(GenerateSlab, MatchesAppendixCounts) {
  const Model m = GenerateSlab(SlabOptions{});
  const ModelSummary s = Summarize(m);
  EXPECT_EQ(s.atoms, 58);  // "hex 58 141"
  EXPECT_EQ(s.elements, 141);
  EXPECT_EQ(s.external_atoms, 22);
  EXPECT_EQ(s.fixed_atoms, 22);
  EXPECT_EQ(s.home_elements, 22);
  EXPECT_EQ(s.triangles, 28);
  // Appendix atom lines: top atoms free external, then home atoms fixed internal, then apexes.
  EXPECT_FALSE(m.atom_fixed[0]);
  EXPECT_TRUE(m.atom_external[0]);
  EXPECT_TRUE(m.atom_fixed[22]);
  EXPECT_FALSE(m.atom_external[22]);
  EXPECT_FALSE(m.atom_fixed[44]);
  EXPECT_FALSE(m.atom_external[44]);
  // Apex depth sqrt(2/3) = 0.8165 rounds to 0.816; the appendix prints -0.817.
  EXPECT_EQ(m.atom_pos_eq[3 * 44 + 2], -0.816);
}

TEST(GenerateSlab, EveryNonHomeElementIsAboutOneSpacingLong) {
  const Model m = GenerateSlab(SlabOptions{});
  for (int32_t e = 0; e < m.num_elems; ++e) {
    if (m.elem_home[e]) {
      EXPECT_EQ(m.elem_leq[e], 0.0);
    } else {
      EXPECT_NEAR(m.elem_leq[e], 1.0, 2e-3) << "element " << e;  // positions rounded to 3 decimals
    }
  }
}

TEST(GenerateSlab, EveryApexFormsATetrahedronWithItsTriangle) {
  const Model m = GenerateSlab(SlabOptions{.decimals = -1});
  // Each apex is joined to exactly three top atoms that are pairwise joined: a tetrahedron.
  std::set<std::pair<int32_t, int32_t>> joined;
  for (int32_t e = 0; e < m.num_elems; ++e) joined.insert(std::minmax(m.elem_atoms[2 * e], m.elem_atoms[2 * e + 1]));
  for (int32_t apex = 44; apex < m.num_atoms; ++apex) {
    std::vector<int32_t> top;
    for (int32_t j = 0; j < m.atom_elem_num[apex]; ++j) {
      const int32_t e = m.atom_elem[m.atom_elem_adr[apex] + j];
      const int32_t other = m.elem_atoms[2 * e] == apex ? m.elem_atoms[2 * e + 1] : m.elem_atoms[2 * e];
      if (m.atom_external[other]) top.push_back(other);
    }
    ASSERT_EQ(top.size(), 3u) << "apex " << apex;
    for (int i = 0; i < 3; ++i) {
      EXPECT_TRUE(joined.count(std::minmax(top[i], top[(i + 1) % 3])));
      EXPECT_NEAR(Dist(m, apex, top[i]), 1.0, 1e-12);
    }
  }
}

TEST(GenerateSlab, CountsScaleWithSize) {
  for (auto [rows, cols] : {std::pair{2, 1}, {3, 7}, {40, 40}, {41, 13}}) {
    const Model m = GenerateSlab(SlabOptions{.rows = rows, .cols = cols});
    const int32_t top = (rows + 1) / 2 * cols + rows / 2 * (cols + 1);
    EXPECT_EQ(m.num_external, top);
    EXPECT_EQ(Summarize(m).home_elements, top);
    // Triangles: 2*cols - 1 per band; apexes: one per triangle based on its band's lower row.
    EXPECT_EQ(m.num_tris, (2 * cols - 1) * (rows - 1));
    const int32_t apexes = rows / 2 * (cols - 1) + (rows - 1) / 2 * cols;
    EXPECT_EQ(m.num_atoms, 2 * top + apexes);
  }
}

TEST(GenerateSlab, InclusionStiffensAndWeighsOnlyItsRegion) {
  SlabOptions options{.rows = 20, .cols = 20};
  options.inclusions.push_back({{10, 8, -0.4}, 2.0, 10.0, 3.0});
  const Model m = GenerateSlab(options);
  int stiff = 0, heavy = 0;
  for (int32_t e = 0; e < m.num_elems; ++e) {
    if (m.elem_k[e] <= 15.0) continue;
    ++stiff;
    EXPECT_DOUBLE_EQ(m.elem_k[e], 150.0);
  }
  for (int32_t i = 0; i < m.num_atoms; ++i) {
    if (m.atom_mass[i] > 0.002) {
      ++heavy;
      EXPECT_FALSE(m.atom_fixed[i]);
      const double* p = &m.atom_pos_eq[3 * i];
      EXPECT_LE(std::hypot(p[0] - 10, p[1] - 8, p[2] + 0.4), 2.0);
    }
  }
  EXPECT_GT(stiff, 20);
  EXPECT_GT(heavy, 10);
}

}  // namespace
}  // namespace idms
