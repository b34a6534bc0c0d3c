// Tools: the sphere MIO contact law (thesis 5.5.1), tweezers grasping (6.1.3), scalpel sweeps
// (3.2.6), and the validation of the device input that feeds them.
#include "idms/sim/tool.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "idms/sim/model.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms {
namespace {

inline void Sub(const double* a, const double* b, double* out) {
  out[0] = a[0] - b[0], out[1] = a[1] - b[1], out[2] = a[2] - b[2];
}
inline double Dot(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline void Cross(const double* a, const double* b, double* out) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

}  // namespace

ContactForce SphereContact(ContactLaw law, double k, double r, double min_distance_fraction, const double d[3]) {
  ContactForce out;
  const double dist2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  if (!(dist2 < r * r)) return out;  // outside, or non-finite
  const double dist = std::sqrt(dist2);
  // d^, and +z when the atom sits on the centre.
  double n[3] = {0, 0, 1};
  if (dist > 1e-12 * r) n[0] = d[0] / dist, n[1] = d[1] / dist, n[2] = d[2] / dist;
  double mag = 0;
  if (law == ContactLaw::kThesis) {
    // Thesis 5.5.1: f = k (r - |d|) / |d| * d / |d|; |d| clamped at d_min so f stays finite.
    const double dmin = min_distance_fraction * r;
    const double de = std::max(dist, dmin);
    mag = k * (r - de) / de;
    out.stiffness = k * r / (de * de);
    // Potential: integral of the magnitude from |d| to r, continued linearly below d_min.
    out.energy = k * (r * std::log(r / de) - (r - de)) + (dist < dmin ? mag * (dmin - dist) : 0.0);
  } else {
    mag = k * (r - dist);
    out.stiffness = k;
    out.energy = 0.5 * k * (r - dist) * (r - dist);
  }
  out.f[0] = mag * n[0], out.f[1] = mag * n[1], out.f[2] = mag * n[2];
  out.touching = true;
  return out;
}

bool SegmentCrossesTriangle(const double p[3], const double q[3], const double a[3], const double b[3],
                            const double c[3]) {
  double dir[3], e1[3], e2[3], h[3], s[3], qv[3];
  Sub(q, p, dir);
  Sub(b, a, e1);
  Sub(c, a, e2);
  Cross(dir, e2, h);
  const double det = Dot(e1, h);
  // Parallel or degenerate (a blade that did not move sweeps no area): no crossing.
  const double scale = std::sqrt(Dot(dir, dir) * Dot(e1, e1) * Dot(e2, e2));
  if (!(std::fabs(det) > 1e-12 * scale)) return false;
  const double inv = 1.0 / det;
  Sub(p, a, s);
  const double u = inv * Dot(s, h);
  if (u < 0 || u > 1) return false;
  Cross(s, e1, qv);
  const double v = inv * Dot(dir, qv);
  if (v < 0 || u + v > 1) return false;
  const double t = inv * Dot(e2, qv);
  return t >= 0 && t <= 1;
}

bool SegmentCrossesSweep(const double p[3], const double q[3], const double a0[3], const double b0[3],
                         const double a1[3], const double b1[3]) {
  return SegmentCrossesTriangle(p, q, a0, b0, b1) || SegmentCrossesTriangle(p, q, a0, b1, a1);
}

bool SetFrictionItem(std::string_view key, std::string_view value, ToolCommand* tool) {
  double* field = key == "mu_s"   ? &tool->mu_s
                  : key == "mu_d" ? &tool->mu_d
                  : key == "k_t"  ? &tool->friction_stiffness
                  : key == "b_t"  ? &tool->friction_damping
                                  : nullptr;
  const std::string text(value);
  char* end = nullptr;
  const double x = std::strtod(text.c_str(), &end);
  if (field == nullptr || text.empty() || *end != '\0' || !std::isfinite(x)) return false;
  *field = x;
  return true;
}

bool ValidateFriction(const ToolCommand& t, std::string* error) {
  auto num = [](double v) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%g", v);
    return std::string(buf);
  };
  if (!(std::isfinite(t.mu_s) && t.mu_s >= 0)) {
    *error = "mu_s must be a finite number >= 0, got " + num(t.mu_s);
  } else if (!(std::isfinite(t.mu_d) && t.mu_d >= 0)) {
    *error = "mu_d must be a finite number >= 0, got " + num(t.mu_d);
  } else if (t.mu_d > t.mu_s) {
    *error = "mu_d must be <= mu_s (" + num(t.mu_s) + "), got " + num(t.mu_d);
  } else if (!(std::isfinite(t.friction_stiffness) && t.friction_stiffness >= 0)) {
    *error = "k_t must be a finite number > 0 (0 = the tool's stiffness), got " + num(t.friction_stiffness);
  } else if (!std::isfinite(t.friction_damping)) {
    *error = "b_t must be a finite number >= 0 (< 0 = k_t dt), got " + num(t.friction_damping);
  } else {
    return true;
  }
  return false;
}

