// The suture thread (thesis 7.2.4, "sewing, suturing"; issue 32): a chain of mass points joined by
// tension-only spring-dampers (a thread goes slack, it does not push), laid behind a needle whose
// tail its first node follows. Drawn through the tissue (needle.cc: the tail passing an entry or
// an exit), it leaves a puncture there: a point riding on the tissue's atoms through which the
// thread slides without friction. The puncture holds the thread's nearest point with a spring-
// damper: the force is perpendicular to the thread wherever the nearest point is inside a
// segment, so the thread slides freely along itself while the tissue is pulled across it, as a
// pulley is by a rope: the bisector of the thread's two directions, the tension's resultant. Past
// the thread's far end (its nearest point the last node), the force has a part along the thread:
// the end is knotted and does not pass through.
//
// Coupling, staggered as the tools are: during the tick's evaluations the tissue feels the
// punctures' springs toward the thread's points at the tick's start (the thread held, as the
// tools' poses are); then the thread is integrated over the tick (symplectic Euler, substeps
// bounded by its own stiffest node) against the punctures where the tissue ended, and each
// puncture's arc position follows the thread's nearest point (searched two segments either side,
// never across a broken segment). The needle's eye (its tail) holds node 0 with a spring-damper
// as stiff as the needle's lateral hold (or the holes', if softer), and the hand feels that
// spring: a thread going taut is felt through it, at most its stiffness times the tail's travel a
// tick, not through the thread's own far stiffer springs nor the holes'.
//
// A tie (a rising edge of ToolCommand::tie) knots the current stitch: the thread at its first and
// last punctures since the last tie is bound by a spring of rest length 0 between those two
// material points, whose pull is at most the tie force; the knot does not pass into either
// puncture. While the loop's tension at the knot is below the tie force, the knot cinches: its
// two points move into the loop at the tie speed, drawing the thread out through the punctures,
// until the loop pulls with the tie force. The knot is drawn tight by hand, and held. Rejected: gluing the two sides'
// atoms directly (the knot would not be on the thread, which could then slide through both punctures and hang loose
// from a closed wound), and finding where the thread crosses itself (a knot is tied where the surgeon ties it, and a
// crossing search every tick costs O(n^2) for no better knot).
//
// A segment whose tension passes the thread's strength parts: it pulls no more, and the two parts
// go their ways (punctures never slide across the break).
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>

#include "idms/sim/tool.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms {
namespace {

// The suture's parameters as rules (internal::ParamRule), in the order the message names them.
constexpr int kSutureRules = 10;
void SutureRules(const SutureParams& p, internal::ParamRule out[kSutureRules]) {
  using internal::ParamBound;
  static_assert(kSutureSegments == 128, "the rule's text says 1..128");
  const internal::ParamRule rules[kSutureRules] = {
      {"length", "a finite number >= 0 (0 = no thread)", p.length, ParamBound::kNonNegative},
      {"segments", "an integer in 1..128", static_cast<double>(p.segments), ParamBound::kPositive, kSutureSegments},
      {"mass", "a finite number > 0", p.mass, ParamBound::kPositive},
      {"stiffness", "a finite number >= 0 (0 = the stiffest one tick holds)", p.stiffness, ParamBound::kNonNegative},
      {"damping", "a finite number (< 0 = near critical)", p.damping, ParamBound::kAny},
      {"strength", "a finite number >= 0 (0 = unbreakable)", p.strength, ParamBound::kNonNegative},
      {"hold_stiffness", "a finite number >= 0 (0 = the needle's lateral stiffness)", p.hold_stiffness,
       ParamBound::kNonNegative},
      {"tie_force", "a finite number > 0", p.tie_force, ParamBound::kPositive},
      {"tie_speed", "a finite number > 0", p.tie_speed, ParamBound::kPositive},
      {"drag", "a finite number >= 0", p.drag, ParamBound::kNonNegative},
  };
  std::copy(rules, rules + kSutureRules, out);
}

}  // namespace

bool ValidateSuture(const ToolCommand& t, std::string* error) {
  internal::ParamRule rules[kSutureRules];
  SutureRules(t.suture, rules);
  return internal::CheckParams("suture", rules, kSutureRules, error);
}

