// The straight needle (thesis 7.2.4, "piercing"; issue 32): a sphere MIO at the tip until the
// tissue yields, then a shaft that holds the atoms near it laterally and slides along its own axis
// against Coulomb friction.
//
// Puncture: at the end of a tick, the tip's axial force on the tissue (the sphere contact's sum
// along the axis) is compared with the puncture threshold; above it the needle enters. The entry
// point is anchored to the tip's strongest contact atoms (weights by contact force), so it rides
// on the deforming surface. The tip contact does not vanish at once: its stiffness fades so that
// its force falls by at most the largest per-tick change of the tip force seen while pressing (the
// give is felt no faster than a tick of the contact that built it), and fades back in after
// withdrawal (over the same number of ticks, at most kMaxTipFadeS).
//
// Inside: each active atom within the capture radius of the inserted shaft (between the entry
// depth and the tip) is pulled toward the axis by k (1 - d / r_c) d_perp plus a damper on its
// velocity relative to the needle, scaled by the same factor: zero at the capture radius, so an
// atom joins or leaves without a step; and faded in over the tip radius behind the tip, so the
// advancing tip picks atoms up without a step either. Rejected: a hard constraint to the shaft
// (a jump when an atom is captured, and a stiffness the explicit schemes cannot bound).
//
// Axial friction is friction.cc's Kikuuwe et al. (2006) law in one dimension: a spring k_a and
// damper b_a between the needle's depth past the entry point and a sticking depth, the force
// bounded by mu f_n, the sticking depth dragged when it slips. f_n is the tissue's grip on the
// shaft: grip times the inserted length plus the lateral springs' magnitudes. The friction acts on
// the entry atoms with their weights (rejected for now: spreading it along the captured atoms,
// which change every tick, so its anchor would have to be re-spread like friction.cc's slip),
// and its opposite on the device, so the hand feels what the tissue receives.
//
// Withdrawal: when the tip comes back behind the depth it punctured at, the needle is free (the tip
// contact fades back in; entering again takes the threshold again).
//
// Through the far side: the tissue is where its elements are, so the tip has left it when no
// element (not cut) passes within the capture radius of it, more than a tip's diameter in. The
// exit point then rides on the captured atoms nearest the tip (weights by inverse distance).
// Pulled on, the tail passes the entry and then the exit (depths along the axis); a suture the
// needle draws (suture.cc) passes each there. The hold on each atom fades out over a tip radius
// before the tail as it does behind the tip, and the grip counts only the shaft still in the
// tissue, so the forces fall smoothly as the tail comes through; once it holds no atom the needle
// is free.
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "idms/sim/model.h"
#include "idms/sim/state.h"
#include "idms/sim/tool.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms {

void NeedleAxisOf(const double q[4], double axis[3]) {
  // -R e_z: the rotation matrix's third column, negated.
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  axis[0] = -2 * (x * z + w * y);
  axis[1] = -2 * (y * z - w * x);
  axis[2] = -(1 - 2 * (x * x + y * y));
}

namespace {

// The needle's parameters as rules (internal::ParamRule), in the order the message names them.
constexpr int kNeedleRules = 9;
void NeedleRules(const NeedleParams& n, internal::ParamRule out[kNeedleRules]) {
  using internal::ParamBound;
  const internal::ParamRule rules[kNeedleRules] = {
      {"length", "a finite number > 0", n.length, ParamBound::kPositive},
      {"puncture_force", "a finite number > 0", n.puncture_force, ParamBound::kPositive},
      {"mu", "a finite number >= 0", n.mu, ParamBound::kNonNegative},
      {"grip", "a finite number >= 0", n.grip, ParamBound::kNonNegative},
      {"capture_radius", "a finite number >= 0 (0 = 2 x the tip radius)", n.capture_radius, ParamBound::kNonNegative},
      {"lateral_stiffness", "a finite number >= 0 (0 = the tool's stiffness)", n.lateral_stiffness,
       ParamBound::kNonNegative},
      {"lateral_damping", "a finite number (< 0 = lateral_stiffness * dt)", n.lateral_damping, ParamBound::kAny},
      {"axial_stiffness", "a finite number >= 0 (0 = the tool's stiffness)", n.axial_stiffness,
       ParamBound::kNonNegative},
      {"axial_damping", "a finite number (< 0 = axial_stiffness * dt)", n.axial_damping, ParamBound::kAny},
  };
  std::copy(rules, rules + kNeedleRules, out);
}

bool NeedleParamsValid(const NeedleParams& n) {
  internal::ParamRule rules[kNeedleRules];
  NeedleRules(n, rules);
  return internal::FirstBadParam(rules, kNeedleRules) == nullptr;
}

}  // namespace

