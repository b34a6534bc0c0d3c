// .fem / .plg / .obj readers and writers: round trips, and one test per malformed input.
#include "idms/sim/model_io.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "idms/sim/generate.h"
#include "idms/sim/summary.h"

namespace idms {
namespace {

// A small valid pair: a tetrahedron with one external face and one home atom.
constexpr const char* kFem = R"(tet 5 7

0 0 0 0.002 1001 2001
1 0 0 0.002 1001 2001
0.5 0.866 0 0.002 1001 2001
0.5 0.289 -0.817 0.002 1001 2000
0 0 0 0 1000 2000

0 1 15 0.2
1 2 15 0.2
2 0 15 0.2
0 3 15 0.2
1 3 15 0.2
2 3 15 0.2
0 4 15 0.2
)";

constexpr const char* kPlg = R"(tet 3 1

0 0 0
1 0 0
0.5 0.866 0

3 0 1 2
)";

template <class T>
bool SameBits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

void ExpectSameModel(const Model& a, const Model& b) {
  EXPECT_EQ(a.name, b.name);
  EXPECT_EQ(a.num_atoms, b.num_atoms);
  EXPECT_EQ(a.num_elems, b.num_elems);
  EXPECT_EQ(a.num_tris, b.num_tris);
  EXPECT_TRUE(SameBits(a.atom_pos_eq, b.atom_pos_eq));
  EXPECT_TRUE(SameBits(a.atom_mass, b.atom_mass));
  EXPECT_TRUE(SameBits(a.atom_fixed, b.atom_fixed));
  EXPECT_TRUE(SameBits(a.atom_external, b.atom_external));
  EXPECT_TRUE(SameBits(a.elem_atoms, b.elem_atoms));
  EXPECT_TRUE(SameBits(a.elem_k, b.elem_k));
  EXPECT_TRUE(SameBits(a.elem_b, b.elem_b));
  EXPECT_TRUE(SameBits(a.elem_leq, b.elem_leq));
  EXPECT_TRUE(SameBits(a.elem_home, b.elem_home));
  EXPECT_TRUE(SameBits(a.external_atoms, b.external_atoms));
  EXPECT_TRUE(SameBits(a.tri_atoms, b.tri_atoms));
  EXPECT_TRUE(SameBits(a.atom_elem_adr, b.atom_elem_adr));
  EXPECT_TRUE(SameBits(a.atom_elem, b.atom_elem));
}

Model ReadBack(const std::string& fem, const std::string& plg) {
  Model m;
  SurfaceMesh mesh;
  LoadError error;
  EXPECT_TRUE(ParseFem(fem, "a.fem", &m, &error)) << error.ToString();
  EXPECT_TRUE(ParsePlg(plg, "a.plg", &mesh, &error)) << error.ToString();
  EXPECT_TRUE(AttachSurface(mesh, "a.plg", 1e-12, &m, &error)) << error.ToString();
  return m;
}

TEST(ModelIo, ParsesTheSmallPair) {
  const Model m = ReadBack(kFem, kPlg);
  EXPECT_EQ(m.name, "tet");
  EXPECT_EQ(m.num_atoms, 5);
  EXPECT_EQ(m.num_external, 3);
  EXPECT_EQ(m.num_tris, 1);
  EXPECT_EQ(Summarize(m).home_elements, 1);
  EXPECT_EQ(m.atom_elem_num[0], 4);
}

TEST(ModelIo, WriteReadIsBitExactAndWriteReadWriteIsByteIdentical) {
  // Exact (unrounded) positions exercise shortest round-trip printing of awkward doubles.
  SlabOptions options{.rows = 9, .cols = 7, .spacing = 0.37, .k = 1.0 / 3.0, .b = 0.1, .mass = 2e-3, .decimals = -1};
  options.inclusions.push_back({{1, 1, 0}, 1.0, 7.3, 1.7});
  const Model original = GenerateSlab(options);
  const std::string fem = WriteFem(original), plg = WritePlg(original);
  const Model back = ReadBack(fem, plg);
  ExpectSameModel(original, back);
  EXPECT_EQ(WriteFem(back), fem);
  EXPECT_EQ(WritePlg(back), plg);
}

