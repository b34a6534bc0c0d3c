// Coulomb friction with stiction at sphere and tweezers contacts, anchored on the deforming
// surface (thesis 7.2.4: "external forces applied to individual atoms and the MIO").
//
// The law is Kikuuwe et al.'s (IEEE T-RO 22(6), 2006): a tangential spring k_t and damper b_t
// between the tool and an anchor, with Coulomb's law on the anchor, discretised by implicit
// Euler. With u the tangential displacement of the tool from its anchor and u' the one committed
// at the end of the last tick, the force the anchor would need to stay put is
//   f* = k_t u + (b_t / T)(u - u'),
// and the tick's force is f* itself when |f*| <= mu f_n (stick: the anchor does not move, so a
// held load does not creep), else mu f_n f*/|f*| (slip), and the anchor is then moved to where
// that bounded force is f*'s, u = (mu f_n f^* + (b_t / T) u') / (k_t + b_t / T). The projection
// is exact at any T: no velocity threshold, no sign switch, so no chattering at rest. mu is
// mu_s while the contact sticks and mu_d once it slips; it sticks again when |f*| <= mu_d f_n
// (the hysteresis that makes stick-slip). Rejected: a velocity-based Coulomb/Karnopp law (it
// needs a threshold velocity, creeps below it and chatters above it at 1 kHz, MuJoCo #3328), and
// CHAI3D's god-object proxy (a proxy on a rigid mesh; here the anchor must ride on atoms that move).
//
// The anchor is the weighted mean of the tool's strongest contact atoms when contact begins
// (weights by contact force), so it moves as the tissue deforms under it; while slipping it is
// re-spread over the current strongest contacts each tick, the anchored point kept. Friction's
// force acts on those atoms with their weights, and its opposite on the device, so the hand feels
// what the tissue receives. Within a tick u' is fixed: the force is the gradient of a Huber
// potential of stiffness k_t + b_t / T, which the energy check and the stable-step prediction see.
#include <algorithm>
#include <cmath>

#include "idms/sim/model.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms::internal {
namespace {

// The anchor spread over the tick's strongest contacts.
void SpreadAnchor(ActiveTool& at) { SpreadOverStrongest(at, at.anchor_atoms, at.anchor_w); }

void CopyAnchorTo(const ActiveTool& at, ToolState& ts) {
  std::copy(at.anchor_atoms, at.anchor_atoms + kAnchorAtoms, ts.anchor_atoms);
  std::copy(at.anchor_w, at.anchor_w + kAnchorAtoms, ts.anchor_w);
  std::copy(at.anchor_offset, at.anchor_offset + 3, ts.anchor_offset);
  std::copy(at.friction_u, at.friction_u + 3, ts.friction_u);
  ts.friction = at.friction;
}

void ClearAnchor(ToolState& ts) {
  std::fill(ts.anchor_atoms, ts.anchor_atoms + kAnchorAtoms, -1);
  std::fill(ts.anchor_w, ts.anchor_w + kAnchorAtoms, 0.0);
  std::fill(ts.anchor_offset, ts.anchor_offset + 3, 0.0);
  std::fill(ts.friction_u, ts.friction_u + 3, 0.0);
  ts.friction = FrictionState::kNone;
}

// What friction does at the State's positions, given the contact force on the atoms (sum over
// the tool's contacts) of the same evaluation.
struct FrictionEval {
  bool active = false;
  double n[3] = {0, 0, 0};      // unit contact normal, surface -> tool
  double fn = 0;                // |contact force|
  double u[3] = {0, 0, 0};      // tangential displacement from the anchor
  double up[3] = {0, 0, 0};     // the committed one, in this tangent plane
  double fstar[3] = {0, 0, 0};  // force that keeps the anchor (on the atoms)
  double fstar_mag = 0;
  double limit = 0;         // mu f_n
  double f[3] = {0, 0, 0};  // the bounded force, on the atoms
  double energy = 0;        // Huber potential of f* (stiffness k_t + b_t / T)
};

FrictionEval Evaluate(const State& s, const ActiveTool& at, const double contact[3], double dt) {
  FrictionEval out;
  const double fn = std::sqrt(Dot3(contact, contact));
  double anchor[3];
  if (!(fn > 0) || !std::isfinite(fn) || !AnchorPoint(s, at.anchor_atoms, at.anchor_w, anchor)) return out;
  out.active = true;
  out.fn = fn;
  for (int c = 0; c < 3; ++c) out.n[c] = -contact[c] / fn;
  double e[3];
  for (int c = 0; c < 3; ++c) e[c] = at.pos[c] - anchor[c] - at.anchor_offset[c];
  const double en = Dot3(e, out.n), upn = Dot3(at.friction_u, out.n);
  const double damp = at.b_t / dt, keff = at.k_t + damp;
  for (int c = 0; c < 3; ++c) {
    out.u[c] = e[c] - en * out.n[c];
    out.up[c] = at.friction_u[c] - upn * out.n[c];
    out.fstar[c] = keff * out.u[c] - damp * out.up[c];
  }
  out.fstar_mag = std::sqrt(Dot3(out.fstar, out.fstar));
  out.limit = (at.friction == FrictionState::kSlip ? at.mu_d : at.mu_s) * fn;
  const double scale = out.fstar_mag > out.limit ? out.limit / out.fstar_mag : 1.0;
  for (int c = 0; c < 3; ++c) out.f[c] = scale * out.fstar[c];
  out.energy = out.fstar_mag <= out.limit ? 0.5 * out.fstar_mag * out.fstar_mag / keff
                                          : (out.limit * out.fstar_mag - 0.5 * out.limit * out.limit) / keff;
  return out;
}

}  // namespace

