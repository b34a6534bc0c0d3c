// The two-layer tetrahedral slab of thesis figure 3-1 and stiff inclusions (thesis 5.6, 3.2.3).
#include "idms/sim/generate.h"

#include <cmath>

#include "idms/sim/check.h"

namespace idms {
namespace {

// Builds the arrays of a slab; the top grid is indexed row by row.
class SlabBuilder {
 public:
  explicit SlabBuilder(const SlabOptions& o) : o_(o) {
    row_start_.resize(o.rows + 1);
    int32_t n = 0;
    for (int32_t r = 0; r < o.rows; ++r) row_start_[r] = n, n += RowLength(r);
    row_start_[o.rows] = n;
  }

  Model Build() {
    Model m;
    m.name = o_.name;
    const int32_t num_top = row_start_[o_.rows];
    const double row_height = o_.spacing * std::sqrt(3.0) / 2;
    const double depth = o_.spacing * std::sqrt(2.0 / 3.0);

    // Top grid: external free atoms at z = 0; even rows start half a spacing in.
    for (int32_t r = 0; r < o_.rows; ++r) {
      for (int32_t j = 0; j < RowLength(r); ++j) {
        const double x = (r % 2 == 0 ? 0.5 : 0.0) * o_.spacing + j * o_.spacing;
        AddAtom(m, x, r * row_height, 0.0, /*fixed=*/false, /*external=*/true);
      }
    }
    // Home atoms: fixed, internal, at the rest position of each top atom (thesis 3.1).
    for (int32_t i = 0; i < num_top; ++i) {
      AddAtom(m, m.atom_pos_eq[3 * i], m.atom_pos_eq[3 * i + 1], m.atom_pos_eq[3 * i + 2], true, false);
    }

    // Triangles in the order and winding of appendix B.1.2: atom by atom, first the triangle
    // whose base lies on the atom's row towards the row below, then the one towards the row above.
    // The last row writes its downward triangles rotated (i, below, i+1), as the appendix does.
    for (int32_t r = 0; r < o_.rows; ++r) {
      for (int32_t j = 0; j < RowLength(r); ++j) {
        const int32_t i = row_start_[r] + j;
        const int32_t left = j > 0 ? i - 1 : -1, right = j + 1 < RowLength(r) ? i + 1 : -1;
        if (r == o_.rows - 1 && r > 0) {
          if (right >= 0) AddTri(m, i, Between(r - 1, r, j, j + 1), right);
          continue;
        }
        if (r > 0 && left >= 0) AddTri(m, i, left, Between(r - 1, r, j - 1, j));
        if (r + 1 < o_.rows && right >= 0) AddTri(m, i, right, Between(r + 1, r, j, j + 1));
      }
    }

    // Top grid edges: along each row, then to the row above.
    for (int32_t r = 0; r < o_.rows; ++r) {
      for (int32_t j = 0; j + 1 < RowLength(r); ++j) AddElem(m, row_start_[r] + j, row_start_[r] + j + 1, o_.k, o_.b);
    }
    for (int32_t r = 0; r + 1 < o_.rows; ++r) {
      for (int32_t j = 0; j < RowLength(r); ++j) {
        const int32_t i = row_start_[r] + j;
        // Even (short) rows touch above atoms j and j+1; odd (long) rows touch j-1 and j.
        const int32_t lo = r % 2 == 0 ? j : j - 1;
        for (int32_t u = lo; u <= lo + 1; ++u) {
          if (u >= 0 && u < RowLength(r + 1)) AddElem(m, i, row_start_[r + 1] + u, o_.k, o_.b);
        }
      }
    }

    // Apex atoms under every triangle whose base lies on its lower row: a regular tetrahedron
    // each, and in the lower layer a triangular lattice of the same spacing.
    std::vector<int32_t> band_start(o_.rows, 0);
    int32_t first_apex = m.num_atoms = static_cast<int32_t>(m.atom_mass.size());
    for (int32_t r = 0; r + 1 < o_.rows; ++r) {
      band_start[r] = static_cast<int32_t>(m.atom_mass.size());
      for (int32_t j = 0; j + 1 < RowLength(r); ++j) {
        const int32_t a = row_start_[r] + j, b = a + 1, c = Between(r + 1, r, j, j + 1);
        const double* pa = &m.atom_pos_eq[3 * a];
        const double* pb = &m.atom_pos_eq[3 * b];
        const double* pc = &m.atom_pos_eq[3 * c];
        const int32_t apex = AddAtom(m, (pa[0] + pb[0] + pc[0]) / 3, (pa[1] + pb[1] + pc[1]) / 3, -depth, false, false);
        AddElem(m, a, apex, o_.k, o_.b);
        AddElem(m, b, apex, o_.k, o_.b);
        AddElem(m, c, apex, o_.k, o_.b);
      }
    }
    (void)first_apex;
    // Lower-layer lattice: neighbours along a band, then to the next band (apex rows are
    // staggered like the top rows, so band r's apex j meets band r+1's apexes j-1+p and j+p).
    for (int32_t r = 0; r + 1 < o_.rows; ++r) {
      const int32_t n = RowLength(r) - 1;
      for (int32_t j = 0; j + 1 < n; ++j) AddElem(m, band_start[r] + j, band_start[r] + j + 1, o_.k, o_.b);
      if (r + 2 >= o_.rows) continue;
      const int32_t n_next = RowLength(r + 1) - 1;
      const int32_t lo = r % 2 == 0 ? 0 : -1;  // even bands are the shorter ones
      for (int32_t j = 0; j < n; ++j) {
        for (int32_t u = j + lo; u <= j + lo + 1; ++u) {
          if (u >= 0 && u < n_next) AddElem(m, band_start[r] + j, band_start[r + 1] + u, o_.k, o_.b);
        }
      }
    }

    // Home elements: every external atom to its home atom, rest length zero.
    for (int32_t i = 0; i < num_top; ++i) AddElem(m, i, num_top + i, o_.home_k, o_.home_b);

    FinalizeModel(m);
    ApplyInclusions(o_.inclusions, &m);
    return m;
  }

