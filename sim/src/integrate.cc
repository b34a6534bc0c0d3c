// The explicit integrators over the active free atoms (thesis 4.1 block 4): explicit Euler
// exactly as eqs. 4.13-4.15, symplectic Euler and RK4; implicit Euler is in implicit.cc.
#include "idms/sim/integrate.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "idms/sim/model.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms::internal {
namespace {

// Forces at the current state, timed; adds weight * each tool's reaction to its tick force.
void Forces(const Model& m, State& s, Workspace& ws, bool filtered, Real T, double weight, StageTimes* times) {
  StageTimer timer(&times->forces_ns);
  EvaluateForces(m, s, ws, filtered, T);
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    for (int c = 0; c < 3; ++c) ws.tools[t].tick_force[c] += weight * ws.tools[t].eval_force[c];
    for (int c = 0; c < 3; ++c) ws.tools[t].tick_friction[c] += weight * ws.tools[t].eval_friction[c];
    ws.tools[t].tick_fn += weight * ws.tools[t].eval_fn;
  }
}

// Eqs. 4.13-4.15: x(n+1) = x(n) + T v(n), v(n+1) = v(n) + T a(n); p is stored absolute.
void ExplicitEulerUpdate(const Model& m, State& s, const Workspace& ws, Real T) {
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    const Real t_over_m = T / static_cast<Real>(m.atom_mass[a]);
    for (int c = 0; c < 3; ++c) {
      s.atom_pos[3 * a + c] += T * s.atom_vel[3 * a + c];
      s.atom_vel[3 * a + c] += t_over_m * ws.atom_force[3 * a + c];
    }
  }
}

// v(n+1) = v(n) + T a(x(n), v(n)); x(n+1) = x(n) + T v(n+1).
void SymplecticEulerUpdate(const Model& m, State& s, const Workspace& ws, Real T) {
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    const Real t_over_m = T / static_cast<Real>(m.atom_mass[a]);
    for (int c = 0; c < 3; ++c) {
      s.atom_vel[3 * a + c] += t_over_m * ws.atom_force[3 * a + c];
      s.atom_pos[3 * a + c] += T * s.atom_vel[3 * a + c];
    }
  }
}

// Classical RK4 on (x, v) with the analytic length rate; the tools hold still within the substep.
// Stage k: derivative (v_k, a_k) at x0 + c_k T (v, a)_{k-1}; weights 1, 2, 2, 1 over 6.
void Rk4Substep(const Model& m, State& s, Workspace& ws, Real T, int32_t substeps, StageTimes* times) {
  const int32_t n = ws.num_active;
  for (int32_t i = 0; i < n; ++i) {
    const int32_t a = ws.active[i];
    for (int c = 0; c < 3; ++c) {
      ws.rk_x0[3 * i + c] = s.atom_pos[3 * a + c];
      ws.rk_v0[3 * i + c] = s.atom_vel[3 * a + c];
      ws.rk_dx[3 * i + c] = ws.rk_dv[3 * i + c] = 0;
    }
  }
  const Real weight[4] = {1, 2, 2, 1};
  const Real advance[4] = {T / 2, T / 2, T, 0};  // where the next stage is evaluated
  for (int stage = 0; stage < 4; ++stage) {
    Forces(m, s, ws, /*filtered=*/false, T, weight[stage] / (6.0 * substeps), times);
    StageTimer timer(&times->integrate_ns);
    for (int32_t i = 0; i < n; ++i) {
      const int32_t a = ws.active[i];
      const Real inv_m = Real(1) / static_cast<Real>(m.atom_mass[a]);
      for (int c = 0; c < 3; ++c) {
        const Real v = s.atom_vel[3 * a + c], acc = ws.atom_force[3 * a + c] * inv_m;
        ws.rk_dx[3 * i + c] += weight[stage] * v;
        ws.rk_dv[3 * i + c] += weight[stage] * acc;
        if (stage < 3) {
          s.atom_pos[3 * a + c] = ws.rk_x0[3 * i + c] + advance[stage] * v;
          s.atom_vel[3 * a + c] = ws.rk_v0[3 * i + c] + advance[stage] * acc;
        }
      }
    }
  }
  StageTimer timer(&times->integrate_ns);
  for (int32_t i = 0; i < n; ++i) {
    const int32_t a = ws.active[i];
    for (int c = 0; c < 3; ++c) {
      s.atom_pos[3 * a + c] = ws.rk_x0[3 * i + c] + T / 6 * ws.rk_dx[3 * i + c];
      s.atom_vel[3 * a + c] = ws.rk_v0[3 * i + c] + T / 6 * ws.rk_dv[3 * i + c];
    }
  }
}

}  // namespace

int32_t RunIntegrator(const Model& m, State& s, Workspace& ws, Integrator integrator, int32_t substeps,
                      StageTimes* times) {
  const Real T = static_cast<Real>(ws.options.dt_s / substeps);
  const bool filtered = UsesFilter(ws.options, integrator);
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    std::fill(ws.tools[t].tick_force, ws.tools[t].tick_force + 3, 0.0);
    std::fill(ws.tools[t].tick_friction, ws.tools[t].tick_friction + 3, 0.0);
    ws.tools[t].tick_fn = 0;
  }
  ws.reach_slack = -1;  // these kernels do not measure how far they move atoms: every candidate
  int32_t cg_iterations = 0;
  for (int32_t k = 0; k < substeps; ++k) {
    switch (integrator) {
      case Integrator::kExplicitEuler:
      case Integrator::kSymplecticEuler: {
        Forces(m, s, ws, filtered, T, 1.0 / substeps, times);
        StageTimer timer(&times->integrate_ns);
        if (integrator == Integrator::kExplicitEuler) {
          ExplicitEulerUpdate(m, s, ws, T);
        } else {
          SymplecticEulerUpdate(m, s, ws, T);
        }
        break;
      }
      case Integrator::kRk4:
        Rk4Substep(m, s, ws, T, substeps, times);
        break;
      case Integrator::kImplicitEuler: {
        cg_iterations += ImplicitEulerSubstep(m, s, ws, T, times);
        for (int32_t t = 0; t < ws.num_tools; ++t) {
          for (int c = 0; c < 3; ++c) ws.tools[t].tick_force[c] += ws.tools[t].eval_force[c] / substeps;
          for (int c = 0; c < 3; ++c) ws.tools[t].tick_friction[c] += ws.tools[t].eval_friction[c] / substeps;
          ws.tools[t].tick_fn += ws.tools[t].eval_fn / substeps;
        }
        break;
      }
    }
  }
  return cg_iterations;
}

}  // namespace idms::internal

namespace idms {

double StableDt(Integrator integrator, const AtomBound& bound, LengthRate rate, double lambda) {
  const bool filtered = rate == LengthRate::kFiltered;
  switch (integrator) {
    case Integrator::kExplicitEuler: {
      if (!filtered) return EulerStableDt(bound);
      if (bound.c <= 0) return bound.omega2 > 0 ? 0.0 : std::numeric_limits<double>::infinity();
      return lambda * bound.c / (bound.omega2 + bound.c * bound.c);
    }
    case Integrator::kSymplecticEuler:
      return (filtered ? lambda : 1.0) * SymplecticStableDt(bound);
    case Integrator::kRk4: {
      const double fastest = std::max(std::sqrt(std::max(bound.omega2, 0.0)), bound.c);
      return fastest > 0 ? 2.5 / fastest : std::numeric_limits<double>::infinity();
    }
    case Integrator::kImplicitEuler:
      break;
  }
  return std::numeric_limits<double>::infinity();
}

}  // namespace idms