namespace internal {
namespace {

// The thread's point at arc position u (segments from node 0), and optionally its velocity and
// the unit direction of its segment (zero when the segment has no length).
void ThreadPoint(const SutureState& ss, double u, double p[3], double v[3] = nullptr, double dir[3] = nullptr) {
  const int32_t last = ss.num_nodes - 2;
  const int32_t i = std::clamp(static_cast<int32_t>(std::floor(u)), 0, last);
  const double f = std::clamp(u - i, 0.0, 1.0);
  for (int c = 0; c < 3; ++c) {
    p[c] = (1 - f) * ss.pos[3 * i + c] + f * ss.pos[3 * (i + 1) + c];
    if (v != nullptr) v[c] = (1 - f) * ss.vel[3 * i + c] + f * ss.vel[3 * (i + 1) + c];
  }
  if (dir == nullptr) return;
  double l2 = 0;
  for (int c = 0; c < 3; ++c) dir[c] = ss.pos[3 * (i + 1) + c] - ss.pos[3 * i + c], l2 += dir[c] * dir[c];
  const double inv = l2 > 0 ? 1 / std::sqrt(l2) : 0.0;
  for (int c = 0; c < 3; ++c) dir[c] *= inv;
}

// A puncture's hold on the thread at point c (velocity cv, direction dir) from the tissue at p
// (velocity pv): a spring, and a damper on the relative velocity across the thread only (along
// it the thread slides freely). On the thread; the tissue gets its opposite.
void Hold(const SutureState& ss, const double* p, const double* pv, const double* c, const double* cv,
          const double* dir, double f[3]) {
  double dv[3];
  for (int k = 0; k < 3; ++k) dv[k] = pv[k] - cv[k];
  const double along = Dot3(dv, dir);
  for (int k = 0; k < 3; ++k) f[k] = ss.hold_k * (p[k] - c[k]) + ss.hold_b * (dv[k] - along * dir[k]);
}

// Adds f at arc position u to the node forces (split between the segment's two nodes).
void AddAt(const SutureState& ss, double u, const double f[3], double* force) {
  const int32_t last = ss.num_nodes - 2;
  const int32_t i = std::clamp(static_cast<int32_t>(std::floor(u)), 0, last);
  const double w = std::clamp(u - i, 0.0, 1.0);
  for (int c = 0; c < 3; ++c) {
    force[3 * i + c] += (1 - w) * f[c];
    force[3 * (i + 1) + c] += w * f[c];
  }
}

// The arc position of the thread's point nearest p over segments [lo, hi].
double Nearest(const SutureState& ss, const double p[3], int32_t lo, int32_t hi) {
  double best = std::numeric_limits<double>::infinity(), u = lo;
  for (int32_t i = lo; i <= hi; ++i) {
    double t = 0;
    const double d2 = SegmentDist2(p, &ss.pos[3 * i], &ss.pos[3 * (i + 1)], &t);
    if (d2 < best) best = d2, u = i + t;
  }
  return u;
}

// The segments a puncture at arc position u may slide over: two either side, not across a break.
void SlideRange(const SutureState& ss, double u, int32_t* lo, int32_t* hi) {
  const int32_t last = ss.num_nodes - 2;
  const int32_t i = std::clamp(static_cast<int32_t>(std::floor(u)), 0, last);
  *lo = std::max(0, i - 2);
  *hi = std::min(last, i + 2);
  if (ss.broken >= 0 && i < ss.broken) *hi = std::min(*hi, ss.broken - 1);
  if (ss.broken >= 0 && i > ss.broken) *lo = std::max(*lo, ss.broken + 1);
  if (*lo > *hi) *lo = *hi = i;
}

// A knot sits on the punctures it was tied at: the thread between its two arc positions (the
// loop) cannot grow by sliding out through them, so puncture j's arc position u stays on the
// loop's side of any knot tied there; and the punctures the loop passes stay on it (were one to
// slide past a knot's point, the loop would lose it).
double KnotStop(const SutureState& ss, int32_t j, double u) {
  for (int32_t k = 0; k < ss.num_ties; ++k) {
    const SutureTie& t = ss.ties[k];
    // Every puncture of the stitch, the knot's two and those between, is on the loop.
    if (j >= std::min(t.first, t.last) && j <= std::max(t.first, t.last))
      u = std::clamp(u, std::min(t.s_a, t.s_b), std::max(t.s_a, t.s_b));
  }
  return u;
}

// The spring tension of the segment at arc position u (0 when slack or parted).
double Tension(const SutureState& ss, double u) {
  const int32_t i = std::clamp(static_cast<int32_t>(std::floor(u)), 0, ss.num_nodes - 2);
  if (i == ss.broken) return 0;
  double d[3];
  for (int c = 0; c < 3; ++c) d[c] = ss.pos[3 * (i + 1) + c] - ss.pos[3 * i + c];
  return std::max(0.0, ss.k * (std::sqrt(Dot3(d, d)) - ss.seg_len));
}

// The tail of needle slot t as this tick poses it.
void TailOf(const ActiveTool& at, double tail[3]) {
  for (int c = 0; c < 3; ++c) tail[c] = at.pos[c] - at.needle.length * at.axis[c];
}

bool Holds(const SutureState& ss) { return ss.num_nodes > 0 && ss.num_punctures > 0; }

// Lays the thread straight behind the needle's tail, resolving its parameters.
void Lay(SutureState& ss, const ActiveTool& at, const SutureParams& p, double dt, int32_t tool) {
  const int32_t n = p.segments + 1;
  ss = SutureState{};
  ss.num_nodes = n;
  ss.tool = tool;
  ss.seg_len = p.length / p.segments;
  ss.node_mass = p.mass / n;
  // The stiffest spring one tick of symplectic Euler holds on a node pair (omega dt = 2) is
  // m / dt^2; the default is that, and the substeps keep any stiffer one stable.
  ss.k = p.stiffness > 0 ? p.stiffness : ss.node_mass / (dt * dt);
  ss.b = p.damping >= 0 ? p.damping : std::sqrt(ss.k * ss.node_mass);
  ss.hold_k = p.hold_stiffness > 0 ? p.hold_stiffness : at.needle.lateral_stiffness;
  ss.hold_b = ss.hold_k * dt;
  ss.eye_k = std::min(ss.hold_k, at.needle.lateral_stiffness);
  ss.eye_b = ss.eye_k * dt;
  ss.strength = p.strength;
  ss.tie_force = p.tie_force;
  ss.tie_speed = p.tie_speed;
  ss.drag = p.drag;
  double tail[3];
  TailOf(at, tail);
  for (int32_t i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) ss.pos[3 * i + c] = tail[c] - i * ss.seg_len * at.axis[c];
  }
  std::copy(tail, tail + 3, ss.eye.begin());
}

// Substeps that keep symplectic Euler stable on the stiffest node: omega h <= 1 and the dampers'
// h b / m <= 1/2 (a node has two segments, a puncture and a knot on it at most).
int32_t Substeps(const SutureState& ss, double dt) {
  const double k = 4 * ss.k + 2 * ss.hold_k + 2 * ss.k;
  const double b = 4 * ss.b + 2 * ss.hold_b;
  const double h = std::min(std::sqrt(ss.node_mass / k), 0.5 * ss.node_mass / std::max(b, 1e-300));
  return std::clamp(static_cast<int32_t>(std::ceil(dt / h - 1e-9)), 1, 64);
}

}  // namespace

