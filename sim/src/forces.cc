// Forces on the active atoms (thesis 4.1 blocks 1-2): field and tool forces (eq. 4.2, 5.5.1),
// element forces (eqs. 4.3-4.9) with the eq. 4.6 filtered length rate, and the energy checks use.
#include <cmath>
#include <limits>

#include "idms/sim/check.h"
#include "idms/sim/model.h"
#include "idms/sim/tool.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms {
namespace internal {

// Eq. 4.2: gravity m g and air resistance -c m v on every active atom; clears the accumulator
// (atom a's force at force[stride * a]).
void FieldForces(const Model& m, const State& s, Workspace& ws, Real* force, int stride) {
  const StepOptions& o = ws.options;
  const bool gravity = o.gravity, air = o.air_damping > 0;
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    Real* f = force + stride * a;
    f[0] = f[1] = f[2] = 0;
    if (gravity) {
      for (int c = 0; c < 3; ++c) f[c] += static_cast<Real>(m.atom_mass[a] * o.gravity_accel[c]);
    }
    if (air) {
      const Real ca = static_cast<Real>(o.air_damping * m.atom_mass[a]);
      for (int c = 0; c < 3; ++c) f[c] -= ca * s.atom_vel[3 * a + c];
    }
  }
}

const Real* ExternalForces(const Model& m, const Workspace& ws) {
  if (ws.atom_force_external.empty()) return nullptr;
  IDMS_CHECK(static_cast<int32_t>(ws.atom_force_external.size()) == 3 * m.num_atoms);
  return ws.atom_force_external.data();
}

namespace {

// The caller's external forces, added last (the fused kernel adds them as it integrates each atom).
void AddExternalForces(Workspace& ws, const Real* external) {
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    for (int c = 0; c < 3; ++c) ws.atom_force[3 * a + c] += external[3 * a + c];
  }
}

}  // namespace

// Thesis 5.5.1 for each sphere/tweezers MIO over the contact candidates, and the tweezers' grasp
// element (6.1.3). The reaction, -sum, is the device force; fixed atoms push back but do not move.
void ToolForces(const State& s, Workspace& ws, Real* force, int stride) {
  const double frac = ws.options.min_distance_fraction;
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    ActiveTool& at = ws.tools[t];
    at.eval_force[0] = at.eval_force[1] = at.eval_force[2] = 0;
    if (!IsContactTool(at.kind)) continue;
    const AtomList atoms = ToolAtoms(ws);
    for (int32_t i = 0; i < atoms.n; ++i) {
      const int32_t a = atoms.ids[i];
      if (a == at.grasp_atom) continue;  // held by the grasp element instead
      const Real* p = &s.atom_pos[3 * a];
      const double d[3] = {p[0] - at.pos[0], p[1] - at.pos[1], p[2] - at.pos[2]};
      if (!InsideSphere(d, at.radius)) continue;
      const ContactForce cf = SphereContact(at.law, at.stiffness, at.radius, frac, d);
      if (!cf.touching) continue;
      for (int c = 0; c < 3; ++c) at.eval_force[c] += cf.f[c];
      if (ws.atom_mark[a]) {
        for (int c = 0; c < 3; ++c) force[stride * a + c] += static_cast<Real>(cf.f[c]);
      }
    }
    // Friction (friction.cc) against this evaluation's contact force, before the grasp element.
    if (at.friction != FrictionState::kNone) AddFriction(s, ws, at, force, stride);
    if (at.kind == ToolKind::kNeedle) AddNeedle(s, ws, t, force, stride);
    if (at.grasp_atom < 0) continue;
    // Grasp element atom -> centre: k (l - l_eq) along s^ (eq. 4.7 with the centre as atom 1).
    const Real* p = &s.atom_pos[3 * at.grasp_atom];
    const double sv[3] = {at.pos[0] - p[0], at.pos[1] - p[1], at.pos[2] - p[2]};
    const double l = std::sqrt(sv[0] * sv[0] + sv[1] * sv[1] + sv[2] * sv[2]);
    if (!(l > kMinLength)) continue;
    const double mag = at.grasp_k * (l - at.grasp_leq) / l;
    for (int c = 0; c < 3; ++c) {
      at.eval_force[c] += mag * sv[c];
      if (ws.atom_mark[at.grasp_atom]) force[stride * at.grasp_atom + c] += static_cast<Real>(mag * sv[c]);
    }
  }
  // The suture's punctures (suture.cc): no tool's force, so the hand feels them only through the thread.
  AddSuture(s, ws, force, stride);
}

