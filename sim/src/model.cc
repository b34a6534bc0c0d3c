// FinalizeModel derives adjacency, rest lengths and the surface lists; Summarize reports.
#include "idms/sim/model.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "idms/sim/check.h"
#include "idms/sim/integrate.h"
#include "idms/sim/stability.h"

namespace idms {
namespace {

double Distance(const std::vector<double>& p, int32_t a, int32_t b) {
  const double dx = p[3 * b] - p[3 * a], dy = p[3 * b + 1] - p[3 * a + 1], dz = p[3 * b + 2] - p[3 * a + 2];
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

template <class T>
int64_t Bytes(const std::vector<T>& v) {
  return static_cast<int64_t>(v.capacity() * sizeof(T));
}

}  // namespace

void FinalizeModel(Model& m) {
  m.num_atoms = static_cast<int32_t>(m.atom_mass.size());
  m.num_elems = static_cast<int32_t>(m.elem_k.size());
  m.num_tris = static_cast<int32_t>(m.tri_atoms.size() / 3);
  IDMS_CHECK(m.atom_pos_eq.size() == 3 * m.atom_mass.size());
  IDMS_CHECK(m.atom_fixed.size() == m.atom_mass.size() && m.atom_external.size() == m.atom_mass.size());
  IDMS_CHECK(m.elem_atoms.size() == 2 * m.elem_k.size() && m.elem_b.size() == m.elem_k.size());

  // The surface list, in file order (plg vertex i is the i-th external atom).
  m.external_atoms.clear();
  m.atom_external_id.assign(m.num_atoms, -1);
  for (int32_t i = 0; i < m.num_atoms; ++i) {
    if (!m.atom_external[i]) continue;
    m.atom_external_id[i] = static_cast<int32_t>(m.external_atoms.size());
    m.external_atoms.push_back(i);
  }
  m.num_external = static_cast<int32_t>(m.external_atoms.size());

  // Rest lengths and home elements (an external atom tied to a fixed atom at its rest position).
  m.elem_leq.resize(m.num_elems);
  m.elem_home.resize(m.num_elems);
  for (int32_t e = 0; e < m.num_elems; ++e) {
    const int32_t a0 = m.elem_atoms[2 * e], a1 = m.elem_atoms[2 * e + 1];
    IDMS_CHECK(a0 >= 0 && a0 < m.num_atoms && a1 >= 0 && a1 < m.num_atoms && a0 != a1);
    m.elem_leq[e] = Distance(m.atom_pos_eq, a0, a1);
    const bool tie = (m.atom_external[a0] && m.atom_fixed[a1]) || (m.atom_external[a1] && m.atom_fixed[a0]);
    m.elem_home[e] = tie && m.elem_leq[e] == 0.0;
  }

  // CSR adjacency: count, prefix sum, fill in element order.
  m.atom_elem_num.assign(m.num_atoms, 0);
  for (int32_t id : m.elem_atoms) ++m.atom_elem_num[id];
  m.atom_elem_adr.resize(m.num_atoms);
  int32_t adr = 0;
  for (int32_t i = 0; i < m.num_atoms; ++i) {
    m.atom_elem_adr[i] = adr;
    adr += m.atom_elem_num[i];
  }
  m.atom_elem.resize(adr);
  std::vector<int32_t> fill(m.atom_elem_adr);
  for (int32_t e = 0; e < m.num_elems; ++e) {
    m.atom_elem[fill[m.elem_atoms[2 * e]]++] = e;
    m.atom_elem[fill[m.elem_atoms[2 * e + 1]]++] = e;
  }
}

int64_t ModelBytes(const Model& m) {
  return Bytes(m.atom_pos_eq) + Bytes(m.atom_mass) + Bytes(m.atom_fixed) + Bytes(m.atom_external) +
         Bytes(m.elem_atoms) + Bytes(m.elem_k) + Bytes(m.elem_b) + Bytes(m.elem_leq) + Bytes(m.elem_home) +
         Bytes(m.external_atoms) + Bytes(m.atom_external_id) + Bytes(m.tri_atoms) + Bytes(m.atom_elem_adr) +
         Bytes(m.atom_elem_num) + Bytes(m.atom_elem) + static_cast<int64_t>(m.name.capacity());
}

ModelSummary Summarize(const Model& m) {
  ModelSummary s;
  s.atoms = m.num_atoms;
  s.elements = m.num_elems;
  s.triangles = m.num_tris;
  s.external_atoms = m.num_external;
  const double inf = std::numeric_limits<double>::infinity();
  for (int c = 0; c < 3; ++c) s.bbox_min[c] = inf, s.bbox_max[c] = -inf;
  for (int32_t i = 0; i < m.num_atoms; ++i) {
    (m.atom_fixed[i] ? s.fixed_atoms : s.free_atoms)++;
    s.total_mass += m.atom_mass[i];
    for (int c = 0; c < 3; ++c) {
      s.bbox_min[c] = std::min(s.bbox_min[c], m.atom_pos_eq[3 * i + c]);
      s.bbox_max[c] = std::max(s.bbox_max[c], m.atom_pos_eq[3 * i + c]);
    }
  }
  if (m.num_atoms == 0) std::fill(s.bbox_min, s.bbox_min + 3, 0.0), std::fill(s.bbox_max, s.bbox_max + 3, 0.0);

  if (m.num_elems > 0) {
    const auto [kmin, kmax] = std::minmax_element(m.elem_k.begin(), m.elem_k.end());
    const auto [bmin, bmax] = std::minmax_element(m.elem_b.begin(), m.elem_b.end());
    s.k_min = *kmin, s.k_max = *kmax, s.b_min = *bmin, s.b_max = *bmax;
  }
  for (uint8_t h : m.elem_home) s.home_elements += h;

  // The most restrictive free atom sets the predicted stable step.
  double dt_euler = inf, dt_symplectic = inf;
  for (int32_t i = 0; i < m.num_atoms; ++i) {
    if (m.atom_fixed[i]) continue;
    const AtomBound bound = GershgorinBound(m, i);
    // The thesis's scheme: explicit Euler with the eq. 4.6 backward-difference rate (lambda = 1).
    dt_euler = std::min(dt_euler, StableDt(Integrator::kExplicitEuler, bound, LengthRate::kFiltered, 1.0));
    dt_symplectic = std::min(dt_symplectic, StableDt(Integrator::kSymplecticEuler, bound, LengthRate::kAnalytic, 1.0));
  }
  s.stable_dt_euler = dt_euler;
  s.stable_dt_symplectic = dt_symplectic;
  return s;
}

}  // namespace idms