TEST(ModelIo, ObjRoundTripsTheSurface) {
  const Model model = GenerateSlab(SlabOptions{});
  const std::string obj = WriteObj(model);
  SurfaceMesh mesh;
  LoadError error;
  ASSERT_TRUE(ParseObj(obj, "s.obj", &mesh, &error)) << error.ToString();
  Model attached = GenerateSlab(SlabOptions{});
  attached.tri_atoms.clear();
  ASSERT_TRUE(AttachSurface(mesh, "s.obj", 0.0, &attached, &error)) << error.ToString();
  EXPECT_EQ(attached.tri_atoms, model.tri_atoms);
}

TEST(ModelIo, ObjAcceptsSlashesNegativeIndicesQuadsAndComments) {
  SurfaceMesh mesh;
  LoadError error;
  ASSERT_TRUE(ParseObj("# quad\nv 0 0 0\nv 1 0 0\nv 1 1 0 1.0\nv 0 1 0\nvn 0 0 1\nf 1//1 2/1/1 -2 -1\n", "q.obj", &mesh,
                       &error))
      << error.ToString();
  EXPECT_EQ(mesh.num_tris(), 2);
  EXPECT_EQ(mesh.tri_verts, (std::vector<int32_t>{0, 1, 2, 0, 2, 3}));
}

TEST(ModelIo, PolygonsWithMoreThanThreeSidesAreFanTriangulated) {
  SurfaceMesh mesh;
  LoadError error;
  ASSERT_TRUE(ParsePlg("p 5 1\n0 0 0\n1 0 0\n2 1 0\n1 2 0\n0 1 0\n5 0 1 2 3 4\n", "p.plg", &mesh, &error));
  EXPECT_EQ(mesh.tri_verts, (std::vector<int32_t>{0, 1, 2, 0, 2, 3, 0, 3, 4}));
}

// ---- malformed input: each case names the line, column and what was expected -----------

struct BadCase {
  const char* name;
  std::string text;
  int line, col;
  const char* expect;  // a substring of the message
};

std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return text.replace(at, from.size(), to);
}

std::string CaseName(const testing::TestParamInfo<BadCase>& param) { return param.param.name; }

class BadFem : public testing::TestWithParam<BadCase> {};

TEST_P(BadFem, IsRejectedWithPositionAndNoPartialModel) {
  const BadCase& c = GetParam();
  Model model;
  model.name = "untouched";
  LoadError error;
  ASSERT_FALSE(ParseFem(c.text, "bad.fem", &model, &error));
  EXPECT_EQ(error.file, "bad.fem");
  EXPECT_EQ(error.line, c.line) << error.ToString();
  EXPECT_EQ(error.col, c.col) << error.ToString();
  EXPECT_NE(error.message.find(c.expect), std::string::npos) << error.ToString();
  EXPECT_EQ(model.name, "untouched");
  EXPECT_EQ(model.num_atoms, 0);
  EXPECT_EQ(error.ToString().rfind("bad.fem:" + std::to_string(c.line) + ":", 0), 0u);
}