namespace {

// Splits "a=1,b=2" at commas and calls item(key, value, whole item) for each; an empty spec has
// one empty item. Stops at the first item that returns false.
template <typename F>
bool ForEachItem(std::string_view spec, F&& item) {
  while (true) {
    const size_t comma = spec.find(',');
    const std::string_view whole = spec.substr(0, comma);
    const size_t eq = whole.find('=');
    const std::string_view key = whole.substr(0, eq);
    const std::string_view value = eq == std::string_view::npos ? std::string_view{} : whole.substr(eq + 1);
    if (!item(key, value, whole)) return false;
    if (comma == std::string_view::npos) return true;
    spec.remove_prefix(comma + 1);
  }
}

bool PositiveNumber(std::string_view value, double* out) {
  const std::string text(value);
  char* end = nullptr;
  const double x = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !std::isfinite(x) || !(x > 0)) return false;
  *out = x;
  return true;
}

}  // namespace

bool ParseFrictionSpec(std::string_view spec, ToolCommand* tool, FrictionGiven* given, std::string* error) {
  *given = {};
  const bool items = ForEachItem(spec, [&](std::string_view key, std::string_view value, std::string_view whole) {
    bool* seen = key == "mu_s"   ? &given->mu_s
                 : key == "mu_d" ? &given->mu_d
                 : key == "k_t"  ? &given->k_t
                 : key == "b_t"  ? &given->b_t
                                 : nullptr;
    if (seen == nullptr || *seen || whole.find('=') == std::string_view::npos || !SetFrictionItem(key, value, tool)) {
      *error =
          "bad item '" + std::string(whole) + "' (expected mu_s=S[,mu_d=D,k_t=K,b_t=B], each once, finite numbers)";
      return false;
    }
    return *seen = true;
  });
  if (!items) return false;
  if (!given->mu_s) {
    *error = "give mu_s=S (the static coefficient, >= 0)";
    return false;
  }
  if (!given->mu_d) tool->mu_d = tool->mu_s;
  return ValidateFriction(*tool, error);
}