bool ValidateNeedle(const ToolCommand& t, std::string* error) {
  internal::ParamRule rules[kNeedleRules];
  NeedleRules(t.needle, rules);
  return internal::CheckParams("needle", rules, kNeedleRules, error);
}

namespace internal {
namespace {

// The largest time the tip contact takes to fade out after a puncture (or back in after a
// withdrawal), s: a bound for a press so slow that its per-tick change is tiny.
constexpr double kMaxTipFadeS = 0.25;

// The entry point (friction.cc's AnchorPoint over the entry atoms). False when there is none or it
// is not finite.
bool EntryPoint(const State& s, const NeedleState& ns, double out[3]) {
  return AnchorPoint(s, ns.entry_atoms, ns.entry_w, out) && ns.entry_atoms[0] >= 0;
}

// The tip's depth past the entry point along the axis (NaN without one).
double Depth(const State& s, const ActiveTool& at) {
  double e[3];
  if (!EntryPoint(s, at.needle_state, e)) return std::nan("");
  const double r[3] = {at.pos[0] - e[0], at.pos[1] - e[1], at.pos[2] - e[2]};
  return Dot3(r, at.axis);
}

// The lateral pull on one atom at offset r from the tip: the factor w (1 - d / r_c) of the spring
// and damper (0 outside the capture), the perpendicular offset, and its potential.
struct Lateral {
  double scale = 0;  // w (1 - d / r_c), or 0 when not captured
  double perp[3] = {0, 0, 0};
  double energy = 0;
};

Lateral LateralAt(const ActiveTool& at, const double r[3]) {
  Lateral out;
  const double along = Dot3(r, at.axis);
  if (!(along < 0 && along > -at.shaft_len)) return out;
  for (int c = 0; c < 3; ++c) out.perp[c] = r[c] - along * at.axis[c];
  const double d = std::sqrt(Dot3(out.perp, out.perp));
  const double rc = at.needle.capture_radius;
  if (!(d < rc)) return out;
  // Faded in over a tip radius behind the tip, and out over one before the tail.
  const double w = std::min({1.0, -along / at.radius, (at.shaft_len + along) / at.radius});
  out.scale = w * (1 - d / rc);
  // The potential of k (1 - d / r_c) d along d^ (w held: its gradient along the axis is left out).
  out.energy = w * at.needle.lateral_stiffness * (0.5 * d * d - d * d * d / (3 * rc));
  return out;
}

// Axial friction at the State's positions given the grip f_n (friction.cc's Evaluate, in 1-D).
struct AxialEval {
  bool active = false;
  double u = 0, fstar = 0, limit = 0, f = 0, energy = 0;
};

AxialEval EvaluateAxial(const State& s, const ActiveTool& at, double fn, double dt) {
  AxialEval out;
  const NeedleState& ns = at.needle_state;
  const double depth = Depth(s, at);
  if (!std::isfinite(depth) || !std::isfinite(fn)) return out;
  out.active = true;
  const double damp = at.needle.axial_damping / dt, keff = at.needle.axial_stiffness + damp;
  out.u = depth - ns.axial_offset;
  out.fstar = keff * out.u - damp * ns.axial_u;
  out.limit = at.needle.mu * fn;
  const double mag = std::fabs(out.fstar);
  out.f = mag > out.limit ? std::copysign(out.limit, out.fstar) : out.fstar;
  out.energy = mag <= out.limit ? 0.5 * mag * mag / keff : (out.limit * mag - 0.5 * out.limit * out.limit) / keff;
  return out;
}

bool Inside(const ActiveTool& at) { return at.kind == ToolKind::kNeedle && at.needle_state.punctured; }

// Some element of the tissue (not cut) passes within r of p: the elements of the active atoms
// within r plus twice the longest rest length (an element stretched to that still reaches).
bool TissueAt(const Model& m, const State& s, const Workspace& ws, const double p[3], double r) {
  const double reach = r + 2 * m.max_leq, r2 = r * r;
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    const double pa[3] = {s.atom_pos[3 * a], s.atom_pos[3 * a + 1], s.atom_pos[3 * a + 2]};
    const double d[3] = {pa[0] - p[0], pa[1] - p[1], pa[2] - p[2]};
    if (!InsideSphere(d, reach)) continue;
    const int32_t adr = m.atom_elem_adr[a];
    for (int32_t j = 0; j < m.atom_elem_num[a]; ++j) {
      const int32_t e = m.atom_elem[adr + j];
      if (ws.elem_cut[e]) continue;
      const int32_t b = m.elem_atoms[2 * e] == a ? m.elem_atoms[2 * e + 1] : m.elem_atoms[2 * e];
      const double pb[3] = {s.atom_pos[3 * b], s.atom_pos[3 * b + 1], s.atom_pos[3 * b + 2]};
      if (SegmentDist2(p, pa, pb) <= r2) return true;
    }
  }
  return false;
}

// The exit point's atoms: the captured atoms nearest the tip, weights by inverse distance (a tip
// radius added, so none dominates). False when the shaft held none.
bool ExitAnchor(const State& s, const Workspace& ws, int32_t t, int32_t atoms[kAnchorAtoms], double w[kAnchorAtoms]) {
  const ActiveTool& at = ws.tools[t];
  double best[kAnchorAtoms];
  std::fill(best, best + kAnchorAtoms, std::numeric_limits<double>::infinity());
  std::fill(atoms, atoms + kAnchorAtoms, -1);
  std::fill(w, w + kAnchorAtoms, 0.0);
  for (int32_t i = 0; i < at.num_needle_atoms; ++i) {
    const int32_t a = ws.needle_atoms[t][i];
    const Real* p = &s.atom_pos[3 * a];
    const double d[3] = {p[0] - at.pos[0], p[1] - at.pos[1], p[2] - at.pos[2]};
    double dist = std::sqrt(Dot3(d, d));
    int32_t id = a;
    for (int k = 0; k < kAnchorAtoms; ++k) {  // insertion into the sorted few
      if (dist < best[k]) std::swap(dist, best[k]), std::swap(id, atoms[k]);
    }
  }
  double total = 0;
  for (int k = 0; k < kAnchorAtoms && atoms[k] >= 0; ++k) total += w[k] = 1 / (best[k] + at.radius);
  for (int k = 0; k < kAnchorAtoms && atoms[k] >= 0; ++k) w[k] /= total;
  return atoms[0] >= 0;
}

}  // namespace

