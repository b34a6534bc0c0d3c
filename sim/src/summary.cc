#include "idms/sim/summary.h"

#include <algorithm>
#include <limits>

#include "idms/sim/integrate.h"
#include "idms/sim/stability.h"

namespace idms {

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
    const AtomBound bound{m.atom_omega2[i], m.atom_damp[i]};  // FinalizeModel's Gershgorin bound
    // The thesis's scheme: explicit Euler with the eq. 4.6 backward-difference rate (lambda = 1).
    dt_euler = std::min(dt_euler, StableDt(Integrator::kExplicitEuler, bound, LengthRate::kFiltered, 1.0));
    dt_symplectic = std::min(dt_symplectic, StableDt(Integrator::kSymplecticEuler, bound, LengthRate::kAnalytic, 1.0));
  }
  s.stable_dt_euler = dt_euler;
  s.stable_dt_symplectic = dt_symplectic;
  return s;
}

}  // namespace idms
