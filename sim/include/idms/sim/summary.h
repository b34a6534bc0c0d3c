// A model's summary figures, as `idms-sim validate` prints them: counts, bounds, parameter ranges
// and the stable steps a Gershgorin bound predicts. Kept apart from model.h so that the
// ground-floor data type does not depend on the integrators.
#pragma once

#include <cstdint>

#include "idms/sim/model.h"

namespace idms {

// Summary figures of a model, as `idms-sim validate` prints them.
struct ModelSummary {
  int32_t atoms = 0, free_atoms = 0, fixed_atoms = 0, external_atoms = 0;
  int32_t elements = 0, home_elements = 0, triangles = 0;
  double bbox_min[3] = {0, 0, 0}, bbox_max[3] = {0, 0, 0};
  double total_mass = 0;
  double k_min = 0, k_max = 0, b_min = 0, b_max = 0;
  // Largest step for which the thesis's scheme — explicit Euler (eqs. 4.13-4.14) with the eq. 4.6
  // backward-difference length rate — is predicted stable by a Gershgorin bound on the
  // linearised system (integrate.h StableDt); 0 when a free atom is undamped.
  double stable_dt_euler = 0;
  // The same for symplectic Euler (depends on stiffness only): 2 / omega_max.
  double stable_dt_symplectic = 0;
};

ModelSummary Summarize(const Model& model);

}  // namespace idms