bool ValidNeedleCommand(const ToolCommand& c) {
  const double n2 = Dot3(c.axis, c.axis);
  return Finite3(c.axis) && n2 > 1e-24 && std::isfinite(n2) && NeedleParamsValid(c.needle) && ValidSutureCommand(c);
}

void ResolveNeedle(const State& s, const ToolState& ts, const ToolCommand& cmd, double dt, ActiveTool& at) {
  // The axis is the last valid one (ResolveTools holds it with the pose).
  const double n = std::sqrt(Dot3(ts.axis, ts.axis));
  for (int c = 0; c < 3; ++c) at.axis[c] = ts.axis[c] / n;
  // Defaults: the tool's stiffness for the springs, k dt for their dampers, 2 r for the capture.
  NeedleParams p = cmd.needle;
  if (!NeedleParamsValid(p)) p = NeedleParams{};  // held input: the defaults
  if (!(p.capture_radius > 0)) p.capture_radius = 2 * at.radius;
  if (!(p.lateral_stiffness > 0)) p.lateral_stiffness = ts.stiffness;
  if (p.lateral_damping < 0) p.lateral_damping = p.lateral_stiffness * dt;
  if (!(p.axial_stiffness > 0)) p.axial_stiffness = ts.stiffness;
  if (p.axial_damping < 0) p.axial_damping = p.axial_stiffness * dt;
  at.needle = p;
  at.needle_state = ts.needle;
  // The tip's sphere contact, faded by the puncture.
  at.stiffness = ts.stiffness * ts.needle.tip_scale;
  // Inside: the inserted shaft, from the entry depth (at most the needle's length) to the tip.
  at.shaft_len = 0;
  if (at.needle_state.punctured && EntryPoint(s, at.needle_state, at.entry_start)) {
    const double depth = Depth(s, at);
    at.shaft_len = std::clamp(depth - at.needle_state.entry_depth, 0.0, p.length);
    // The part in the tissue: from the entry (or the tail, past it) to the exit (or the tip).
    const double far = at.needle_state.exited ? std::min(depth, at.needle_state.exit_depth) : depth;
    at.grip_len = std::clamp(far - std::max(depth - p.length, 0.0), 0.0, p.length);
  }
}

