// The haptic-window system of thesis figure 4-2, its integrators' one-step matrices, and the
// spectral-radius tests behind `idms-sim stability`.
#include "idms/sim/haptic_window.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

#include "idms/sim/check.h"
#include "idms/sim/integrate.h"
#include "idms/sim/stability.h"

namespace idms {
namespace {

// Symplectic Euler from the blocks of A in (position, velocity) order: the velocity rows step
// with the old state, the position rows with the new velocity.
Eigen::MatrixXd SymplecticMatrix(const Eigen::MatrixXd& a, double dt_s) {
  const Eigen::Index n = a.rows() / 2;
  Eigen::MatrixXd a_pp(n, n), a_pv(n, n), a_vp(n, n), a_vv(n, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = 0; j < n; ++j) {
      a_pp(i, j) = a(2 * i, 2 * j), a_pv(i, j) = a(2 * i, 2 * j + 1);
      a_vp(i, j) = a(2 * i + 1, 2 * j), a_vv(i, j) = a(2 * i + 1, 2 * j + 1);
    }
  }
  // v(n+1) = T A_vp x(n) + (I + T A_vv) v(n)
  const Eigen::MatrixXd id = Eigen::MatrixXd::Identity(n, n);
  const Eigen::MatrixXd m_vp = dt_s * a_vp;
  const Eigen::MatrixXd m_vv = id + dt_s * a_vv;
  // x(n+1) = x(n) + T (A_pp x(n) + A_pv v(n+1)); for eq. 4.17 A_pp = 0 and A_pv = I
  const Eigen::MatrixXd m_pp = id + dt_s * a_pp + dt_s * a_pv * m_vp;
  const Eigen::MatrixXd m_pv = dt_s * a_pv * m_vv;
  // Back to the interleaved layout of A.
  Eigen::MatrixXd a_z(a.rows(), a.cols());
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = 0; j < n; ++j) {
      a_z(2 * i, 2 * j) = m_pp(i, j), a_z(2 * i, 2 * j + 1) = m_pv(i, j);
      a_z(2 * i + 1, 2 * j) = m_vp(i, j), a_z(2 * i + 1, 2 * j + 1) = m_vv(i, j);
    }
  }
  return a_z;
}

// Bisects [stable_lo, unstable_hi] (either order) until it is `tol` wide; returns its middle.
double Bisect(const std::function<bool(double)>& stable_at, double stable_end, double unstable_end, double tol) {
  for (int iter = 0; iter < 200 && std::abs(unstable_end - stable_end) > tol; ++iter) {
    const double mid = 0.5 * (stable_end + unstable_end);
    (stable_at(mid) ? stable_end : unstable_end) = mid;
  }
  return 0.5 * (stable_end + unstable_end);
}

}  // namespace

Eigen::MatrixXd HapticWindowA(const HapticWindowParams& p) {
  const double km = p.k / p.m, bm = p.b / p.m;
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(6, 6);
  for (int i = 0; i < 3; ++i) {
    // eq. 4.17: x_{2i+1}' = x_{2i+2}; mass i+1 feels -3(k, b) on itself (two neighbours or
    // ground, plus home) and +(k, b) from each neighbouring mass.
    a(2 * i, 2 * i + 1) = 1;
    a(2 * i + 1, 2 * i) = -3 * km, a(2 * i + 1, 2 * i + 1) = -3 * bm;
    if (i > 0) a(2 * i + 1, 2 * i - 2) = km, a(2 * i + 1, 2 * i - 1) = bm;
    if (i < 2) a(2 * i + 1, 2 * i + 2) = km, a(2 * i + 1, 2 * i + 3) = bm;
  }
  return a;
}