bool ValidSutureCommand(const ToolCommand& c) {
  internal::ParamRule rules[kSutureRules];
  SutureRules(c.suture, rules);
  return FirstBadParam(rules, kSutureRules) == nullptr;
}

void ResolveSuture(State& s, Workspace& ws, const ToolInput& input) {
  SutureState& ss = s.suture;
  ws.suture_on = false;
  ws.suture_tie = false;
  ws.suture_tool = -1;
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    const ActiveTool& at = ws.tools[t];
    if (at.kind != ToolKind::kNeedle) continue;
    const ToolCommand& cmd = input.tools[t];
    if (ss.num_nodes == 0 && ValidSutureCommand(cmd) && cmd.suture.length > 0)
      Lay(ss, at, cmd.suture, ws.options.dt_s, t);
    if (ss.num_nodes > 0 && ss.tool == t) {
      ws.suture_tool = t;
      ws.suture_tie = cmd.tie && !ss.tie_held;
      ss.tie_held = cmd.tie;
    }
  }
  if (ss.num_nodes > 0 && ws.suture_tool < 0) {
    ss.tool = -1;  // its needle is gone: the thread trails free
    ss.tie_held = false;
  }
  ws.suture_on = Holds(ss);
}

void BeginSuture(const State& s, Workspace& ws) {
  if (!ws.suture_on) return;
  const SutureState& ss = s.suture;
  const double k = ss.hold_k + ss.hold_b / ws.options.dt_s;
  for (int32_t j = 0; j < ss.num_punctures; ++j) {
    const SuturePuncture& pu = ss.punctures[j];
    ThreadPoint(ss, pu.s, &ws.suture_points[j][0], &ws.suture_points[j][3], &ws.suture_points[j][6]);
    for (int i = 0; i < kAnchorAtoms && pu.atoms[i] >= 0; ++i) {
      if (ws.atom_mark[pu.atoms[i]] == 1) ws.atom_extra_k[pu.atoms[i]] += pu.w[i] * k;
    }
  }
}