bool NeedleInside(const Workspace& ws) {
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    if (Inside(ws.tools[t])) return true;
  }
  return false;
}

void NeedleShaft(const ActiveTool& at, double tail[3]) {
  for (int c = 0; c < 3; ++c) tail[c] = at.pos[c] - at.shaft_len * at.axis[c];
}

void BeginNeedles(const State& s, Workspace& ws, StepReport* report) {
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    ActiveTool& at = ws.tools[t];
    at.num_needle_atoms = 0;
    if (!Inside(at)) continue;
    // The captured atoms: active atoms in reach of the inserted shaft, in active-list order.
    const double k_lat = at.needle.lateral_stiffness + at.needle.lateral_damping / ws.options.dt_s;
    for (int32_t i = 0; i < ws.num_active; ++i) {
      const int32_t a = ws.active[i];
      const Real* p = &s.atom_pos[3 * a];
      const double r[3] = {p[0] - at.pos[0], p[1] - at.pos[1], p[2] - at.pos[2]};
      const Lateral lat = LateralAt(at, r);
      if (!(lat.scale > 0)) continue;
      if (at.num_needle_atoms == kNeedleAtoms) {
        ++report->tools[t].needle_overflow;
        continue;
      }
      ws.needle_atoms[t][at.num_needle_atoms++] = a;
      // Gershgorin: the spring and the damper (as k + b / T, as friction.cc counts its damper).
      ws.atom_extra_k[a] += k_lat;
    }
    // The axial spring on the entry atoms.
    const double k_ax = at.needle.axial_stiffness + at.needle.axial_damping / ws.options.dt_s;
    const NeedleState& ns = at.needle_state;
    for (int i = 0; i < kAnchorAtoms && ns.entry_atoms[i] >= 0; ++i) {
      if (ws.atom_mark[ns.entry_atoms[i]] == 1) ws.atom_extra_k[ns.entry_atoms[i]] += ns.entry_w[i] * k_ax;
    }
    report->tools[t].needle_atoms = at.num_needle_atoms;
  }
}