 private:
  int32_t RowLength(int32_t r) const { return r % 2 == 0 ? o_.cols : o_.cols + 1; }

  // The atom of row `r` lying between atoms j0 and j1 of the neighbouring row `r_from`.
  int32_t Between(int32_t r, int32_t r_from, int32_t j0, int32_t j1) const {
    IDMS_CHECK(j1 == j0 + 1);
    // A short (even) row's gap j..j+1 faces long-row atom j+1; a long row's gap faces short atom j.
    const int32_t j = r_from % 2 == 0 ? j1 : j0;
    return row_start_[r] + j;
  }

  double Round(double v) const {
    if (o_.decimals < 0) return v;
    const double scale = std::pow(10.0, o_.decimals);
    const double rounded = std::round(v * scale) / scale;
    return rounded == 0.0 ? 0.0 : rounded;  // no negative zero in files
  }

  int32_t AddAtom(Model& m, double x, double y, double z, bool fixed, bool external) {
    m.atom_pos_eq.insert(m.atom_pos_eq.end(), {Round(x), Round(y), Round(z)});
    m.atom_mass.push_back(o_.mass);
    m.atom_fixed.push_back(fixed);
    m.atom_external.push_back(external);
    return static_cast<int32_t>(m.atom_mass.size()) - 1;
  }

  static void AddElem(Model& m, int32_t a, int32_t b, double k, double damping) {
    m.elem_atoms.insert(m.elem_atoms.end(), {a, b});
    m.elem_k.push_back(k);
    m.elem_b.push_back(damping);
  }

  static void AddTri(Model& m, int32_t a, int32_t b, int32_t c) { m.tri_atoms.insert(m.tri_atoms.end(), {a, b, c}); }

  const SlabOptions& o_;
  std::vector<int32_t> row_start_;  // (rows + 1): first top atom of each row
};

bool Inside(const Inclusion& inc, const double* p) {
  const double dx = p[0] - inc.center[0], dy = p[1] - inc.center[1], dz = p[2] - inc.center[2];
  return dx * dx + dy * dy + dz * dz <= inc.radius * inc.radius;
}

}  // namespace

Model GenerateSlab(const SlabOptions& options) {
  IDMS_CHECK(options.rows >= 2 && options.cols >= 1 && options.spacing > 0);
  return SlabBuilder(options).Build();
}

void ApplyInclusions(const std::vector<Inclusion>& inclusions, Model* model) {
  Model& m = *model;
  for (const Inclusion& inc : inclusions) {
    for (int32_t i = 0; i < m.num_atoms; ++i) {
      if (!m.atom_fixed[i] && Inside(inc, &m.atom_pos_eq[3 * i])) m.atom_mass[i] *= inc.mass_scale;
    }
    for (int32_t e = 0; e < m.num_elems; ++e) {
      const double* p0 = &m.atom_pos_eq[3 * m.elem_atoms[2 * e]];
      const double* p1 = &m.atom_pos_eq[3 * m.elem_atoms[2 * e + 1]];
      const double mid[3] = {(p0[0] + p1[0]) / 2, (p0[1] + p1[1]) / 2, (p0[2] + p1[2]) / 2};
      if (Inside(inc, mid)) m.elem_k[e] *= inc.k_scale;
    }
  }
}

}  // namespace idms
