// Stable-step predictions for the explicit integrators (thesis 4.2), from Gershgorin bounds.
// Used by `idms-sim validate` and by the step to choose substeps.
#pragma once

#include <cstdint>

namespace idms {

struct Model;

// Upper bounds on the linearised dynamics of one free atom: every eigenvalue of M^-1 K in the
// atom's Gershgorin row is <= omega2, every eigenvalue of M^-1 B is <= c. Units 1/s^2 and 1/s.
struct AtomBound {
  double omega2 = 0;
  double c = 0;
};

// Gershgorin row of free atom `atom`: centre sum(k)/m plus radius sum over free neighbours of
// k/m (fixed neighbours add to the centre only). `extra_k` adds a stiffness acting on the atom
// alone, such as a tool's contact stiffness. Does not allocate.
AtomBound GershgorinBound(const Model& model, int32_t atom, double extra_k = 0, double extra_b = 0);

// Largest T for which explicit Euler on x'' + c x' + omega2 x = 0 has |z| <= 1:
// c / omega2 when underdamped, 2 / (c/2 + sqrt(c^2/4 - omega2)) when overdamped. 0 when c = 0
// and omega2 > 0 (undamped oscillators are never stable under explicit Euler); +inf when omega2 = c = 0.
double EulerStableDt(const AtomBound& bound);

// Largest T for symplectic Euler (v first, then x with the new v) on the same oscillator:
// (-c + sqrt(c^2 + 4 omega2)) / omega2, and 2 / c when omega2 = 0 (Jury criterion).
double SymplecticStableDt(const AtomBound& bound);

}  // namespace idms