void AddNeedle(const State& s, Workspace& ws, int32_t t, Real* force, int stride) {
  ActiveTool& at = ws.tools[t];
  at.eval_axial = at.eval_normal_needle = at.eval_lateral = 0;
  if (!Inside(at)) return;
  const double dt = ws.options.dt_s;
  double vn[3];
  for (int c = 0; c < 3; ++c) vn[c] = (at.pos[c] - at.prev_pos[c]) / dt;
  // Lateral: each captured atom toward the axis, its perpendicular velocity relative to the needle damped.
  double fn = 0;
  for (int32_t i = 0; i < at.num_needle_atoms; ++i) {
    const int32_t a = ws.needle_atoms[t][i];
    const Real* p = &s.atom_pos[3 * a];
    const Real* v = &s.atom_vel[3 * a];
    const double r[3] = {p[0] - at.pos[0], p[1] - at.pos[1], p[2] - at.pos[2]};
    const Lateral lat = LateralAt(at, r);
    if (!(lat.scale > 0)) continue;
    double dv[3] = {v[0] - vn[0], v[1] - vn[1], v[2] - vn[2]};
    const double dv_along = Dot3(dv, at.axis);
    double f[3];
    for (int c = 0; c < 3; ++c) {
      dv[c] -= dv_along * at.axis[c];
      f[c] = -lat.scale * (at.needle.lateral_stiffness * lat.perp[c] + at.needle.lateral_damping * dv[c]);
    }
    fn += lat.scale * at.needle.lateral_stiffness * std::sqrt(Dot3(lat.perp, lat.perp));
    for (int c = 0; c < 3; ++c) at.eval_force[c] += f[c];
    if (ws.atom_mark[a]) {
      for (int c = 0; c < 3; ++c) force[stride * a + c] += static_cast<Real>(f[c]);
    }
  }
  // Axial friction against the grip: on the entry atoms with their weights.
  at.eval_lateral = fn;
  fn += at.needle.grip * at.grip_len;
  const AxialEval ax = EvaluateAxial(s, at, fn, dt);
  at.eval_normal_needle = fn;
  if (!ax.active) return;
  at.eval_axial = ax.f;
  for (int c = 0; c < 3; ++c) at.eval_force[c] += ax.f * at.axis[c];
  const NeedleState& ns = at.needle_state;
  for (int i = 0; i < kAnchorAtoms && ns.entry_atoms[i] >= 0; ++i) {
    const int32_t a = ns.entry_atoms[i];
    if (ws.atom_mark[a] != 1) continue;
    for (int c = 0; c < 3; ++c) force[stride * a + c] += static_cast<Real>(ns.entry_w[i] * ax.f * at.axis[c]);
  }
}

double NeedleEnergy(const State& s, const Workspace& ws, int32_t t) {
  const ActiveTool& at = ws.tools[t];
  if (!Inside(at)) return 0;
  const double dt = ws.options.dt_s;
  double energy = 0, fn = 0;
  for (int32_t i = 0; i < at.num_needle_atoms; ++i) {
    const Real* p = &s.atom_pos[3 * ws.needle_atoms[t][i]];
    const double r[3] = {p[0] - at.pos[0], p[1] - at.pos[1], p[2] - at.pos[2]};
    const Lateral lat = LateralAt(at, r);
    energy += lat.energy;
    fn += lat.scale * at.needle.lateral_stiffness * std::sqrt(Dot3(lat.perp, lat.perp));
  }
  const AxialEval ax = EvaluateAxial(s, at, fn + at.needle.grip * at.grip_len, dt);
  return energy + (ax.active ? ax.energy : 0.0);
}

