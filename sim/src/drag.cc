// The drag interaction: press, settle, then a constant sideways push through a simulated hand.
#include "idms/sim/drag.h"

#include <cmath>
#include <cstdlib>
#include <numbers>

namespace idms {

bool ParseDragSpec(std::string_view spec, DragOptions* o, std::string* error) {
  if (spec.substr(0, 5) == "drag:") spec.remove_prefix(5);
  if (spec == "drag") spec = {};
  while (!spec.empty()) {
    const size_t comma = spec.find(',');
    const std::string item(spec.substr(0, comma));
    spec = comma == std::string_view::npos ? std::string_view{} : spec.substr(comma + 1);
    const size_t eq = item.find('=');
    const std::string key = item.substr(0, eq), value = eq == std::string::npos ? "" : item.substr(eq + 1);
    char* end = nullptr;
    const double x = std::strtod(value.c_str(), &end);
    const bool ok = !value.empty() && *end == '\0' && std::isfinite(x);
    double* field = key == "fraction"  ? &o->fraction
                    : key == "depth"   ? &o->depth
                    : key == "mass"    ? &o->hand_mass
                    : key == "damping" ? &o->hand_damping
                    : key == "push"    ? &o->push_s
                                       : nullptr;
    const bool positive = key == "mass" || key == "push";
    if (field == nullptr || !ok || x < 0 || (positive && x == 0) || (key == "push" && x <= o->ramp_s)) {
      *error = "drag: bad item '" + item + "' (expected fraction=F>=0, depth=D>=0, mass=M>0, damping=B>=0, push=S>" +
               std::to_string(o->ramp_s) + ")";
      return false;
    }
    *field = x;
  }
  return true;
}

DragHand::DragHand(const ScriptGeometry& geometry, const DragOptions& options) : g_(geometry), o_(options) {
  if (o_.hand_damping < 0) o_.hand_damping = 2 * std::sqrt(400 * o_.hand_mass);
  x_ = g_.center[0];
}

ScriptSample DragHand::Next(double t, const double f[3]) {
  const double dt = t - t_;
  t_ = t;
  ScriptSample out;
  const double contact_z = g_.top_z + g_.mio_radius;
  if (t < o_.press_s) {
    // Down from 1 unit above first contact, eased.
    const double s = 0.5 * (1 - std::cos(std::numbers::pi * t / o_.press_s));
    out.pos[2] = contact_z + 1.0 - s * (1.0 + o_.depth);
  } else {
    out.pos[2] = contact_z - o_.depth;
  }
  const double push_start = PushStart();
  if (t <= push_start) {
    // The normal force the push is scaled to: the settle's last 0.2 s.
    if (t > push_start - 0.2) fn_sum_ += std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]), ++fn_n_;
    fn_ = fn_n_ > 0 ? fn_sum_ / fn_n_ : 0;
    push_ = 0;
  } else {
    const double u = std::fmin(1.0, (t - push_start) / o_.ramp_s);
    push_ = o_.fraction * o_.mu_s * fn_ * 0.5 * (1 - std::cos(std::numbers::pi * u));
    // The hand: semi-implicit Euler, the damping implicit (stable for any damping).
    if (dt > 0) {
      v_ = (v_ + dt * (push_ + f[0]) / o_.hand_mass) / (1 + dt * o_.hand_damping / o_.hand_mass);
      x_ += dt * v_;
    }
  }
  out.pos[0] = x_;
  out.pos[1] = g_.center[1];
  return out;
}

}  // namespace idms