const std::string fem = kFem;
INSTANTIATE_TEST_SUITE_P(
    ModelIo, BadFem,
    testing::Values(
        BadCase{"Empty", "", 1, 1, "empty file"}, BadCase{"BlankOnly", "\n  \n", 1, 1, "empty file"},
        BadCase{"Binary", Replace(fem, "tet 5 7", std::string("tet\0 5 7", 8)), 1, 4, "binary data"},
        BadCase{"MissingCounts", Replace(fem, "tet 5 7", "tet 5"), 1, 6, "number of elements"},
        BadCase{"CountNotANumber", Replace(fem, "tet 5 7", "tet five 7"), 1, 5,
                "number of atoms (an integer), found 'five'"},
        BadCase{"NegativeCount", Replace(fem, "tet 5 7", "tet 5 -7"), 1, 7, "number of elements in [0,"},
        BadCase{"ZeroAtoms", Replace(fem, "tet 5 7", "tet 0 7"), 1, 5, "number of atoms in [1,"},
        BadCase{"ExtraHeaderField", Replace(fem, "tet 5 7", "tet 5 7 9"), 1, 9, "extra field '9'"},
        BadCase{"TooFewAtomsForCount", Replace(fem, "tet 5 7", "tet 6 7"), 9, 11, "boundary condition of atom 5"},
        BadCase{"Truncated", fem.substr(0, fem.find("2 3 15")), 14, 1,
                "unexpected end of file: expected element 5 of 7"},
        BadCase{"ExtraLine", fem + "0 2 1 1\n", 16, 1, "expected end of file after 5 atoms and 7 elements"},
        BadCase{"MissingField", Replace(fem, "0.5 0.866 0 0.002 1001 2001", "0.5 0.866 0 0.002 1001"), 5, 23,
                "surface condition of atom 2"},
        BadCase{"ExtraField", Replace(fem, "1 0 0 0.002 1001 2001", "1 0 0 0.002 1001 2001 7"), 4, 23,
                "extra field '7'"},
        BadCase{"NotANumber", Replace(fem, "1 0 0 0.002", "1 zero 0 0.002"), 4, 3,
                "y of atom 1 of 5 (a number), found 'zero'"},
        BadCase{"NaN", Replace(fem, "1 0 0 0.002", "1 nan 0 0.002"), 4, 3, "a finite number"},
        BadCase{"Inf", Replace(fem, "0 1 15 0.2", "0 1 inf 0.2"), 9, 5, "a finite number"},
        BadCase{"Overflow", Replace(fem, "0 1 15 0.2", "0 1 1e999 0.2"), 9, 5, "out-of-range"},
        BadCase{"ZeroMassFree", Replace(fem, "1 0 0 0.002 1001", "1 0 0 0 1001"), 4, 7,
                "positive mass for free atom 1"},
        BadCase{"NegativeMass", Replace(fem, "1 0 0 0.002 1001", "1 0 0 -0.002 1001"), 4, 7, "mass >= 0"},
        BadCase{"UnknownBc", Replace(fem, "1 0 0 0.002 1001", "1 0 0 0.002 1002"), 4, 13,
                "boundary condition 1000 (fixed) or 1001"},
        BadCase{"UnknownSc", Replace(fem, "1 0 0 0.002 1001 2001", "1 0 0 0.002 1001 2002"), 4, 18,
                "surface condition 2000 (internal) or 2001"},
        BadCase{"AtomIdOutOfRange", Replace(fem, "1 2 15 0.2", "1 5 15 0.2"), 10, 3, "in [0, 4], found 5"},
        BadCase{"NegativeAtomId", Replace(fem, "1 2 15 0.2", "-1 2 15 0.2"), 10, 1, "in [0, 4], found -1"},
        BadCase{"SelfElement", Replace(fem, "1 2 15 0.2", "2 2 15 0.2"), 10, 3, "joins atom 2 to itself"},
        BadCase{"DuplicateElement", Replace(fem, "1 2 15 0.2", "1 0 15 0.2"), 10, 1,
                "atoms 0 and 1 are already joined by the element on line 9"},
        BadCase{"NegativeStiffness", Replace(fem, "1 2 15 0.2", "1 2 -15 0.2"), 10, 5, "stiffness >= 0"},
        BadCase{"NegativeViscosity", Replace(fem, "1 2 15 0.2", "1 2 15 -0.2"), 10, 8, "viscosity >= 0"},
        BadCase{"HugeCountTruncated", "tet 200000000 1\n0 0 0 1 1001 2001\n", 3, 1, "expected atom 1 of 200000000"}),
    CaseName);

class BadPlg : public testing::TestWithParam<BadCase> {};

TEST_P(BadPlg, IsRejectedWithPosition) {
  const BadCase& c = GetParam();
  Model model;
  LoadError error;
  ASSERT_TRUE(ParseFem(kFem, "a.fem", &model, &error));
  SurfaceMesh mesh;
  const bool parsed = ParsePlg(c.text, "bad.plg", &mesh, &error);
  const bool ok = parsed && AttachSurface(mesh, "bad.plg", 1e-3, &model, &error);
  ASSERT_FALSE(ok);
  EXPECT_EQ(error.line, c.line) << error.ToString();
  EXPECT_EQ(error.col, c.col) << error.ToString();
  EXPECT_NE(error.message.find(c.expect), std::string::npos) << error.ToString();
  EXPECT_EQ(model.num_tris, 0) << "a failed attach must leave the model's surface untouched";
}