void CommitNeedles(const Model& m, State& s, Workspace& ws, StepReport* report) {
  const double dt = ws.options.dt_s;
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    ActiveTool& at = ws.tools[t];
    if (at.kind != ToolKind::kNeedle) continue;
    ToolState& ts = s.tools[t];
    NeedleState& ns = ts.needle;
    ToolReport& tr = report->tools[t];
    // The tip's axial force on the tissue where the atoms ended (the contact's own loop).
    double tip[3] = {0, 0, 0};
    for (int32_t i = 0; i < ws.num_candidates; ++i) {
      const Real* p = &s.atom_pos[3 * ws.candidates[i]];
      const double d[3] = {p[0] - at.pos[0], p[1] - at.pos[1], p[2] - at.pos[2]};
      if (!InsideSphere(d, at.radius)) continue;
      const ContactForce cf = SphereContact(at.law, at.stiffness, at.radius, ws.options.min_distance_fraction, d);
      for (int c = 0; c < 3; ++c) tip[c] += cf.f[c];
    }
    double axial = Dot3(tip, at.axis);
    if (!std::isfinite(axial)) axial = 0;
    tr.tip_axial_force = axial;
    if (!ns.punctured) {
      // Free: the largest per-tick change of the press, then the threshold.
      if (axial > 0 || ns.tip_axial > 0) ns.tip_max_step = std::max(ns.tip_max_step, std::fabs(axial - ns.tip_axial));
      ns.tip_axial = axial;
      if (axial > at.needle.puncture_force && at.strong_atoms[0] >= 0) {
        // Puncture: the entry on the tick's strongest contacts, the needle sticking where it is.
        SpreadOverStrongest(at, ns.entry_atoms, ns.entry_w);
        at.needle_state = ns;
        const double depth = Depth(s, at);
        if (std::isfinite(depth)) {
          ns.punctured = true;
          ns.entry_depth = ns.axial_offset = depth;
          ns.axial_u = 0;
          ns.axial = FrictionState::kStick;
          ns.tip_ramp = std::clamp(ns.tip_max_step / axial, dt / kMaxTipFadeS, 1.0);
        }
      }
    } else {
      // Inside: stick or slip (the sticking depth dragged), then the withdrawal test.
      const AxialEval ax = EvaluateAxial(s, at, at.eval_normal_needle, dt);
      const double depth = Depth(s, at);
      if (!ax.active || !std::isfinite(depth) || depth < ns.entry_depth) {
        const double ramp = ns.tip_ramp;
        const double scale = ns.tip_scale;
        ns = NeedleState{};
        ns.tip_ramp = ramp > 0 ? ramp : 1.0;
        ns.tip_scale = scale;
        ns.tip_axial = axial;
      } else {
        const double damp = at.needle.axial_damping / dt, keff = at.needle.axial_stiffness + damp;
        double u_new = ax.u;
        ns.axial = FrictionState::kStick;
        if (std::fabs(ax.fstar) > ax.limit) {
          ns.axial = FrictionState::kSlip;
          u_new = (std::copysign(ax.limit, ax.fstar) + damp * ns.axial_u) / keff;
          ns.axial_offset += ax.u - u_new;
        }
        ns.axial_u = u_new;
        tr.inserted = depth - ns.entry_depth;
        tr.axial_force = -at.eval_axial;
        tr.needle_normal = at.eval_normal_needle;
        tr.axial = ns.axial;
        // Through the far side, then drawn on through: the tail past the entry, then the exit.
        if (!ns.exited && tr.inserted > 2 * at.radius && !TissueAt(m, s, ws, at.pos, at.needle.capture_radius) &&
            ExitAnchor(s, ws, t, ns.exit_atoms, ns.exit_w)) {
          ns.exited = true;
          double e[3], x[3];
          ns.exit_depth = EntryPoint(s, ns, e) && AnchorPoint(s, ns.exit_atoms, ns.exit_w, x)
                              ? Dot3(x, at.axis) - Dot3(e, at.axis)
                              : depth;
        }
        const double tail_depth = depth - at.needle.length;
        if (ns.exited && !ns.entry_passed && tail_depth >= 0) {
          ns.entry_passed = true;
          SutureDrawnThrough(s, t, ns.entry_atoms, ns.entry_w, &report->suture);
        }
        if (ns.entry_passed && !ns.exit_passed && tail_depth >= ns.exit_depth) {
          ns.exit_passed = true;
          SutureDrawnThrough(s, t, ns.exit_atoms, ns.exit_w, &report->suture);
        }
        // Free once the tail has left the last atom it held (their hold, and with it the
        // friction's bound, faded out as it passed them: the hand feels no step).
        if (ns.exit_passed && !(at.eval_lateral > 0)) {
          tr.drawn_through = true;
          const double ramp = ns.tip_ramp;
          ns = NeedleState{};  // free: the tip fades back in
          ns.tip_ramp = ramp > 0 ? ramp : 1.0;
          ns.tip_scale = 0;
          ns.tip_axial = axial;
        }
        tr.exited = ns.exited;
      }
    }
    // The tip contact fades out while inside: next tick's stiffness factor is the one that would
    // have made this tick's axial force tip_max_step smaller (the force is linear in k), so the
    // give is felt no faster than the press's largest tick. Once free it fades back in.
    if (ns.punctured) {
      const double drop = axial - ns.tip_max_step;
      ns.tip_scale = axial > 0 && drop > 0 ? std::clamp(ns.tip_scale * drop / axial, 0.0, 1.0) : 0.0;
    } else {
      ns.tip_scale = std::min(1.0, ns.tip_scale + ns.tip_ramp);
    }
    tr.punctured = ns.punctured;
  }
}

}  // namespace internal
}  // namespace idms
