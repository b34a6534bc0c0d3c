// .fem / .plg / .obj readers and writers (thesis appendix B). Readers validate everything and
// commit the model only when the whole file is good; writers print shortest round-trip decimals.
#include "idms/sim/model_io.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <tuple>
#include <utility>

#include "text_scanner.h"

namespace idms {
namespace {

using internal::TextScanner;

constexpr int64_t kMaxAtoms = 200'000'000;    // 3 * kMaxAtoms fits int32 positions indexing
constexpr int64_t kMaxElems = 1'000'000'000;  // 2 * kMaxElems fits int32
constexpr int64_t kMaxPolygonSides = 1'000'000;

// Never reserve more than the text could describe: a lying header must not allocate gigabytes.
size_t SafeReserve(int64_t count, size_t text_bytes, size_t min_bytes_per_item) {
  return static_cast<size_t>(std::min<int64_t>(count, static_cast<int64_t>(text_bytes / min_bytes_per_item) + 1));
}

std::string Num(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

void AppendNum(std::string& out, double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

void AppendInt(std::string& out, int64_t v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

std::string SafeName(const std::string& name) {
  std::string out = name.empty() ? "model" : name;
  for (char& c : out) {
    if (static_cast<unsigned char>(c) <= ' ') c = '_';
  }
  return out;
}

bool BeginText(std::string_view text, std::string_view file, std::string_view header, LoadError* error) {
  if (text.find_first_not_of(" \t\r\n\v\f") == std::string_view::npos) {
    if (error) *error = {std::string(file), 1, 1, "empty file: expected header '" + std::string(header) + "'"};
    return false;
  }
  return internal::CheckIsText(text, file, error);
}

// Reads the .fem atom lines into `m`.
bool ParseFemAtoms(TextScanner& in, int64_t na, Model& m) {
  for (int64_t i = 0; i < na; ++i) {
    in.SetItem("atom", i, na);
    if (!in.NextLine()) return in.FailAtEof("expected " + in.Item() + " (x y z mass bc sc)");
    double x, y, z, mass;
    if (!in.Real("x", &x) || !in.Real("y", &y) || !in.Real("z", &z)) return false;
    const int mass_col = (in.AtEndOfLine(), in.column());
    if (!in.Real("mass", &mass)) return false;
    int64_t bc, sc;
    const int bc_col = (in.AtEndOfLine(), in.column());
    if (!in.Int("boundary condition", INT32_MIN, INT32_MAX, &bc)) return false;
    if (bc != kBcFixed && bc != kBcFree) {
      return in.Fail(bc_col, "expected boundary condition 1000 (fixed) or 1001 (free) for " + in.Item() + ", found " +
                                 std::to_string(bc));
    }
    const int sc_col = (in.AtEndOfLine(), in.column());
    if (!in.Int("surface condition", INT32_MIN, INT32_MAX, &sc)) return false;
    if (sc != kScInternal && sc != kScExternal) {
      return in.Fail(sc_col, "expected surface condition 2000 (internal) or 2001 (external) for " + in.Item() +
                                 ", found " + std::to_string(sc));
    }
    if (!in.ExpectEndOfLine()) return false;
    if (mass < 0) return in.Fail(mass_col, "expected mass >= 0 for " + in.Item() + ", found " + Num(mass));
    if (mass == 0 && bc == kBcFree) {
      return in.Fail(mass_col,
                     "expected a positive mass for free " + in.Item() + ", found 0 (only fixed atoms may be massless)");
    }
    m.atom_pos_eq.insert(m.atom_pos_eq.end(), {x, y, z});
    m.atom_mass.push_back(mass);
    m.atom_fixed.push_back(bc == kBcFixed);
    m.atom_external.push_back(sc == kScExternal);
  }
  return true;
}

// Reads the .fem element lines into `m`, remembering each element's line for later errors.
bool ParseFemElements(TextScanner& in, int64_t na, int64_t ne, Model& m, std::vector<int32_t>& lines) {
  for (int64_t e = 0; e < ne; ++e) {
    in.SetItem("element", e, ne);
    if (!in.NextLine()) return in.FailAtEof("expected " + in.Item() + " (a1 a2 stiffness viscosity)");
    int64_t a0, a1;
    if (!in.Int("first atom id", 0, na - 1, &a0)) return false;
    const int a1_col = (in.AtEndOfLine(), in.column());
    if (!in.Int("second atom id", 0, na - 1, &a1)) return false;
    if (a0 == a1)
      return in.Fail(a1_col,
                     in.Item() + " joins atom " + std::to_string(a0) + " to itself: expected two different atoms");
    double k, b;
    const int k_col = (in.AtEndOfLine(), in.column());
    if (!in.Real("stiffness", &k)) return false;
    if (k < 0) return in.Fail(k_col, "expected stiffness >= 0 for " + in.Item() + ", found " + Num(k));
    const int b_col = (in.AtEndOfLine(), in.column());
    if (!in.Real("viscosity", &b)) return false;
    if (b < 0) return in.Fail(b_col, "expected viscosity >= 0 for " + in.Item() + ", found " + Num(b));
    if (!in.ExpectEndOfLine()) return false;
    m.elem_atoms.insert(m.elem_atoms.end(), {static_cast<int32_t>(a0), static_cast<int32_t>(a1)});
    m.elem_k.push_back(k);
    m.elem_b.push_back(b);
    lines.push_back(in.line_number());
  }
  return true;
}

// Two elements joining the same pair of atoms (in either order) are a modelling error.
bool CheckDuplicateElements(const Model& m, const std::vector<int32_t>& lines, std::string_view file,
                            LoadError* error) {
  std::vector<std::tuple<int32_t, int32_t, int32_t>> pairs(lines.size());
  for (size_t e = 0; e < lines.size(); ++e) {
    const int32_t a = m.elem_atoms[2 * e], b = m.elem_atoms[2 * e + 1];
    pairs[e] = {std::min(a, b), std::max(a, b), static_cast<int32_t>(e)};
  }
  std::sort(pairs.begin(), pairs.end());
  for (size_t i = 1; i < pairs.size(); ++i) {
    const auto [a, b, e] = pairs[i];
    const auto [pa, pb, pe] = pairs[i - 1];
    if (a != pa || b != pb) continue;
    if (error) {
      *error = {std::string(file), lines[e], 1,
                "duplicate element: atoms " + std::to_string(a) + " and " + std::to_string(b) +
                    " are already joined by the element on line " + std::to_string(lines[pe])};
    }
    return false;
  }
  return true;
}

// Appends polygon `ids` fan-triangulated: (v0, vi, vi+1).
void AddPolygon(const std::vector<int32_t>& ids, SurfaceMesh& mesh) {
  for (size_t i = 1; i + 1 < ids.size(); ++i) mesh.tri_verts.insert(mesh.tri_verts.end(), {ids[0], ids[i], ids[i + 1]});
}

// Fails at the first vertex (in reading order) that repeats an earlier one. A polygon may have
// up to kMaxPolygonSides: pairs sorted by (id, position) put each id's occurrences side by side,
// O(n log n), where comparing every pair took minutes at 10^6 sides. Small polygons (nearly
// all of them) keep the pairwise loop, which allocates nothing.
bool CheckDistinct(TextScanner& in, const std::vector<int32_t>& ids, const std::vector<int>& cols,
                   std::string_view which, std::vector<std::pair<int32_t, int32_t>>& scratch) {
  constexpr size_t kPairwiseMax = 32;
  size_t first_repeat = ids.size();
  if (ids.size() <= kPairwiseMax) {
    for (size_t i = 0; i < ids.size() && first_repeat == ids.size(); ++i) {
      for (size_t j = 0; j < i; ++j) {
        if (ids[i] == ids[j]) {
          first_repeat = i;
          break;
        }
      }
    }
  } else {
    scratch.resize(ids.size());
    for (size_t i = 0; i < ids.size(); ++i) scratch[i] = {ids[i], static_cast<int32_t>(i)};
    std::sort(scratch.begin(), scratch.end());
    // Within a run of one id, every position after the run's first is a repeat.
    for (size_t k = 1; k < scratch.size(); ++k) {
      if (scratch[k].first == scratch[k - 1].first)
        first_repeat = std::min(first_repeat, static_cast<size_t>(scratch[k].second));
    }
  }
  if (first_repeat == ids.size()) return true;
  return in.Fail(cols[first_repeat], std::string(which) + " repeats vertex " + std::to_string(ids[first_repeat]) +
                                         ": expected distinct vertices");
}

}  // namespace

std::string LoadError::ToString() const {
  std::string s = file;
  if (line > 0) s += ":" + std::to_string(line);
  if (line > 0 && col > 0) s += ":" + std::to_string(col);
  return s + ": " + message;
}

bool ParseFem(std::string_view text, std::string_view file, Model* model, LoadError* error) {
  if (!BeginText(text, file, "name na ne", error)) return false;
  TextScanner in(text, file, error);
  in.NextLine();

  // Header: name, number of atoms, number of elements.
  std::string_view name;
  int64_t na, ne;
  if (!in.Word("model name", &name)) return false;
  if (!in.Int("number of atoms", 1, kMaxAtoms, &na) || !in.Int("number of elements", 0, kMaxElems, &ne)) return false;
  if (!in.ExpectEndOfLine()) return false;

  // Atoms, then elements; blank lines anywhere are separators.
  Model m;
  m.name = std::string(name);
  const size_t atoms = SafeReserve(na, text.size(), 12);
  m.atom_pos_eq.reserve(3 * atoms), m.atom_mass.reserve(atoms), m.atom_fixed.reserve(atoms),
      m.atom_external.reserve(atoms);
  if (!ParseFemAtoms(in, na, m)) return false;
  std::vector<int32_t> lines;
  const size_t elems = SafeReserve(ne, text.size(), 8);
  lines.reserve(elems), m.elem_atoms.reserve(2 * elems), m.elem_k.reserve(elems), m.elem_b.reserve(elems);
  if (!ParseFemElements(in, na, ne, m, lines)) return false;
  if (!in.ExpectEndOfFile(std::to_string(na) + " atoms and " + std::to_string(ne) + " elements")) return false;
  if (!CheckDuplicateElements(m, lines, file, error)) return false;

  FinalizeModel(m);
  *model = std::move(m);
  return true;
}

bool ParsePlg(std::string_view text, std::string_view file, SurfaceMesh* mesh, LoadError* error) {
  if (!BeginText(text, file, "name nv np", error)) return false;
  TextScanner in(text, file, error);
  in.NextLine();

  // Header: name, number of vertices, number of polygons.
  std::string_view name;
  int64_t nv, np;
  if (!in.Word("surface name", &name)) return false;
  if (!in.Int("number of vertices", 0, kMaxAtoms, &nv) || !in.Int("number of polygons", 0, kMaxElems, &np))
    return false;
  if (!in.ExpectEndOfLine()) return false;

  // Vertices.
  SurfaceMesh out;
  out.name = std::string(name);
  const size_t verts = SafeReserve(nv, text.size(), 6);
  out.vert_pos.reserve(3 * verts), out.vert_line.reserve(verts);
  for (int64_t i = 0; i < nv; ++i) {
    in.SetItem("vertex", i, nv);
    if (!in.NextLine()) return in.FailAtEof("expected " + in.Item() + " (x y z)");
    double p[3];
    if (!in.Real("x", &p[0]) || !in.Real("y", &p[1]) || !in.Real("z", &p[2])) return false;
    if (!in.ExpectEndOfLine()) return false;
    out.vert_pos.insert(out.vert_pos.end(), p, p + 3);
    out.vert_line.push_back(in.line_number());
  }

  // Polygons: a side count, then that many vertex ids; fan-triangulated.
  out.tri_verts.reserve(3 * SafeReserve(np, text.size(), 8));
  std::vector<int32_t> ids;
  std::vector<int> cols;
  std::vector<std::pair<int32_t, int32_t>> scratch;
  for (int64_t p = 0; p < np; ++p) {
    in.SetItem("polygon", p, np);
    if (!in.NextLine()) return in.FailAtEof("expected " + in.Item() + " (n v1 ... vn)");
    int64_t sides;
    const int sides_col = (in.AtEndOfLine(), in.column());
    if (!in.Int("number of sides", INT32_MIN, INT32_MAX, &sides)) return false;
    if (sides < 3 || sides > kMaxPolygonSides) {
      return in.Fail(sides_col,
                     "expected a polygon of at least 3 vertices for " + in.Item() + ", found " + std::to_string(sides));
    }
    ids.clear(), cols.clear();
    for (int64_t s = 0; s < sides; ++s) {
      int64_t v;
      cols.push_back((in.AtEndOfLine(), in.column()));
      if (!in.Int("vertex id " + std::to_string(s + 1), 0, nv - 1, &v)) return false;
      ids.push_back(static_cast<int32_t>(v));
    }
    if (!in.ExpectEndOfLine() || !CheckDistinct(in, ids, cols, in.Item(), scratch)) return false;
    AddPolygon(ids, out);
  }
  if (!in.ExpectEndOfFile(std::to_string(nv) + " vertices and " + std::to_string(np) + " polygons")) return false;
  *mesh = std::move(out);
  return true;
}

bool ParseObj(std::string_view text, std::string_view file, SurfaceMesh* mesh, LoadError* error) {
  if (!BeginText(text, file, "v x y z", error)) return false;
  TextScanner in(text, file, error);
  SurfaceMesh out;
  std::vector<int32_t> ids;
  std::vector<int> cols;
  std::vector<std::pair<int32_t, int32_t>> scratch;
  while (in.NextLine('#')) {
    std::string_view keyword;
    const int keyword_col = in.column();
    in.Word("a statement", &keyword);
    if (keyword == "v") {
      // Vertex: x y z, an optional w (ignored).
      double p[3], w;
      in.SetItem("vertex", static_cast<int64_t>(out.vert_pos.size() / 3) + 1, 0);
      if (!in.Real("x", &p[0]) || !in.Real("y", &p[1]) || !in.Real("z", &p[2])) return false;
      if (!in.AtEndOfLine() && !in.Real("w", &w)) return false;
      if (!in.ExpectEndOfLine()) return false;
      if (out.vert_pos.size() / 3 >= static_cast<size_t>(kMaxAtoms)) return in.Fail(keyword_col, "too many vertices");
      out.vert_pos.insert(out.vert_pos.end(), p, p + 3);
      out.vert_line.push_back(in.line_number());
    } else if (keyword == "f") {
      // Face: v, v/vt, v//vn or v/vt/vn items; 1-based, negative = relative to the last vertex.
      ids.clear(), cols.clear();
      const int64_t nv = static_cast<int64_t>(out.vert_pos.size() / 3);
      while (!in.AtEndOfLine()) {
        std::string_view item;
        const int col = in.column();
        in.Word("face vertex", &item);
        const std::string_view index_text = item.substr(0, item.find('/'));
        int64_t index = 0;
        const auto [end, ec] = std::from_chars(index_text.data(), index_text.data() + index_text.size(), index);
        if (ec != std::errc() || end != index_text.data() + index_text.size() || index == 0) {
          return in.Fail(col, "expected a face vertex index (1-based, or negative), found '" + std::string(item) + "'");
        }
        const int64_t v = index > 0 ? index - 1 : nv + index;
        if (v < 0 || v >= nv) {
          return in.Fail(col, "face vertex " + std::to_string(index) + " is out of range: " + std::to_string(nv) +
                                  " vertices defined so far");
        }
        ids.push_back(static_cast<int32_t>(v));
        cols.push_back(col);
      }
      if (ids.size() < 3) {
        return in.Fail(keyword_col, "expected a face of at least 3 vertices, found " + std::to_string(ids.size()));
      }
      if (!CheckDistinct(in, ids, cols, "face", scratch)) return false;
      AddPolygon(ids, out);
    } else if (keyword == "o" || keyword == "g") {
      std::string_view name;
      if (!in.AtEndOfLine() && in.Word("name", &name) && out.name.empty()) out.name = std::string(name);
    } else if (keyword == "vn" || keyword == "vt" || keyword == "vp" || keyword == "s" || keyword == "usemtl" ||
               keyword == "mtllib" || keyword == "l") {
      continue;  // normals, texture coordinates, smoothing, materials and lines carry nothing for the DSM
    } else {
      return in.Fail(keyword_col, "expected an obj statement (v, f, o, g, vn, vt, s, usemtl, mtllib), found '" +
                                      std::string(keyword) + "'");
    }
  }
  *mesh = std::move(out);
  return true;
}

bool AttachSurface(const SurfaceMesh& mesh, std::string_view file, double tolerance, Model* model, LoadError* error) {
  Model& m = *model;
  auto fail = [&](int line, std::string message) {
    if (error) *error = {std::string(file), line, line > 0 ? 1 : 0, std::move(message)};
    return false;
  };
  if (mesh.num_verts() != m.num_external) {
    return fail(1, "expected " + std::to_string(m.num_external) +
                       " vertices (one per external atom of the fem), found " + std::to_string(mesh.num_verts()));
  }
  // Vertex i must sit where the i-th external atom rests.
  for (int32_t v = 0; v < mesh.num_verts(); ++v) {
    const int32_t atom = m.external_atoms[v];
    const double* pv = &mesh.vert_pos[3 * v];
    const double* pa = &m.atom_pos_eq[3 * atom];
    const double d = std::sqrt((pv[0] - pa[0]) * (pv[0] - pa[0]) + (pv[1] - pa[1]) * (pv[1] - pa[1]) +
                               (pv[2] - pa[2]) * (pv[2] - pa[2]));
    if (!(d <= tolerance)) {
      const int line = static_cast<size_t>(v) < mesh.vert_line.size() ? mesh.vert_line[v] : 0;
      return fail(line, "vertex " + std::to_string(v) + " (" + Num(pv[0]) + " " + Num(pv[1]) + " " + Num(pv[2]) +
                            ") is " + Num(d) + " from external atom " + std::to_string(v) + " (fem atom " +
                            std::to_string(atom) + " at " + Num(pa[0]) + " " + Num(pa[1]) + " " + Num(pa[2]) +
                            "); expected within " + Num(tolerance));
    }
  }
  m.tri_atoms.resize(mesh.tri_verts.size());
  for (size_t i = 0; i < mesh.tri_verts.size(); ++i) m.tri_atoms[i] = m.external_atoms[mesh.tri_verts[i]];
  m.num_tris = static_cast<int32_t>(m.tri_atoms.size() / 3);
  return true;
}

bool ReadTextFile(const std::string& path, int64_t max_bytes, std::string* text, LoadError* error) {
  auto fail = [&](std::string message) {
    if (error) *error = {path, 0, 0, std::move(message)};
    return false;
  };
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) return fail("cannot open: no such file");
  if (!std::filesystem::is_regular_file(status)) return fail("cannot open: not a regular file");
  const auto size = static_cast<int64_t>(std::filesystem::file_size(path, ec));
  if (ec) return fail("cannot read its size: " + ec.message());
  if (size > max_bytes) {
    return fail("file is " + std::to_string(size) + " bytes; the limit is " + std::to_string(max_bytes) + " bytes");
  }
  std::ifstream file(path, std::ios::binary);
  if (!file) return fail(std::string("cannot open: ") + std::strerror(errno));
  std::string data(static_cast<size_t>(size), '\0');
  file.read(data.data(), size);
  if (file.gcount() != size) return fail("short read: the file changed while it was read");
  *text = std::move(data);
  return true;
}

void ModelPaths(const std::string& prefix_or_fem, std::string* fem_path, std::string* plg_path) {
  std::string prefix = prefix_or_fem;
  if (prefix.size() > 4 && prefix.compare(prefix.size() - 4, 4, ".fem") == 0) prefix.resize(prefix.size() - 4);
  *fem_path = prefix + ".fem";
  *plg_path = prefix + ".plg";
}

bool LoadModel(const std::string& fem_path, const std::string& plg_path, const ReadOptions& options, Model* model,
               LoadError* error) {
  std::string text;
  Model m;
  if (!ReadTextFile(fem_path, options.max_bytes, &text, error) || !ParseFem(text, fem_path, &m, error)) return false;
  if (!plg_path.empty()) {
    SurfaceMesh mesh;
    const bool obj = plg_path.size() > 4 && plg_path.compare(plg_path.size() - 4, 4, ".obj") == 0;
    if (!ReadTextFile(plg_path, options.max_bytes, &text, error)) return false;
    if (!(obj ? ParseObj(text, plg_path, &mesh, error) : ParsePlg(text, plg_path, &mesh, error))) return false;
    if (!AttachSurface(mesh, plg_path, options.plg_tolerance, &m, error)) return false;
  }
  *model = std::move(m);
  return true;
}

bool ParseModelText(std::string_view fem, std::string_view plg, const std::string& name, Model* model,
                    LoadError* error) {
  SurfaceMesh mesh;
  return ParseFem(fem, name + ".fem", model, error) && ParsePlg(plg, name + ".plg", &mesh, error) &&
         AttachSurface(mesh, name + ".plg", ReadOptions{}.plg_tolerance, model, error);
}

std::string WriteFem(const Model& m) {
  std::string out;
  out.reserve(static_cast<size_t>(m.num_atoms) * 48 + static_cast<size_t>(m.num_elems) * 32 + 64);
  out += SafeName(m.name) + " " + std::to_string(m.num_atoms) + " " + std::to_string(m.num_elems) + "\n\n";
  for (int32_t i = 0; i < m.num_atoms; ++i) {
    for (int c = 0; c < 3; ++c) AppendNum(out, m.atom_pos_eq[3 * i + c]), out += ' ';
    AppendNum(out, m.atom_mass[i]);
    out += m.atom_fixed[i] ? " 1000" : " 1001";
    out += m.atom_external[i] ? " 2001\n" : " 2000\n";
  }
  out += '\n';
  for (int32_t e = 0; e < m.num_elems; ++e) {
    AppendInt(out, m.elem_atoms[2 * e]), out += ' ';
    AppendInt(out, m.elem_atoms[2 * e + 1]), out += ' ';
    AppendNum(out, m.elem_k[e]), out += ' ';
    AppendNum(out, m.elem_b[e]), out += '\n';
  }
  return out;
}

std::string WritePlg(const Model& m) {
  std::string out;
  out.reserve(static_cast<size_t>(m.num_external) * 32 + static_cast<size_t>(m.num_tris) * 24 + 64);
  out += SafeName(m.name) + " " + std::to_string(m.num_external) + " " + std::to_string(m.num_tris) + "\n\n";
  for (int32_t atom : m.external_atoms) {
    for (int c = 0; c < 3; ++c) AppendNum(out, m.atom_pos_eq[3 * atom + c]), out += c < 2 ? ' ' : '\n';
  }
  out += '\n';
  for (int32_t t = 0; t < m.num_tris; ++t) {
    out += '3';
    for (int c = 0; c < 3; ++c) out += ' ', AppendInt(out, m.atom_external_id[m.tri_atoms[3 * t + c]]);
    out += '\n';
  }
  return out;
}

std::string WriteObj(const Model& m) { return WriteObj(m, m.atom_pos_eq.data()); }

std::string WriteObj(const Model& m, const double* positions) {
  std::string out = "# idms surface: external atoms of the DSM, in .plg vertex order\no " + SafeName(m.name) + "\n";
  for (int32_t atom : m.external_atoms) {
    out += 'v';
    for (int c = 0; c < 3; ++c) out += ' ', AppendNum(out, positions[3 * atom + c]);
    out += '\n';
  }
  for (int32_t t = 0; t < m.num_tris; ++t) {
    out += 'f';
    for (int c = 0; c < 3; ++c) out += ' ', AppendInt(out, m.atom_external_id[m.tri_atoms[3 * t + c]] + 1);
    out += '\n';
  }
  return out;
}

bool WriteTextFileAtomic(const std::string& path, std::string_view text, std::string* error) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) {
    if (error) *error = path + ": cannot write: " + std::strerror(errno);
    return false;
  }
  const bool written = std::fwrite(text.data(), 1, text.size(), f) == text.size();
  const bool flushed = std::fflush(f) == 0 && ::fsync(::fileno(f)) == 0;
  const bool closed = std::fclose(f) == 0;
  if (!written || !flushed || !closed || std::rename(tmp.c_str(), path.c_str()) != 0) {
    if (error) *error = path + ": cannot write: " + std::strerror(errno);
    std::remove(tmp.c_str());
    return false;
  }
  return true;
}

bool SaveModel(const Model& model, const std::string& prefix, std::string* error) {
  return WriteTextFileAtomic(prefix + ".fem", WriteFem(model), error) &&
         WriteTextFileAtomic(prefix + ".plg", WritePlg(model), error);
}

}  // namespace idms
