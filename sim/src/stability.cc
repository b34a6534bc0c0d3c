// Gershgorin bounds and the closed-form stable steps of explicit and symplectic Euler.
#include "idms/sim/stability.h"

#include <cmath>
#include <limits>

#include "idms/sim/model.h"

namespace idms {

AtomBound GershgorinBound(const Model& model, int32_t atom, double extra_k, double extra_b) {
  double centre_k = extra_k, radius_k = 0, centre_b = extra_b, radius_b = 0;
  const int32_t adr = model.atom_elem_adr[atom];
  for (int32_t j = 0; j < model.atom_elem_num[atom]; ++j) {
    const int32_t e = model.atom_elem[adr + j];
    const int32_t a0 = model.elem_atoms[2 * e];
    const int32_t other = a0 == atom ? model.elem_atoms[2 * e + 1] : a0;
    centre_k += model.elem_k[e];
    centre_b += model.elem_b[e];
    // A fixed neighbour has no row of its own, so it adds no off-diagonal term.
    if (!model.atom_fixed[other]) {
      radius_k += model.elem_k[e];
      radius_b += model.elem_b[e];
    }
  }
  const double m = model.atom_mass[atom];
  return {(centre_k + radius_k) / m, (centre_b + radius_b) / m};
}

double EulerStableDt(const AtomBound& bound) {
  const double w2 = bound.omega2, c = bound.c;
  if (w2 <= 0) return c > 0 ? 2.0 / c : std::numeric_limits<double>::infinity();
  if (c * c < 4 * w2) return c / w2;                      // underdamped: |1 + lambda T|^2 = 1 - cT + w2 T^2
  return 2.0 / (0.5 * c + std::sqrt(0.25 * c * c - w2));  // overdamped: the faster real root
}

double SymplecticStableDt(const AtomBound& bound) {
  const double w2 = bound.omega2, c = bound.c;
  if (w2 <= 0) return c > 0 ? 2.0 / c : std::numeric_limits<double>::infinity();
  // Jury: 1 - cT > -1 and 4 - 2cT - w2 T^2 > 0; the second is the binding one for w2 > 0.
  return (-c + std::sqrt(c * c + 4 * w2)) / w2;
}

}  // namespace idms