const std::string plg = kPlg;
INSTANTIATE_TEST_SUITE_P(
    ModelIo, BadPlg,
    testing::Values(BadCase{"Empty", "", 1, 1, "empty file"},
                    BadCase{"TwoSidedPolygon", Replace(plg, "3 0 1 2", "2 0 1"), 7, 1, "at least 3 vertices"},
                    BadCase{"SidesDisagree", Replace(plg, "3 0 1 2", "3 0 1"), 7, 6, "vertex id 3 of polygon 0"},
                    BadCase{"VertexOutOfRange", Replace(plg, "3 0 1 2", "3 0 1 3"), 7, 7, "in [0, 2], found 3"},
                    BadCase{"RepeatedVertex", Replace(plg, "3 0 1 2", "3 0 1 1"), 7, 7, "repeats vertex 1"},
                    // Vertices 0 and 1 both repeat; the first repeat in reading order is the one named.
                    BadCase{"FirstRepeatIsNamed", Replace(plg, "3 0 1 2", "5 0 1 2 1 0"), 7, 9, "repeats vertex 1"},
                    BadCase{"TooFewVertices", Replace(Replace(plg, "tet 3 1", "tet 2 1"), "3 0 1 2", "3 0 1 1"), 5, 1,
                            "number of sides of polygon 0 of 1 (an integer), found '0.5'"},
                    BadCase{"WrongVertexCount", "tet 2 0\n0 0 0\n1 0 0\n", 1, 1, "expected 3 vertices"},
                    BadCase{"PositionMismatch", Replace(plg, "1 0 0", "1 0.01 0"), 4, 1,
                            "vertex 1 (1 0.01 0) is 0.01 from external atom 1"},
                    BadCase{"NaNVertex", Replace(plg, "1 0 0", "1 NaN 0"), 4, 3, "finite"},
                    BadCase{"MissingPolygon", Replace(plg, "tet 3 1", "tet 3 2"), 8, 1, "expected polygon 1 of 2"}),
    CaseName);

// A .plg of n vertices and one polygon through all of them (the ids as given).
std::string OnePolygonPlg(const std::vector<int32_t>& ids) {
  std::string text = "big ";
  text += std::to_string(ids.size());
  text += " 1\n";
  for (size_t i = 0; i < ids.size(); ++i) text.append(std::to_string(i)).append(" 0 0\n");
  text += std::to_string(ids.size());
  for (const int32_t id : ids) text.append(" ").append(std::to_string(id));
  return text + "\n";
}

// The distinct-vertex check is O(n log n): a 200,000-sided polygon (the limit is 10^6) is read in
// well under a second, where the pairwise check took about 8 s (and 10^6 sides three minutes).
// Generous bound: a quadratic check cannot meet it, a slow machine or a sanitizer build can.
TEST(ModelIo, APolygonOfManySidesIsCheckedInNearLinearTime) {
  constexpr int32_t kSides = 200'000;
  std::vector<int32_t> ids(kSides);
  for (int32_t i = 0; i < kSides; ++i) ids[i] = (i * 7919) % kSides;  // a permutation (7919 is prime)
  SurfaceMesh mesh;
  LoadError error;
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_TRUE(ParsePlg(OnePolygonPlg(ids), "big.plg", &mesh, &error)) << error.ToString();
  EXPECT_EQ(mesh.num_tris(), kSides - 2);
  // The same polygon with its last vertex repeating an early one: the same error as ever.
  ids.back() = ids[5];
  const std::string repeated = OnePolygonPlg(ids);
  ASSERT_FALSE(ParsePlg(repeated, "big.plg", &mesh, &error));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(error.line, kSides + 2);
  const size_t line_start = repeated.rfind('\n', repeated.size() - 2) + 1;
  EXPECT_EQ(error.col, static_cast<int>(repeated.rfind(' ') + 2 - line_start));
  EXPECT_NE(error.message.find("repeats vertex " + std::to_string(ids[5])), std::string::npos) << error.ToString();
  EXPECT_LT(seconds, 4.0) << "two 200,000-sided polygons took " << seconds << " s";
  std::printf("two 200,000-sided polygons parsed and checked in %.3f s\n", seconds);
  // Two repeats: the one met first in reading order is named, not the smaller vertex id.
  std::vector<int32_t> small(40);
  for (int32_t i = 0; i < 40; ++i) small[i] = i;
  small[33] = 10, small[20] = 25;
  ASSERT_FALSE(ParsePlg(OnePolygonPlg(small), "small.plg", &mesh, &error));
  EXPECT_NE(error.message.find("repeats vertex 25"), std::string::npos) << error.ToString();
}