namespace {

// An element whose atoms coincide has no direction (eq. 4.5 divides by 0). A zero-length element
// (l_eq = 0) then exerts nothing, which is its limit; otherwise it pushes its atoms apart with
// k l_eq along its rest direction, so coincident atoms separate the way the model was built.
// The viscous term is dropped for that tick, and the eq. 4.6 filter restarts at the next one.
void DegenerateElement(const Model& m, Workspace& ws, int32_t e, Real push) {
  if (push <= 0) return;
  const int32_t a0 = m.elem_atoms[2 * e], a1 = m.elem_atoms[2 * e + 1];
  Real dir[3];
  for (int c = 0; c < 3; ++c)
    dir[c] = static_cast<Real>((m.atom_pos_eq[3 * a1 + c] - m.atom_pos_eq[3 * a0 + c]) / m.elem_leq[e]);
  for (int c = 0; c < 3; ++c) {
    if (ws.atom_mark[a0]) ws.atom_force[3 * a0 + c] -= push * dir[c];
    if (ws.atom_mark[a1]) ws.atom_force[3 * a1 + c] += push * dir[c];
  }
}

// Eqs. 4.3-4.9 over the active elements; forces land on active endpoints only.
// kDamped = false drops the viscous term and the eq. 4.6 filter (no element has b > 0).
template <bool kDamped, bool kFiltered>
void ElementForces(const Model& m, State& s, Workspace& ws, Real T, Real lambda) {
  const int32_t* elem_atoms = m.elem_atoms.data();
  const Real* pos = s.atom_pos.data();
  const Real* vel = s.atom_vel.data();
  const uint8_t* mark = ws.atom_mark.data();
  Real* force = ws.atom_force.data();
  const Real inv_t = Real(1) / T;
  for (int32_t i = 0; i < ws.num_elems; ++i) {
    const int32_t e = ws.elems[i];
    const int32_t a0 = elem_atoms[2 * e], a1 = elem_atoms[2 * e + 1];
    // eq. 4.3: s = p1 - p0; eq. 4.4: l = |s|; eq. 4.5: s^ = s / l (0 when l ~ 0).
    const Real sx = pos[3 * a1] - pos[3 * a0], sy = pos[3 * a1 + 1] - pos[3 * a0 + 1],
               sz = pos[3 * a1 + 2] - pos[3 * a0 + 2];
    const Real l = std::sqrt(sx * sx + sy * sy + sz * sz);
    const Real k = static_cast<Real>(m.elem_k[e]), leq = static_cast<Real>(m.elem_leq[e]);
    [[maybe_unused]] Real rate = 0;
    const bool degenerate = l <= kMinLength;
    if constexpr (kDamped && kFiltered) {
      // eq. 4.6: lambda (l_n - l_{n-1}) / T + (1 - lambda) l'_{n-1}; a filter with a restart mark
      // (State::elem_len) starts from rest. A degenerate element's rate would be noise (it has
      // no direction): its filter is marked to restart.
      const bool fresh = s.elem_len[e] != kFilterRestart;
      const Real prev_len = fresh ? s.elem_len[e] : l;
      const Real prev_rate = fresh ? s.elem_rate[e] : Real(0);
      rate = lambda * (l - prev_len) * inv_t + (Real(1) - lambda) * prev_rate;
      s.elem_len[e] = degenerate ? kFilterRestart : l;
      s.elem_rate[e] = degenerate ? Real(0) : rate;
    }
    if (degenerate) [[unlikely]] {
      DegenerateElement(m, ws, e, k * leq);
      continue;
    }
    const Real inv_l = Real(1) / l;
    // eq. 4.7: k (l - l_eq) s^, written as a multiple of s.
    Real mag = k * (Real(1) - leq * inv_l);
    if constexpr (kDamped) {
      if constexpr (!kFiltered) {
        // l' = s^ . (v1 - v0): exact, and a function of (x, v) as RK4 and the Jacobian need.
        rate = ((vel[3 * a1] - vel[3 * a0]) * sx + (vel[3 * a1 + 1] - vel[3 * a0 + 1]) * sy +
                (vel[3 * a1 + 2] - vel[3 * a0 + 2]) * sz) *
               inv_l;
      }
      // eq. 4.8: b l' s^; eq. 4.9: f = f_k + f_b.
      mag += static_cast<Real>(m.elem_b[e]) * rate * inv_l;
    }
    const Real fx = mag * sx, fy = mag * sy, fz = mag * sz;
    // The element pulls atom 0 towards atom 1 when stretched, and atom 1 back.
    if (mark[a0]) force[3 * a0] += fx, force[3 * a0 + 1] += fy, force[3 * a0 + 2] += fz;
    if (mark[a1]) force[3 * a1] -= fx, force[3 * a1 + 1] -= fy, force[3 * a1 + 2] -= fz;
  }
}

}  // namespace