bool AnchorPoint(const State& s, const int32_t* atoms, const double* w, double out[3]) {
  out[0] = out[1] = out[2] = 0;
  for (int i = 0; i < kAnchorAtoms && atoms[i] >= 0; ++i) {
    for (int c = 0; c < 3; ++c) out[c] += w[i] * s.atom_pos[3 * atoms[i] + c];
  }
  return Finite3(out);
}

void SpreadOverStrongest(const ActiveTool& at, int32_t* atoms, double* w) {
  double total = 0;
  for (int i = 0; i < kAnchorAtoms && at.strong_atoms[i] >= 0; ++i) total += at.strong_f[i];
  for (int i = 0; i < kAnchorAtoms; ++i) {
    const bool used = at.strong_atoms[i] >= 0 && total > 0;
    atoms[i] = used ? at.strong_atoms[i] : -1;
    w[i] = used ? at.strong_f[i] / total : 0.0;
  }
}

void RankContact(ActiveTool& at, int32_t atom, double force) {
  if (!(force > at.strong_f[kAnchorAtoms - 1]) && at.strong_atoms[kAnchorAtoms - 1] >= 0) return;
  int i = kAnchorAtoms - 1;
  for (; i > 0 && (at.strong_atoms[i - 1] < 0 || force > at.strong_f[i - 1]); --i) {
    at.strong_atoms[i] = at.strong_atoms[i - 1];
    at.strong_f[i] = at.strong_f[i - 1];
  }
  at.strong_atoms[i] = atom;
  at.strong_f[i] = force;
}

void BeginFriction(State& s, Workspace& ws) {
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    ActiveTool& at = ws.tools[t];
    if (!(at.mu_s > 0)) continue;
    // Contact begins: the anchor on the strongest contacts, where the tool is now.
    if (at.friction == FrictionState::kNone && at.strong_atoms[0] >= 0) {
      SpreadAnchor(at);
      double anchor[3];
      if (!AnchorPoint(s, at.anchor_atoms, at.anchor_w, anchor)) {
        std::fill(at.anchor_atoms, at.anchor_atoms + kAnchorAtoms, -1);
        continue;
      }
      for (int c = 0; c < 3; ++c) at.anchor_offset[c] = at.pos[c] - anchor[c], at.friction_u[c] = 0;
      std::copy(at.pos, at.pos + 3, at.prev_pos);  // the move before contact did no friction work
      at.friction = FrictionState::kStick;
      CopyAnchorTo(at, s.tools[t]);
    }
    if (at.friction == FrictionState::kNone) continue;
    AnchorPoint(s, at.anchor_atoms, at.anchor_w, at.anchor_start);
    // Its spring stiffens the anchor atoms: w_i (k_t + b_t / T) on each (Gershgorin row sum).
    const double keff = at.k_t + at.b_t / ws.options.dt_s;
    for (int i = 0; i < kAnchorAtoms && at.anchor_atoms[i] >= 0; ++i) {
      if (ws.atom_mark[at.anchor_atoms[i]] == 1) ws.atom_extra_k[at.anchor_atoms[i]] += at.anchor_w[i] * keff;
    }
  }
}