Eigen::MatrixXd OneStepMatrix(const Eigen::MatrixXd& a, Integrator integrator, double dt_s) {
  IDMS_CHECK(a.rows() == a.cols() && a.rows() % 2 == 0 && dt_s > 0);
  const Eigen::MatrixXd id = Eigen::MatrixXd::Identity(a.rows(), a.cols());
  const Eigen::MatrixXd at = a * dt_s;
  switch (integrator) {
    case Integrator::kExplicitEuler:
      // eq. 4.18: A_z = A T + I
      return id + at;
    case Integrator::kSymplecticEuler:
      return SymplecticMatrix(a, dt_s);
    case Integrator::kRk4:
      // Taylor series to 4th order, in Horner form.
      return id + at * (id + at / 2 * (id + at / 3 * (id + at / 4)));
    case Integrator::kImplicitEuler:
      // I - A T is invertible whenever no eigenvalue of A equals 1/T (always for k, b >= 0).
      return (id - at).fullPivLu().inverse();
  }
  IDMS_CHECK(false);
  return id;
}

std::vector<std::complex<double>> SortedEigenvalues(const Eigen::MatrixXd& matrix) {
  // Overflowed entries (absurd parameters) or no convergence: NaN, which is never stable.
  const std::complex<double> nan(std::numeric_limits<double>::quiet_NaN(), 0.0);
  if (!matrix.allFinite()) return std::vector<std::complex<double>>(matrix.rows(), nan);
  // Eigen's default 40 QR sweeps per row fail on ~1 in 2000 window matrices (an exceptional
  // shift cycle; e.g. RK4 at k = 386.77193); 1000 in all never did in a scan of 4e5 of them,
  // so allow 200 per row, with the complex QR as a second opinion.
  Eigen::EigenSolver<Eigen::MatrixXd> solver;
  solver.setMaxIterations(200 * static_cast<Eigen::Index>(matrix.rows()));
  solver.compute(matrix, /*computeEigenvectors=*/false);
  std::vector<std::complex<double>> eig;
  if (solver.info() == Eigen::Success) {
    eig.assign(solver.eigenvalues().begin(), solver.eigenvalues().end());
  } else {
    Eigen::ComplexEigenSolver<Eigen::MatrixXcd> complex_solver(matrix.cast<std::complex<double>>(), false);
    if (complex_solver.info() != Eigen::Success) return std::vector<std::complex<double>>(matrix.rows(), nan);
    eig.assign(complex_solver.eigenvalues().begin(), complex_solver.eigenvalues().end());
  }
  std::sort(eig.begin(), eig.end(), [](const std::complex<double>& x, const std::complex<double>& y) {
    const double ax = std::abs(x), ay = std::abs(y);
    return ax != ay ? ax > ay : x.imag() > y.imag();
  });
  return eig;
}

bool IsStableRadius(double spectral_radius) { return spectral_radius < 1.0 - kMarginalTol; }

StabilityReport AnalyzeStability(const Eigen::MatrixXd& a, Integrator integrator, double dt_s) {
  StabilityReport report;
  report.continuous = SortedEigenvalues(a);
  report.discrete = SortedEigenvalues(OneStepMatrix(a, integrator, dt_s));
  // Sorted by modulus, so the first is the spectral radius.
  report.spectral_radius = report.discrete.empty() ? 0.0 : std::abs(report.discrete.front());
  report.stable = IsStableRadius(report.spectral_radius);
  return report;
}

StabilityReport AnalyzeHapticWindow(const HapticWindowParams& params, Integrator integrator) {
  return AnalyzeStability(HapticWindowA(params), integrator, params.dt_s);
}

double EulerEdgeDt(const std::vector<std::complex<double>>& continuous) {
  double edge = std::numeric_limits<double>::infinity();
  for (const std::complex<double>& lambda : continuous) {
    // |1 + lambda T|^2 = 1 + 2 Re(lambda) T + |lambda|^2 T^2 = 1 at T = -2 Re / |lambda|^2.
    const double re = lambda.real(), norm2 = std::norm(lambda);
    edge = std::min(edge, re < 0 ? -2 * re / norm2 : 0.0);
  }
  return edge;
}