void EvaluateForces(const Model& m, State& s, Workspace& ws, bool filtered, Real T) {
  FieldForces(m, s, ws, ws.atom_force.data(), 3);
  ToolForces(s, ws, ws.atom_force.data(), 3);
  const Real lambda = static_cast<Real>(ws.options.lambda);
  if (!m.has_damping) {
    ElementForces<false, false>(m, s, ws, T, lambda);
  } else if (filtered) {
    ElementForces<true, true>(m, s, ws, T, lambda);
  } else {
    ElementForces<true, false>(m, s, ws, T, lambda);
  }
  if (const Real* external = ExternalForces(m, ws)) AddExternalForces(ws, external);
}

namespace {

// Gravity's potential relative to rest over the active atoms: -sum m g . (p - p_eq).
double GravityEnergy(const Model& m, const State& s, const Workspace& ws) {
  double gravity = 0;
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    const Real* p = &s.atom_pos[3 * a];
    for (int c = 0; c < 3; ++c) {
      gravity -= m.atom_mass[a] * ws.options.gravity_accel[c] * (p[c] - m.atom_pos_eq[3 * a + c]);
    }
  }
  return gravity;
}

// Tool penalty potentials and grasp elements, at the tools' current pose, added to *contact,
// their rounding noise to *noise.
void ToolEnergy(const State& s, const Workspace& ws, double* contact, double* noise) {
  const double eps = 4 * std::numeric_limits<Real>::epsilon();
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    const ActiveTool& at = ws.tools[t];
    if (!IsContactTool(at.kind)) continue;
    const double dl = eps * (std::fabs(at.pos[0]) + std::fabs(at.pos[1]) + std::fabs(at.pos[2]) + 1);
    const AtomList atoms = ToolAtoms(ws);
    double sum[3] = {0, 0, 0};  // the contact force, for friction's bound
    for (int32_t i = 0; i < atoms.n; ++i) {
      const int32_t a = atoms.ids[i];
      if (a == at.grasp_atom) continue;
      const Real* p = &s.atom_pos[3 * a];
      const double d[3] = {p[0] - at.pos[0], p[1] - at.pos[1], p[2] - at.pos[2]};
      if (!InsideSphere(d, at.radius)) continue;
      const ContactForce cf = SphereContact(at.law, at.stiffness, at.radius, ws.options.min_distance_fraction, d);
      *contact += cf.energy;
      *noise += (std::sqrt(cf.f[0] * cf.f[0] + cf.f[1] * cf.f[1] + cf.f[2] * cf.f[2]) + cf.stiffness * dl) * dl;
      for (int c = 0; c < 3; ++c) sum[c] += cf.f[c];
    }
    if (at.friction != FrictionState::kNone) *contact += FrictionEnergy(s, at, sum, ws.options.dt_s);
    if (at.kind == ToolKind::kNeedle) *contact += NeedleEnergy(s, ws, t);
    if (at.grasp_atom >= 0) {
      const Real* p = &s.atom_pos[3 * at.grasp_atom];
      const double dx = at.pos[0] - p[0], dy = at.pos[1] - p[1], dz = at.pos[2] - p[2];
      const double stretch = std::sqrt(dx * dx + dy * dy + dz * dz) - at.grasp_leq;
      *contact += 0.5 * at.grasp_k * stretch * stretch;
      *noise += at.grasp_k * (std::fabs(stretch) + dl) * dl;
    }
  }
  *contact += SutureEnergy(s, ws);
}

}  // namespace

