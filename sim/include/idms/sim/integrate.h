// Stable-step predictions per integrator (thesis 4.2 and past it), from the per-atom Gershgorin
// bounds of stability.h. The step uses them to choose substeps or the implicit fallback.
#pragma once

#include "idms/sim/stability.h"
#include "idms/sim/step.h"

namespace idms {

// Largest step for which `integrator` is predicted stable on x'' + c x' + omega2 x = 0 with the
// bound's omega2 and c. Does not allocate.
//  - explicit Euler, analytic rate: EulerStableDt (c / omega2 underdamped; 0 when undamped);
//  - explicit Euler, eq. 4.6 filtered rate: lambda c / (omega2 + c^2). The filter lags the rate
//    by one step, which turns the scalar test equation into a third-order recurrence
//    z^3 - 2z^2 + (1 + T^2 omega2 + T c) z - T c; its Jury conditions give exactly
//    T < c / (omega2 + c^2) for lambda = 1 (about half the analytic limit on the thesis's
//    fragment). For lambda < 1 the factor lambda is an empirical lower bound, checked against
//    the companion matrix over omega2 in [1, 1e12], c in [1e-2, 1e6], lambda in [0.1, 1];
//  - symplectic Euler: SymplecticStableDt, times lambda with the filtered rate (the filter then
//    sees the new velocity: for lambda = 1 it equals the analytic rate);
//  - RK4: 2.5 / max(omega, c) (the left half-disc of radius 2.5 lies in RK4's stability region);
//  - implicit Euler: +inf.
double StableDt(Integrator integrator, const AtomBound& bound, LengthRate rate = LengthRate::kAnalytic,
                double lambda = 1.0);

}  // namespace idms