bool ParseToolSpec(std::string_view spec, ToolCommand* tool, std::string* error) {
  const size_t colon = spec.find(':');
  const std::string_view kind = spec.substr(0, colon);
  const std::string quoted = "--tool '" + std::string(spec) + "': ";
  if (kind == "sphere") {
    tool->kind = ToolKind::kSphere;
  } else if (kind == "tweezers") {
    tool->kind = ToolKind::kTweezers;
  } else {
    *error = quoted + "expected sphere:... or tweezers:...";
    return false;
  }
  if (colon == std::string_view::npos || colon + 1 == spec.size()) return true;
  bool mu_d_given = false;
  const bool items =
      ForEachItem(spec.substr(colon + 1), [&](std::string_view key, std::string_view value, std::string_view whole) {
        if (key == "r" && PositiveNumber(value, &tool->radius)) return true;
        if (key == "k" && PositiveNumber(value, &tool->stiffness)) return true;
        if (key == "law" && (value == "thesis" || value == "linear")) {
          tool->law = value == "thesis" ? ContactLaw::kThesis : ContactLaw::kLinear;
          return true;
        }
        if (whole.find('=') != std::string_view::npos && SetFrictionItem(key, value, tool)) {
          if (key == "mu_s" && !mu_d_given) tool->mu_d = tool->mu_s;  // mu_d defaults to mu_s
          mu_d_given = mu_d_given || key == "mu_d";
          return true;
        }
        *error = quoted + "bad item '" + std::string(whole) +
                 "' (expected r=POSITIVE, k=POSITIVE, law=thesis|linear, mu_s=, mu_d=, k_t=, b_t=)";
        return false;
      });
  if (!items) return false;
  if (!ValidateFriction(*tool, error)) {
    *error = quoted + *error;
    return false;
  }
  return true;
}