TEST(ModelIo, ObjRejectsUnknownStatementsAndBadFaces) {
  SurfaceMesh mesh;
  LoadError error;
  EXPECT_FALSE(ParseObj("v 0 0 0\nv 1 0 0\nv 0 1 0\nfoo 1\n", "x.obj", &mesh, &error));
  EXPECT_EQ(error.ToString(),
            "x.obj:4:1: expected an obj statement (v, f, o, g, vn, vt, s, usemtl, mtllib), found 'foo'");
  EXPECT_FALSE(ParseObj("v 0 0 0\nv 1 0 0\nf 1 2\n", "x.obj", &mesh, &error));
  EXPECT_NE(error.message.find("at least 3 vertices"), std::string::npos);
  EXPECT_FALSE(ParseObj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "x.obj", &mesh, &error));
  EXPECT_EQ(error.line, 4);
  EXPECT_EQ(error.col, 7);
  EXPECT_FALSE(ParseObj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "x.obj", &mesh, &error));
  EXPECT_FALSE(ParseObj("v 0 0\n", "x.obj", &mesh, &error));
  EXPECT_EQ(error.line, 1);
}

// ---- files on disk ----------------------------------------------------------------------

class ModelFiles : public testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("idms_io_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  void Write(const std::string& name, const std::string& text) const {
    std::ofstream(Path(name), std::ios::binary) << text;
  }
  std::filesystem::path dir_;
};

TEST_F(ModelFiles, SaveThenLoadGivesTheSameModel) {
  const Model model = GenerateSlab(SlabOptions{.rows = 6, .cols = 5});
  std::string err;
  ASSERT_TRUE(SaveModel(model, Path("slab"), &err)) << err;
  Model back;
  LoadError error;
  ASSERT_TRUE(LoadModel(Path("slab.fem"), Path("slab.plg"), {}, &back, &error)) << error.ToString();
  ExpectSameModel(model, back);
  EXPECT_FALSE(std::filesystem::exists(Path("slab.fem.tmp." + std::to_string(::getpid()))));
}

TEST_F(ModelFiles, OversizeFileIsRefusedBeforeReading) {
  Write("big.fem", kFem);
  Model m;
  LoadError error;
  ReadOptions options;
  options.max_bytes = 100;
  ASSERT_FALSE(LoadModel(Path("big.fem"), "", options, &m, &error));
  EXPECT_NE(error.message.find("the limit is 100 bytes"), std::string::npos) << error.ToString();
  EXPECT_EQ(error.file, Path("big.fem"));
}

TEST_F(ModelFiles, MissingFileAndDirectoryAreErrors) {
  Model m;
  LoadError error;
  EXPECT_FALSE(LoadModel(Path("none.fem"), "", {}, &m, &error));
  EXPECT_NE(error.message.find("no such file"), std::string::npos);
  EXPECT_FALSE(LoadModel(dir_.string(), "", {}, &m, &error));
  EXPECT_NE(error.message.find("not a regular file"), std::string::npos);
}

TEST_F(ModelFiles, BadPlgLeavesNoModel) {
  Write("a.fem", kFem);
  Write("a.plg", Replace(kPlg, "1 0 0", "1 5 0"));
  Model m;
  m.name = "previous";
  LoadError error;
  EXPECT_FALSE(LoadModel(Path("a.fem"), Path("a.plg"), {}, &m, &error));
  EXPECT_EQ(m.name, "previous");
  EXPECT_EQ(error.line, 4);
}

TEST_F(ModelFiles, ObjSurfaceCanReplaceThePlg) {
  const Model model = GenerateSlab(SlabOptions{});
  std::string err;
  ASSERT_TRUE(SaveModel(model, Path("hex"), &err));
  ASSERT_TRUE(WriteTextFileAtomic(Path("hex.obj"), WriteObj(model), &err));
  Model back;
  LoadError error;
  ASSERT_TRUE(LoadModel(Path("hex.fem"), Path("hex.obj"), {}, &back, &error)) << error.ToString();
  EXPECT_EQ(back.tri_atoms, model.tri_atoms);
}

}  // namespace
}  // namespace idms