void AddSuture(const State& s, Workspace& ws, Real* force, int stride) {
  if (!ws.suture_on) return;
  const SutureState& ss = s.suture;
  for (int32_t j = 0; j < ss.num_punctures; ++j) {
    const SuturePuncture& pu = ss.punctures[j];
    double p[3] = {0, 0, 0}, v[3] = {0, 0, 0};
    for (int i = 0; i < kAnchorAtoms && pu.atoms[i] >= 0; ++i) {
      for (int c = 0; c < 3; ++c) {
        p[c] += pu.w[i] * s.atom_pos[3 * pu.atoms[i] + c];
        v[c] += pu.w[i] * s.atom_vel[3 * pu.atoms[i] + c];
      }
    }
    const std::array<double, 9>& cp = ws.suture_points[j];
    double f[3];
    Hold(ss, p, v, &cp[0], &cp[3], &cp[6], f);
    for (int c = 0; c < 3; ++c) f[c] = -f[c];
    if (!Finite3(f)) continue;
    for (int i = 0; i < kAnchorAtoms && pu.atoms[i] >= 0; ++i) {
      const int32_t a = pu.atoms[i];
      if (!ws.atom_mark[a]) continue;
      for (int c = 0; c < 3; ++c) force[stride * a + c] += static_cast<Real>(pu.w[i] * f[c]);
    }
  }
}

double SutureEnergy(const State& s, const Workspace& ws) {
  if (!ws.suture_on) return 0;
  const SutureState& ss = s.suture;
  double energy = 0;
  for (int32_t j = 0; j < ss.num_punctures; ++j) {
    const SuturePuncture& pu = ss.punctures[j];
    double p[3];
    if (!AnchorPoint(s, pu.atoms, pu.w, p)) continue;
    const double d[3] = {p[0] - ws.suture_points[j][0], p[1] - ws.suture_points[j][1], p[2] - ws.suture_points[j][2]};
    energy += 0.5 * ss.hold_k * Dot3(d, d);
  }
  return energy;
}

void SutureDrawnThrough(State& s, int32_t tool, const int32_t* atoms, const double* w, SutureReport* report) {
  SutureState& ss = s.suture;
  if (ss.num_nodes == 0 || ss.tool != tool || ss.num_punctures == kSuturePunctures) return;
  double p[3];
  if (!AnchorPoint(s, atoms, w, p)) return;
  SuturePuncture& pu = ss.punctures[ss.num_punctures++];
  std::copy(atoms, atoms + kAnchorAtoms, pu.atoms);
  std::copy(w, w + kAnchorAtoms, pu.w);
  // Where the thread is when its needle's tail passes: near node 0, on the needle's side of a break.
  pu.s = Nearest(ss, p, 0, ss.broken >= 0 ? std::max(0, ss.broken - 1) : ss.num_nodes - 2);
  if (ss.num_punctures > 1) pu.order = pu.s <= ss.punctures[ss.num_punctures - 2].s ? 1 : -1;
  ++report->new_punctures;
}