namespace internal {

const ParamRule* FirstBadParam(const ParamRule* rules, int n) {
  for (int i = 0; i < n; ++i) {
    const ParamRule& r = rules[i];
    const double v = r.value;
    bool ok = std::isfinite(v) && v <= r.max;
    if (r.bound == ParamBound::kPositive) ok = ok && v > 0;
    if (r.bound == ParamBound::kNonNegative) ok = ok && v >= 0;
    if (!ok) return &r;
  }
  return nullptr;
}

std::string BadParamMessage(const char* prefix, const ParamRule& rule) {
  char value[32];
  std::snprintf(value, sizeof(value), "%g", rule.value);
  return std::string(prefix) + "." + rule.field + " must be " + rule.expected + ", got " + value;
}

bool CheckParams(const char* prefix, const ParamRule* rules, int n, std::string* error) {
  const ParamRule* bad = FirstBadParam(rules, n);
  if (bad == nullptr) return true;
  *error = BadParamMessage(prefix, *bad);
  return false;
}

namespace {

// Friction's parameters as the step takes them: finite, 0 <= mu_d <= mu_s, and a stiffness and
// damping that are finite (their signs choose defaults). Anything else: no friction (validated at
// the boundary; this is the last line of defence).
bool FrictionValid(const ToolCommand& c) {
  return std::isfinite(c.mu_s) && std::isfinite(c.mu_d) && c.mu_d >= 0 && c.mu_d <= c.mu_s &&
         std::isfinite(c.friction_stiffness) && std::isfinite(c.friction_damping);
}

bool ValidCommand(const ToolCommand& c) {
  if (!Finite3(c.pos)) return false;
  if (c.kind == ToolKind::kScalpel) return Finite3(c.blade);
  if (c.kind == ToolKind::kNeedle && !ValidNeedleCommand(c)) return false;
  return std::isfinite(c.radius) && c.radius > 0 && std::isfinite(c.stiffness) && c.stiffness >= 0;
}

// Elements crossing the quad a blade swept from (a0, b0) to (a1, b1) become pending cuts.
// Candidates: elements of atoms near the sweep (hash) or, in full mode, every element.
int32_t DetectCuts(const Model& m, const State& s, Workspace& ws, const double* a0, const double* b0, const double* a1,
                   const double* b1) {
  int32_t cut = 0;
  auto test = [&](int32_t e) {
    if (ws.elem_cut[e]) return;
    double p[3], q[3];
    for (int c = 0; c < 3; ++c) {
      p[c] = s.atom_pos[3 * m.elem_atoms[2 * e] + c];
      q[c] = s.atom_pos[3 * m.elem_atoms[2 * e + 1] + c];
    }
    if (!SegmentCrossesSweep(p, q, a0, b0, a1, b1)) return;
    ws.elem_cut[e] = 1;
    ws.pending_cuts[ws.num_pending_cuts++] = e;
    ++cut;
  };
  if (ws.options.full) {
    for (int32_t e = 0; e < m.num_elems; ++e) test(e);
    return cut;
  }
  // Each element is tested once: elem_mark + the (still unused) ws.elems list undo the marks.
  // An element crossing a blade's sweep has an endpoint within half its length of the crossing;
  // the longest rest length covers elements stretched up to twice it.
  const double reach = std::max(m.max_leq, 1e-6);
  double lo[3], hi[3];
  for (int c = 0; c < 3; ++c) {
    lo[c] = std::min({a0[c], b0[c], a1[c], b1[c]}) - reach;
    hi[c] = std::max({a0[c], b0[c], a1[c], b1[c]}) + reach;
  }
  int32_t num_seen = 0;
  ForEachAtomInBox(ws.hash, lo, hi, [&](int32_t a) {
    const int32_t adr = m.atom_elem_adr[a];
    for (int32_t j = 0; j < m.atom_elem_num[a]; ++j) {
      const int32_t e = m.atom_elem[adr + j];
      if (ws.elem_mark[e]) continue;
      ws.elem_mark[e] = 1;
      ws.elems[num_seen++] = e;
      test(e);
    }
  });
  for (int32_t i = 0; i < num_seen; ++i) ws.elem_mark[ws.elems[i]] = 0;
  return cut;
}

}  // namespace

void ResolveTools(const Model& m, State& s, Workspace& ws, const ToolInput& input, StepReport* report) {
  const int32_t num_tools = std::clamp(input.num_tools, 0, kMaxTools);
  ws.num_tools = num_tools;
  report->num_tools = num_tools;
  for (int32_t t = 0; t < kMaxTools; ++t) {
    ToolState& ts = s.tools[t];
    ActiveTool& at = ws.tools[t];
    at = ActiveTool{};
    const ToolCommand* cmd = t < num_tools ? &input.tools[t] : nullptr;
    // An unused slot forgets its tool (and lets go of anything it held).
    if (cmd == nullptr || cmd->kind == ToolKind::kNone) {
      ts = ToolState{};
      continue;
    }
    // Valid input becomes the held pose; invalid input falls back to it (or to nothing).
    const bool had_scalpel = ts.has_pos && ts.kind == ToolKind::kScalpel;
    const double prev_base[3] = {ts.pos[0], ts.pos[1], ts.pos[2]};
    const double prev_tip[3] = {ts.blade_tip[0], ts.blade_tip[1], ts.blade_tip[2]};
    if (ValidCommand(*cmd)) {
      for (int c = 0; c < 3; ++c) at.prev_pos[c] = ts.has_pos ? ts.pos[c] : cmd->pos[c];
      for (int c = 0; c < 3; ++c) ts.pos[c] = cmd->pos[c], ts.blade_tip[c] = cmd->pos[c] + cmd->blade[c];
      ts.radius = cmd->radius;
      ts.stiffness = cmd->stiffness;
      if (ts.kind != cmd->kind) ts.grasp_atom = -1, ts.needle = NeedleState{};
      std::copy(cmd->axis, cmd->axis + 3, ts.axis);
      ts.kind = cmd->kind;
      ts.has_pos = true;
    } else {
      ++s.warnings.bad_tool_input;
      report->tools[t].input_held = true;
      if (!ts.has_pos || ts.kind != cmd->kind) continue;
      std::copy(ts.pos, ts.pos + 3, at.prev_pos);
    }
    at.kind = cmd->kind;
    at.law = cmd->law;
    at.closed = report->tools[t].input_held ? ts.closed : cmd->closed;
    for (int c = 0; c < 3; ++c) at.pos[c] = ts.pos[c], at.blade_tip[c] = ts.blade_tip[c];
    at.radius = ts.radius;
    at.stiffness = ts.stiffness;
    at.grasp_atom = ts.grasp_atom;
    at.grasp_leq = ts.grasp_leq;
    at.grasp_k = ts.grasp_k;
    // Friction: resolved coefficients (validated: a bad value is no friction) and the anchor.
    if (IsContactTool(at.kind) && FrictionValid(*cmd) && cmd->mu_s > 0) {
      at.mu_s = cmd->mu_s;
      at.mu_d = cmd->mu_d;
      at.k_t = cmd->friction_stiffness > 0 ? cmd->friction_stiffness : at.stiffness;
      at.b_t = cmd->friction_damping >= 0 ? cmd->friction_damping : at.k_t * ws.options.dt_s;
      std::copy(ts.anchor_atoms, ts.anchor_atoms + kAnchorAtoms, at.anchor_atoms);
      std::copy(ts.anchor_w, ts.anchor_w + kAnchorAtoms, at.anchor_w);
      std::copy(ts.anchor_offset, ts.anchor_offset + 3, at.anchor_offset);
      std::copy(ts.friction_u, ts.friction_u + 3, at.friction_u);
      at.friction = ts.friction;
    } else if (ts.friction != FrictionState::kNone) {
      ts.friction = FrictionState::kNone;  // friction switched off: forget the anchor
      std::fill(ts.anchor_atoms, ts.anchor_atoms + kAnchorAtoms, -1);
    }
    if (at.kind == ToolKind::kNeedle) ResolveNeedle(s, ts, *cmd, ws.options.dt_s, at);
    // Scalpel: the quad swept since the last tick (thesis 3.2.6: slicing removes elements).
    if (at.kind == ToolKind::kScalpel && had_scalpel) {
      report->tools[t].cut_elements = DetectCuts(m, s, ws, prev_base, prev_tip, at.pos, at.blade_tip);
    }
  }
  ResolveSuture(s, ws, input);
}

void UpdateGrasps(const Model& m, State& s, Workspace& ws, StepReport* report) {
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    ActiveTool& at = ws.tools[t];
    ToolState& ts = s.tools[t];
    if (at.kind != ToolKind::kTweezers) continue;
    const bool closed = at.closed;
    // Opening deletes the grasp element (thesis 6.1.3).
    if (!closed) {
      ts.grasp_atom = at.grasp_atom = -1;
    } else if (!ts.closed && at.grasp_atom < 0) {
      // Closing while in contact: the nearest free contact atom to the MIO centre.
      int32_t best = -1;
      double best_d2 = at.radius * at.radius;
      for (int32_t i = 0; i < ws.num_candidates; ++i) {
        const int32_t a = ws.candidates[i];
        if (m.atom_fixed[a]) continue;
        double d2 = 0;
        for (int c = 0; c < 3; ++c) d2 += (s.atom_pos[3 * a + c] - at.pos[c]) * (s.atom_pos[3 * a + c] - at.pos[c]);
        if (d2 < best_d2) best_d2 = d2, best = a;
      }
      if (best >= 0) {
        // The hand-over is continuous (thesis 6.1.3: once the atom is held, the MIO force is the
        // connecting element's): the element starts pushing the atom out with the contact force
        // it had, k (l_eq - l) = |f_contact|, and turns to pulling as the tweezers lift.
        const Real* p = &s.atom_pos[3 * best];
        const double d[3] = {p[0] - at.pos[0], p[1] - at.pos[1], p[2] - at.pos[2]};
        const ContactForce cf = SphereContact(at.law, at.stiffness, at.radius, ws.options.min_distance_fraction, d);
        const double push = std::sqrt(cf.f[0] * cf.f[0] + cf.f[1] * cf.f[1] + cf.f[2] * cf.f[2]);
        ts.grasp_atom = at.grasp_atom = best;
        ts.grasp_leq = at.grasp_leq = std::sqrt(best_d2) + push / at.stiffness;
        ts.grasp_k = at.grasp_k = at.stiffness;
      }
    }
    ts.closed = closed;
    report->tools[t].grasp_atom = at.grasp_atom;
  }
}

}  // namespace internal
}  // namespace idms