void AddFriction(const State& s, Workspace& ws, ActiveTool& at, Real* force, int stride) {
  const FrictionEval fe = Evaluate(s, at, at.eval_force, ws.options.dt_s);
  std::copy(fe.n, fe.n + 3, at.eval_normal);
  at.eval_fn = fe.fn;
  std::copy(fe.f, fe.f + 3, at.eval_friction);
  if (!fe.active) return;
  for (int c = 0; c < 3; ++c) at.eval_force[c] += fe.f[c];
  for (int i = 0; i < kAnchorAtoms && at.anchor_atoms[i] >= 0; ++i) {
    const int32_t a = at.anchor_atoms[i];
    if (ws.atom_mark[a] != 1) continue;
    for (int c = 0; c < 3; ++c) force[stride * a + c] += static_cast<Real>(at.anchor_w[i] * fe.f[c]);
  }
}

double FrictionEnergy(const State& s, const ActiveTool& at, const double contact[3], double dt) {
  return Evaluate(s, at, contact, dt).energy;
}

void CommitFriction(State& s, Workspace& ws, StepReport* report) {
  const double dt = ws.options.dt_s;
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    ActiveTool& at = ws.tools[t];
    ToolReport& tr = report->tools[t];
    if (!(at.mu_s > 0) || at.friction == FrictionState::kNone) continue;
    ToolState& ts = s.tools[t];
    // The last evaluation's contact decides the normal; the anchor is seen where the atoms ended.
    double contact[3];
    for (int c = 0; c < 3; ++c) contact[c] = -at.eval_fn * at.eval_normal[c];
    const FrictionEval fe = Evaluate(s, at, contact, dt);
    double anchor[3];
    const bool anchored = AnchorPoint(s, at.anchor_atoms, at.anchor_w, anchor);
    // Friction's work this tick, the device moving at the tick's start under the tick's force (the
    // energy check's convention); the change of its spring's energy is added below.
    double work = 0;
    for (int c = 0; c < 3; ++c) {
      work += at.tick_friction[c] * ((anchor[c] - at.anchor_start[c]) - (at.pos[c] - at.prev_pos[c]));
    }
    const double u_old2 = Dot3(at.friction_u, at.friction_u);
    if (!fe.active || !anchored || !std::isfinite(work)) {
      // Contact lost (or a non-finite anchor): the spring lets go, its energy dissipated; the next
      // contact anchors anew.
      if (std::isfinite(work)) tr.friction_work = work - 0.5 * at.k_t * u_old2;
      ClearAnchor(ts);
      continue;
    }
    double u_new[3];
    if (fe.fstar_mag <= fe.limit) {
      at.friction = FrictionState::kStick;
      std::copy(fe.u, fe.u + 3, u_new);
    } else {
      // Slip: the anchor moves so that the bounded force is f*'s (implicit Euler, above), then is
      // spread over the current strongest contacts with the anchored point kept.
      at.friction = FrictionState::kSlip;
      const double damp = at.b_t / dt, keff = at.k_t + damp;
      for (int c = 0; c < 3; ++c) {
        u_new[c] = (fe.limit * fe.fstar[c] / fe.fstar_mag + damp * fe.up[c]) / keff;
        at.anchor_offset[c] += fe.u[c] - u_new[c];
      }
      if (at.strong_atoms[0] >= 0) {
        // The stiffness BeginFriction gave the old anchor atoms goes now (ClearExtraK and
        // ClearTickScratch clear the new ones, which may not include them).
        for (int i = 0; i < kAnchorAtoms && at.anchor_atoms[i] >= 0; ++i) ws.atom_extra_k[at.anchor_atoms[i]] = 0;
        SpreadAnchor(at);
        double spread[3];
        if (AnchorPoint(s, at.anchor_atoms, at.anchor_w, spread)) {
          for (int c = 0; c < 3; ++c) at.anchor_offset[c] += anchor[c] - spread[c];
        }
      }
    }
    std::copy(u_new, u_new + 3, at.friction_u);
    tr.friction_work = work + 0.5 * at.k_t * (Dot3(u_new, u_new) - u_old2);
    tr.normal_force = at.tick_fn;
    tr.friction = at.friction;
    for (int c = 0; c < 3; ++c) tr.friction_force[c] = -at.tick_friction[c];
    CopyAnchorTo(at, ts);
  }
}

}  // namespace idms::internal