void CommitSuture(State& s, Workspace& ws, StepReport* report) {
  SutureState& ss = s.suture;
  SutureReport& sr = report->suture;
  if (ss.num_nodes == 0) return;
  const double dt = ws.options.dt_s;
  const int32_t n = ss.num_nodes;
  // The needle's eye: its tail, from where it was (linearly over the substeps).
  double tail[3] = {ss.eye[0], ss.eye[1], ss.eye[2]};
  const bool pinned = ss.tool >= 0 && ws.tools[ss.tool].kind == ToolKind::kNeedle;
  if (pinned) TailOf(ws.tools[ss.tool], tail);
  const double tail0[3] = {ss.eye[0], ss.eye[1], ss.eye[2]};
  // The punctures where the tissue ended the tick (and their velocities).
  double anchor[kSuturePunctures][6];
  for (int32_t j = 0; j < ss.num_punctures; ++j) {
    const SuturePuncture& pu = ss.punctures[j];
    std::fill(anchor[j], anchor[j] + 6, 0.0);
    for (int i = 0; i < kAnchorAtoms && pu.atoms[i] >= 0; ++i) {
      for (int c = 0; c < 3; ++c) {
        anchor[j][c] += pu.w[i] * s.atom_pos[3 * pu.atoms[i] + c];
        anchor[j][3 + c] += pu.w[i] * s.atom_vel[3 * pu.atoms[i] + c];
      }
    }
  }
  // A tie knots the stitch: its first and last punctures' arc positions, held from now on.
  if (ws.suture_tie) {
    if (ss.num_punctures - ss.stitch_start >= 2 && ss.num_ties < kSutureTies) {
      SutureTie& tie = ss.ties[ss.num_ties++];
      tie.first = ss.stitch_start;
      tie.last = ss.num_punctures - 1;
      tie.s_a = ss.punctures[tie.first].s;
      tie.s_b = ss.punctures[tie.last].s;
      ss.stitch_start = ss.num_punctures;
      sr.tied = true;
    } else {
      sr.tie_refused = true;
    }
  }
  // Knots cinch while the loop pulls less than the tie force at both ends: the knot's points move
  // into the loop, and KnotStop drags the punctures' arc positions with them (the thread is drawn
  // out through them).
  for (int32_t j = 0; j < ss.num_ties; ++j) {
    SutureTie& tie = ss.ties[j];
    if (!(Tension(ss, tie.s_a) < ss.tie_force && Tension(ss, tie.s_b) < ss.tie_force)) continue;
    // Not past the stitch's inner punctures (the knot draws its outer two toward them at most).
    const double step = 0.5 * ss.tie_speed * dt / ss.seg_len;  // each side, in segments
    const double inner_a = ss.punctures[tie.last > tie.first ? tie.first + 1 : tie.first].s;
    const double inner_b = ss.punctures[tie.last > tie.first ? tie.last - 1 : tie.last].s;
    const double dir = tie.s_b >= tie.s_a ? 1.0 : -1.0;
    tie.s_a += dir * std::clamp(dir * (inner_a - tie.s_a), 0.0, step);
    tie.s_b -= dir * std::clamp(dir * (tie.s_b - inner_b), 0.0, step);
  }
  const int32_t substeps = Substeps(ss, dt);
  const double h = dt / substeps;
  // Scratch on the stack: the nodes' forces, and their positions at the tick's start.
  double force[3 * (kSutureSegments + 1)];
  double pos0[3 * (kSutureSegments + 1)];
  std::copy(ss.pos.begin(), ss.pos.begin() + 3 * n, pos0);
  double max_tension = 0, pull[3] = {0, 0, 0};
  int32_t snapped = -1;
  for (int32_t k = 0; k < substeps; ++k) {
    std::fill(force, force + 3 * n, 0.0);
    max_tension = 0;
    // Segments: tension only (a thread goes slack).
    for (int32_t i = 0; i + 1 < n; ++i) {
      if (i == ss.broken) continue;
      double d[3], dv[3];
      for (int c = 0; c < 3; ++c)
        d[c] = ss.pos[3 * (i + 1) + c] - ss.pos[3 * i + c], dv[c] = ss.vel[3 * (i + 1) + c] - ss.vel[3 * i + c];
      const double l = std::sqrt(Dot3(d, d));
      if (!(l > ss.seg_len) || !(l > 0)) continue;
      const double tension = std::max(0.0, ss.k * (l - ss.seg_len) + ss.b * Dot3(dv, d) / l);
      for (int c = 0; c < 3; ++c) {
        force[3 * i + c] += tension * d[c] / l;
        force[3 * (i + 1) + c] -= tension * d[c] / l;
      }
      if (tension > max_tension) max_tension = tension;
      if (ss.strength > 0 && tension > ss.strength && snapped < 0) snapped = i;
    }
    // The eye holds node 0 with its spring-damper (the hand feels it, averaged).
    if (pinned) {
      const double f = static_cast<double>(k + 1) / substeps;
      for (int c = 0; c < 3; ++c) {
        const double eye = tail0[c] + f * (tail[c] - tail0[c]), eye_v = (tail[c] - tail0[c]) / dt;
        const double fe = ss.eye_k * (eye - ss.pos[c]) + ss.eye_b * (eye_v - ss.vel[c]);
        force[c] += fe;
        pull[c] += fe / substeps;
      }
    }
    // Punctures: the thread's nearest point held to each.
    for (int32_t j = 0; j < ss.num_punctures; ++j) {
      double cp[3], cv[3], dir[3], f[3];
      ThreadPoint(ss, ss.punctures[j].s, cp, cv, dir);
      Hold(ss, anchor[j], anchor[j] + 3, cp, cv, dir, f);
      AddAt(ss, ss.punctures[j].s, f, force);
    }
    // Knots: pulled together, at most the tie force.
    for (int32_t j = 0; j < ss.num_ties; ++j) {
      double a[3], b[3];
      ThreadPoint(ss, ss.ties[j].s_a, a);
      ThreadPoint(ss, ss.ties[j].s_b, b);
      const double d[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
      const double l = std::sqrt(Dot3(d, d));
      if (!(l > 0)) continue;
      const double mag = std::min(ss.k * l, ss.tie_force) / l;
      const double fa[3] = {mag * d[0], mag * d[1], mag * d[2]};
      const double fb[3] = {-fa[0], -fa[1], -fa[2]};
      AddAt(ss, ss.ties[j].s_a, fa, force);
      AddAt(ss, ss.ties[j].s_b, fb, force);
    }
    // Symplectic Euler.
    const double damp = 1 / (1 + h * ss.drag);  // the air drag, implicitly
    for (int32_t i = 0; i < n; ++i) {
      for (int c = 0; c < 3; ++c) {
        double& v = ss.vel[3 * i + c];
        v = (v + h * force[3 * i + c] / ss.node_mass) * damp;
        ss.pos[3 * i + c] += h * v;
      }
    }
    // Each puncture follows the thread's nearest point; a knot on it does not pass in.
    for (int32_t j = 0; j < ss.num_punctures; ++j) {
      int32_t lo = 0, hi = 0;
      SlideRange(ss, ss.punctures[j].s, &lo, &hi);
      ss.punctures[j].s = KnotStop(ss, j, Nearest(ss, anchor[j], lo, hi));
    }
    for (int32_t j = 1; j < ss.num_punctures; ++j) {
      SuturePuncture& pu = ss.punctures[j];
      const double prev = ss.punctures[j - 1].s;
      if (pu.order > 0) pu.s = std::min(pu.s, prev);
      if (pu.order < 0) pu.s = std::max(pu.s, prev);
    }
  }
  // A thread that went non-finite is put back where it was, at rest (counted with the repairs).
  bool finite = true;
  for (int32_t i = 0; i < 3 * n && finite; ++i) finite = std::isfinite(ss.pos[i]) && std::isfinite(ss.vel[i]);
  if (!finite) {
    std::copy(pos0, pos0 + 3 * n, ss.pos.begin());
    std::fill(ss.vel.begin(), ss.vel.begin() + 3 * n, 0.0);
    ++s.warnings.state_repaired;
    max_tension = 0;
    pull[0] = pull[1] = pull[2] = 0;
    snapped = -1;
  }
  if (snapped >= 0 && ss.broken < 0) {
    ss.broken = snapped;
    sr.broke = true;
  }
  // The hand feels the thread at the eye: the eye's force on node 0 is the tool's on the world.
  std::copy(tail, tail + 3, ss.eye.begin());
  if (pinned) {
    ActiveTool& at = ws.tools[ss.tool];
    for (int c = 0; c < 3; ++c) at.tick_force[c] += pull[c];
    sr.pull = std::sqrt(Dot3(pull, pull));
  }
  sr.nodes = n;
  sr.punctures = ss.num_punctures;
  sr.ties = ss.num_ties;
  sr.max_tension = max_tension;
  sr.substeps = substeps;
}

}  // namespace internal
}  // namespace idms
