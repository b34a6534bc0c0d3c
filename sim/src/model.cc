// FinalizeModel derives adjacency, rest lengths and the surface lists.
#include "idms/sim/model.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "idms/sim/check.h"
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

  // Step constants: bounds per free atom, the longest element, damping present.
  m.max_leq = 0;
  m.has_damping = false;
  for (int32_t e = 0; e < m.num_elems; ++e) {
    m.max_leq = std::max(m.max_leq, m.elem_leq[e]);
    m.has_damping = m.has_damping || m.elem_b[e] > 0;
  }
  m.atom_omega2.assign(m.num_atoms, 0.0);
  m.atom_damp.assign(m.num_atoms, 0.0);
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    if (m.atom_fixed[a] || !(m.atom_mass[a] > 0)) continue;  // a massless free atom is refused by MakeWorkspace
    const AtomBound bound = GershgorinBound(m, a);
    m.atom_omega2[a] = bound.omega2;
    m.atom_damp[a] = bound.c;
  }
}

int64_t ModelBytes(const Model& m) {
  return Bytes(m.atom_pos_eq) + Bytes(m.atom_mass) + Bytes(m.atom_fixed) + Bytes(m.atom_external) +
         Bytes(m.elem_atoms) + Bytes(m.elem_k) + Bytes(m.elem_b) + Bytes(m.elem_leq) + Bytes(m.elem_home) +
         Bytes(m.external_atoms) + Bytes(m.atom_external_id) + Bytes(m.tri_atoms) + Bytes(m.atom_elem_adr) +
         Bytes(m.atom_elem_num) + Bytes(m.atom_elem) + Bytes(m.atom_omega2) + Bytes(m.atom_damp) +
         static_cast<int64_t>(m.name.capacity());
}

}  // namespace idms