double StabilityLimitDt(const Eigen::MatrixXd& a, Integrator integrator, double dt_max) {
  const auto stable_at = [&](double dt_s) {
    const std::vector<std::complex<double>> z = SortedEigenvalues(OneStepMatrix(a, integrator, dt_s));
    return IsStableRadius(std::abs(z.front()));
  };
  // Start well below the fastest time constant, where every consistent method is near 1 + lambda T.
  const std::vector<std::complex<double>> lambda = SortedEigenvalues(a);
  const double rho = std::abs(lambda.front());
  if (!(rho > 0) || !std::isfinite(rho)) return 0;
  double dt_s = 1e-3 / rho;
  if (!stable_at(dt_s)) return 0;
  // Geometric scan for the first unstable step, then bisection between the last two samples.
  while (dt_s < dt_max) {
    const double next = std::min(dt_s * 1.05, dt_max);
    if (!stable_at(next)) return Bisect(stable_at, dt_s, next, 1e-12 * next);
    dt_s = next;
  }
  return std::numeric_limits<double>::infinity();
}

std::vector<StabilityEdge> FindStabilityEdges(const std::function<bool(double)>& stable_at, double lo, double hi,
                                              int num_steps) {
  IDMS_CHECK(num_steps >= 2 && hi > lo);
  std::vector<StabilityEdge> edges;
  const double tol = (hi - lo) * 1e-12;
  double prev_value = lo;
  bool prev_stable = stable_at(lo);
  for (int i = 1; i < num_steps; ++i) {
    const double value = lo + (hi - lo) * i / (num_steps - 1);
    const bool stable = stable_at(value);
    // A flip between two samples: bisect it, keeping the stable end on the stable side.
    if (stable != prev_stable) {
      const double edge =
          stable ? Bisect(stable_at, value, prev_value, tol) : Bisect(stable_at, prev_value, value, tol);
      edges.push_back({edge, stable});
    }
    prev_value = value, prev_stable = stable;
  }
  return edges;
}

Model HapticWindowModel(const HapticWindowParams& p) {
  Model model;
  model.name = "haptic_window";
  // Atoms: masses 1..3 at x = 1..3 (free, external), ground at x = 0 and 4, homes at x = 1..3.
  const double xs[8] = {1, 2, 3, 0, 4, 1, 2, 3};
  for (int i = 0; i < 8; ++i) {
    const bool free_atom = i < 3;
    model.atom_pos_eq.insert(model.atom_pos_eq.end(), {xs[i], 0.0, 0.0});
    model.atom_mass.push_back(free_atom ? p.m : 0.0);
    model.atom_fixed.push_back(free_atom ? 0 : 1);
    model.atom_external.push_back(free_atom ? 1 : 0);
  }
  // Elements of figure 4-2: ground-1, 1-2, 2-3, 3-ground, and a home element per mass.
  const int32_t pairs[7][2] = {{3, 0}, {0, 1}, {1, 2}, {2, 4}, {5, 0}, {6, 1}, {7, 2}};
  for (const auto& pair : pairs) {
    model.elem_atoms.insert(model.elem_atoms.end(), {pair[0], pair[1]});
    model.elem_k.push_back(p.k);
    model.elem_b.push_back(p.b);
  }
  FinalizeModel(model);
  return model;
}

std::optional<double> GershgorinStableDt(const HapticWindowParams& params, Integrator integrator) {
  if (integrator != Integrator::kExplicitEuler && integrator != Integrator::kSymplecticEuler) return std::nullopt;
  // Eq. 4.17 damps with the analytic length rate, so the prediction must too (Summarize reports
  // the thesis's filtered eq. 4.6 scheme, whose limit is about half as long).
  const Model model = HapticWindowModel(params);
  double dt = std::numeric_limits<double>::infinity();
  for (int32_t i = 0; i < model.num_atoms; ++i) {
    if (!model.atom_fixed[i])
      dt = std::min(dt,
                    StableDt(integrator, AtomBound{model.atom_omega2[i], model.atom_damp[i]}, LengthRate::kAnalytic));
  }
  return dt;
}

}  // namespace idms
