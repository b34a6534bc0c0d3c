// Linear stability of the integrators on the 6th-order haptic-window system of thesis figure 4-2
// (eqs. 4.16-4.18): the continuous matrix A, each integrator's one-step matrix, their spectra.
// Used by `idms-sim stability` and its root loci (figures 4-3 to 4-6). Not for the 1 kHz loop.
#pragma once

#include <Eigen/Core>
#include <complex>
#include <functional>
#include <optional>
#include <vector>

#include "idms/sim/model.h"
#include "idms/sim/step.h"  // Integrator: the same four schemes the step runs

namespace idms {

// Media-fragment parameters of figure 4-2. Defaults are the thesis's nominal values (4.2).
struct HapticWindowParams {
  double k = 15.0;      // element stiffness, force / length, >= 0
  double b = 0.45;      // element viscosity, force / (length / s), >= 0
  double m = 0.002;     // atom mass, > 0
  double dt_s = 0.001;  // time step T, s, > 0
};

// A pole on the unit circle (|z| within this of 1) is not asymptotically stable, so "stable"
// means radius < 1 - kMarginalTol: a free mode (k = b = 0) sits at z = 1 exactly and drifts,
// and symplectic Euler on an undamped window (b = 0) keeps every pole on the circle (bounded,
// never decaying); both are reported not stable. 1e-9 is far above the eigensolver's error on
// these 6x6 matrices (~1e-14) and far below any margin that matters; it moves a reported edge
// by ~1e-8 relative (k = b / T comes out as 449.999997 instead of 450).
inline constexpr double kMarginalTol = 1e-9;

// eq. 4.17 exactly as written: state x1..x6 = position and velocity of masses 1, 2, 3; each mass
// tied by (k, b) to its neighbours, to its home position and, at the ends, to ground.
Eigen::MatrixXd HapticWindowA(const HapticWindowParams& params);

// The one-step matrix A_z (x[n+1] = A_z x[n]) of `integrator` with step dt_s > 0 on x' = A x.
// `a` is square of even size with states interleaved (position, velocity) per degree of freedom,
// as in eq. 4.17; symplectic Euler relies on that layout. Allocates.
//   kExplicitEuler:   I + A T (eq. 4.18)
//   kSymplecticEuler: v' = v + T a(x, v), then x' = x + T v' (position rows use the new velocity)
//   kRk4:             I + AT + (AT)^2/2 + (AT)^3/6 + (AT)^4/24
//   kImplicitEuler:   (I - A T)^-1, backward Euler on the linear system
Eigen::MatrixXd OneStepMatrix(const Eigen::MatrixXd& a, Integrator integrator, double dt_s);

// Eigenvalues sorted by decreasing modulus, then decreasing imaginary part (conjugate pairs
// adjacent, positive first). All NaN when `matrix` is not finite or the solver fails. Allocates.
std::vector<std::complex<double>> SortedEigenvalues(const Eigen::MatrixXd& matrix);

struct StabilityReport {
  std::vector<std::complex<double>> continuous;  // eig(A), 1/s
  std::vector<std::complex<double>> discrete;    // eig(A_z), z-plane
  double spectral_radius = 0;                    // max |z|; NaN if the matrix overflowed
  bool stable = false;                           // spectral_radius < 1 - kMarginalTol
};

StabilityReport AnalyzeStability(const Eigen::MatrixXd& a, Integrator integrator, double dt_s);
StabilityReport AnalyzeHapticWindow(const HapticWindowParams& params, Integrator integrator);

bool IsStableRadius(double spectral_radius);

// Exact explicit-Euler edge from continuous eigenvalues: |1 + lambda T| = 1 at
// T = -2 Re(lambda) / |lambda|^2; the smallest such T over all lambda. An eigenvalue with
// Re >= 0 is never inside the circle, so it gives 0. +inf for an empty list.
double EulerEdgeDt(const std::vector<std::complex<double>>& continuous);

// Smallest dt in (0, dt_max] at which the one-step matrix stops being stable, by a geometric
// scan (ratio 1.05) from 1e-3 / rho(A) and bisection to relative 1e-12. +inf when none is found
// (e.g. implicit Euler), 0 when the system is not stable even at the first scanned step.
double StabilityLimitDt(const Eigen::MatrixXd& a, Integrator integrator, double dt_max);

// Parameter values in [lo, hi] where `stable_at` changes, found on `num_steps` uniform samples
// and refined by bisection to |hi - lo| * 1e-12. Each entry: the value, and whether the stable
// side is above it. Misses a stable island narrower than the sample spacing. Calls stable_at O(num_steps + 40 *
// crossings) times.
struct StabilityEdge {
  double value = 0;
  bool stable_above = false;
};
std::vector<StabilityEdge> FindStabilityEdges(const std::function<bool(double)>& stable_at, double lo, double hi,
                                              int num_steps);

// Figure 4-2 as a DSM Model (3 free atoms on the x axis, 2 fixed ground atoms, 3 fixed home
// atoms with zero-length home elements), so stability.h's Gershgorin bounds apply to it.
Model HapticWindowModel(const HapticWindowParams& params);

// The stable step stability.h predicts for the window (Summarize over its free atoms: the
// middle atom's row has centre 3k/m and radius 2k/m, damping likewise). Explicit and symplectic
// Euler only; nullopt for RK4 and implicit Euler, for which stability.h has no prediction.
std::optional<double> GershgorinStableDt(const HapticWindowParams& params, Integrator integrator);

}  // namespace idms