Energy ActiveEnergy(const Model& m, const State& s, const Workspace& ws) {
  const StepOptions& o = ws.options;
  double kinetic = 0, gravity = 0, elastic = 0, contact = 0, noise = 0;
  const double eps = 4 * std::numeric_limits<Real>::epsilon();
  bool finite = true;
  double abs_pos = 0;  // the largest |x| + |y| + |z| of an active atom
  // Kinetic, and gravity relative to rest (so its size does not drown the other terms).
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    const Real* p = &s.atom_pos[3 * a];
    const Real* v = &s.atom_vel[3 * a];
    finite = finite && std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
    abs_pos = std::max(abs_pos, std::fabs(double(p[0])) + std::fabs(double(p[1])) + std::fabs(double(p[2])));
    kinetic += 0.5 * m.atom_mass[a] * (double(v[0]) * v[0] + double(v[1]) * v[1] + double(v[2]) * v[2]);
    if (o.gravity) {
      for (int c = 0; c < 3; ++c) gravity -= m.atom_mass[a] * o.gravity_accel[c] * (p[c] - m.atom_pos_eq[3 * a + c]);
    }
  }
  // Elastic: 1/2 k (l - l_eq)^2 over the active elements. Each length carries ~dl of rounding,
  // bounded over the region by the largest position (the fused kernel bounds it the same way, so
  // both kernels hold a gain to the same tolerance).
  const double dl = eps * (abs_pos + 1);
  for (int32_t i = 0; i < ws.num_elems; ++i) {
    const int32_t e = ws.elems[i];
    const Real* p0 = &s.atom_pos[3 * m.elem_atoms[2 * e]];
    const Real* p1 = &s.atom_pos[3 * m.elem_atoms[2 * e + 1]];
    const double dx = p1[0] - p0[0], dy = p1[1] - p0[1], dz = p1[2] - p0[2];
    const double stretch = std::sqrt(dx * dx + dy * dy + dz * dz) - m.elem_leq[e];
    elastic += 0.5 * m.elem_k[e] * stretch * stretch;
    noise += m.elem_k[e] * (std::fabs(stretch) + dl) * dl;
  }
  ToolEnergy(s, ws, &contact, &noise);
  Energy out;
  out.scale = kinetic + elastic + contact + std::fabs(gravity);
  out.noise = noise;
  out.h = finite ? kinetic + gravity + elastic + contact : std::nan("");
  return out;
}

void ToolAndGravityEnergy(const Model& m, const State& s, const Workspace& ws, Energy* e) {
  const double gravity = ws.options.gravity ? GravityEnergy(m, s, ws) : 0.0;
  double contact = 0;
  ToolEnergy(s, ws, &contact, &e->noise);
  e->h += gravity + contact;
  e->scale += contact + std::fabs(gravity);
}

}  // namespace internal

double ModelEnergy(const Model& m, const State& s, const Workspace& ws) {
  double h = 0;
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    const Real* v = &s.atom_vel[3 * a];
    h += 0.5 * m.atom_mass[a] * (double(v[0]) * v[0] + double(v[1]) * v[1] + double(v[2]) * v[2]);
    if (ws.options.gravity && !m.atom_fixed[a]) {
      for (int c = 0; c < 3; ++c) {
        h -= m.atom_mass[a] * ws.options.gravity_accel[c] * (s.atom_pos[3 * a + c] - m.atom_pos_eq[3 * a + c]);
      }
    }
  }
  return h + internal::ElasticEnergy(m, s);
}

namespace internal {

double ElasticEnergy(const Model& m, const State& s) {
  double h = 0;
  for (int32_t e = 0; e < m.num_elems; ++e) {
    const Real* p0 = &s.atom_pos[3 * m.elem_atoms[2 * e]];
    const Real* p1 = &s.atom_pos[3 * m.elem_atoms[2 * e + 1]];
    const double dx = p1[0] - p0[0], dy = p1[1] - p0[1], dz = p1[2] - p0[2];
    const double stretch = std::sqrt(dx * dx + dy * dy + dz * dz) - m.elem_leq[e];
    h += 0.5 * m.elem_k[e] * stretch * stretch;
  }
  return h;
}

}  // namespace internal

}  // namespace idms
