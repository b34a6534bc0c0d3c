// The scripted and human (simulated hand) devices and the --device spec parser.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <string>

#include "device_internal.h"
#include "idms/agent/device.h"
#include "idms/sim/drag.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/model.h"
#include "text_internal.h"

namespace idms::agent {
namespace {

// Script time for loop time t: the script played forwards, then backwards, and so on, so a run
// longer than the script stays continuous (no jump from the end pose back to the start pose).
double PingPong(double t, double duration) {
  if (duration <= 0) return 0;
  const double period = 2 * duration;
  const double u = std::fmod(std::max(t, 0.0), period);
  return u <= duration ? u : period - u;
}

// The scripted target at time t_s, in device coordinates.
struct ScriptTarget {
  Script script = Script::kPalpate;
  ScriptGeometry geometry;
  Registration registration;
  double duration_s = 0;
  ToolKind tool_kinds[kMaxTools] = {ToolKind::kSphere};
  int32_t num_tools = 1;

  // The position and button; into `reading` too, the orientation where the script gives one (the
  // pierce) and the tool it holds (the suture).
  void At(double t_s, double pos_device[3], bool* closed, DeviceReading* reading = nullptr) const {
    // The suture is played once and then held: played backwards, its needle would unpick it.
    const double t = script == Script::kSuture ? std::min(t_s, duration_s) : PingPong(t_s, duration_s);
    const ScriptSample s = SampleScript(script, geometry, t);
    registration.ModelToDevice(s.pos, pos_device);
    *closed = s.closed;
    if (reading != nullptr && s.oriented)
      reading->oriented = registration.OrientationToDevice(s.orientation, reading->orientation);
    // The tool the script holds now: the scene's first of its kind (none: the one held).
    if (reading != nullptr && s.kind != ToolKind::kNone) {
      for (int32_t i = 0; i < num_tools; ++i) {
        if (tool_kinds[i] == s.kind) {
          reading->tool = i;
          break;
        }
      }
    }
  }
};

// scripted:NAME — the device is exactly where the script says; forces go nowhere.
class ScriptedDevice final : public Device {
 public:
  ScriptedDevice(ScriptTarget target, std::string name) : target_(target), name_(std::move(name)) {}
  void Read(int64_t, double t_s, DeviceReading* out) override {
    target_.At(t_s, out->pos, &out->closed, out);
    out->valid = true;
  }
  void Write(int64_t, const double*) override {}
  void Release() override {}
  const char* name() const override { return name_.c_str(); }

 private:
  ScriptTarget target_;
  std::string name_;
};

// human:NAME — a hand of mass m held by a spring k and damper c to the scripted target; the
// device force acts on it, so contact pushes the hand back and stability is closed-loop:
//   m a = k (target - x) - c v + f_device   (device frame), symplectic Euler at the loop tick.
class HumanDevice final : public Device {
 public:
  HumanDevice(ScriptTarget target, std::string name, double mass, double k, double zeta, double dt_s)
      : target_(target), name_(std::move(name)), mass_(mass), k_(k), c_(2 * zeta * std::sqrt(k * mass)), dt_s_(dt_s) {
    bool closed = false;
    target_.At(0, x_, &closed);
  }

  void Read(int64_t, double t_s, DeviceReading* out) override {
    // The hand moves under the spring to the target, its damping and last tick's device force.
    double target[3];
    target_.At(t_s, target, &out->closed, out);  // the hand turns as the script does
    for (int i = 0; i < 3; ++i) {
      const double a = (k_ * (target[i] - x_[i]) - c_ * v_[i] + force_[i]) / mass_;
      v_[i] += dt_s_ * a;
      x_[i] += dt_s_ * v_[i];
      out->pos[i] = x_[i];
    }
    out->valid = true;
  }
  void Write(int64_t, const double force[3]) override {
    for (int i = 0; i < 3; ++i) force_[i] = force[i];
  }
  void Release() override { force_[0] = force_[1] = force_[2] = 0; }
  const char* name() const override { return name_.c_str(); }

 private:
  ScriptTarget target_;
  std::string name_;
  double mass_, k_, c_, dt_s_;
  double x_[3] = {0, 0, 0}, v_[3] = {0, 0, 0}, force_[3] = {0, 0, 0};
};

// scripted:drag — press, then push sideways with a constant force through a simulated hand
// (sim/drag.h): the hand's x is free and the device force pushes it back, so a contact with
// friction holds below mu_s f_n and slides above it. Played once; then it holds its last pose.
class DragDevice final : public Device {
 public:
  DragDevice(const ScriptGeometry& geometry, const DragOptions& options, const Registration& registration, double dt_s)
      : hand_(geometry, options), registration_(registration), dt_s_(dt_s) {}

  void Read(int64_t, double t_s, DeviceReading* out) override {
    const ScriptSample s = hand_.Next(std::min(t_s + dt_s_, hand_.Duration()), force_model_);
    registration_.ModelToDevice(s.pos, out->pos);
    out->closed = false;
    out->valid = true;
  }
  void Write(int64_t, const double force[3]) override { registration_.ForceToModel(force, force_model_); }
  void Release() override { force_model_[0] = force_model_[1] = force_model_[2] = 0; }
  const char* name() const override { return "scripted:drag"; }

 private:
  DragHand hand_;
  Registration registration_;
  double dt_s_;
  double force_model_[3] = {0, 0, 0};
};

// "key=value" options after the first comma of a spec.
bool ParseOption(std::string_view item, std::string_view* key, double* value, std::string* error) {
  const size_t eq = item.find('=');
  if (eq == std::string_view::npos) {
    *error = Cat({"expected KEY=VALUE, got '", item}) + "'";
    return false;
  }
  *key = item.substr(0, eq);
  const std::string_view text = item.substr(eq + 1);
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), *value);
  if (ec != std::errc() || ptr != text.data() + text.size() || !std::isfinite(*value)) {
    *error = Cat({"'", *key, "' needs a number, got '", text, "'"});
    return false;
  }
  return true;
}

std::unique_ptr<Device> MakeScriptDevice(bool human, std::string_view args, const DeviceContext& context,
                                         std::string* error) {
  // The script name, then options.
  const size_t comma = args.find(',');
  const std::string_view script_name = args.substr(0, comma);
  ScriptTarget target;
  if (!human && script_name == "drag") {
    if (context.model == nullptr) {
      *error = "a scripted device needs the model";
      return nullptr;
    }
    if (!(context.mu_s > 0)) {
      *error =
          "drag pushes at a fraction of mu_s f_n: give the tool friction (--friction mu_s=S or the scene's "
          "static_friction)";
      return nullptr;
    }
    DragOptions options;
    options.mu_s = context.mu_s;
    if (comma != std::string_view::npos && !ParseDragSpec(args.substr(comma + 1), &options, error)) return nullptr;
    return std::make_unique<DragDevice>(MakeScriptGeometry(*context.model, context.mio_radius), options,
                                        context.registration, context.dt_s);
  }
  if (!ParseScriptName(script_name, &target.script)) {
    *error = Cat({"unknown script '", script_name}) +
             "': expected palpate, stroke-slow, stroke-fast, pluck, stroke-gentle, scan, pierce, stitch, suture or "
             "(scripted) drag";
    return nullptr;
  }
  if (context.model == nullptr) {
    *error = "a scripted device needs the model";
    return nullptr;
  }
  target.registration = context.registration;
  std::copy(context.tool_kinds, context.tool_kinds + kMaxTools, target.tool_kinds);
  target.num_tools = context.num_tools;
  const std::string name = std::string(human ? "human:" : "scripted:") + std::string(script_name);
  // Hand parameters: a light hand (50 g) on a soft arm (5 Hz), damped; the scan's grid.
  double mass = 0.05, k = 60, zeta = 0.7;
  int grid = kScanGrid;
  std::string_view rest = comma == std::string_view::npos ? std::string_view() : args.substr(comma + 1);
  while (!rest.empty()) {
    const size_t next = rest.find(',');
    std::string_view key;
    double value = 0;
    if (!ParseOption(rest.substr(0, next), &key, &value, error)) return nullptr;
    if (human && key == "mass" && value > 0) {
      mass = value;
    } else if (human && key == "k" && value > 0) {
      k = value;
    } else if (human && key == "zeta" && value >= 0) {
      zeta = value;
    } else if (target.script == Script::kScan && key == "grid" && value >= kMinScanGrid && value <= kMaxScanGrid &&
               value == std::floor(value)) {
      grid = static_cast<int>(value);
    } else {
      const bool scan = target.script == Script::kScan;
      *error = Cat({"option '", key, "' is unknown or out of range here",
                    human  ? (scan ? " (human: mass > 0, k > 0, zeta >= 0; scan: grid = 2 to 15)"
                                   : " (human: mass > 0, k > 0, zeta >= 0)")
                    : scan ? " (scan: grid = 2 to 15)"
                           : " (scripted devices take no options)"});
      return nullptr;
    }
    rest = next == std::string_view::npos ? std::string_view() : rest.substr(next + 1);
  }
  target.geometry = MakeScriptGeometry(*context.model, context.mio_radius, grid);
  target.duration_s = ScriptDuration(target.script, target.geometry);
  if (human) {
    // The hand's own integrator (symplectic Euler at the loop's dt) is stable only while
    // (w dt)^2 + 4 zeta (w dt) < 4, w = sqrt(k / m): beyond it the hand diverges on its own.
    const double w_dt = std::sqrt(k / mass) * context.dt_s;
    const double limit = 2 * (std::sqrt(zeta * zeta + 1) - zeta);
    if (!(w_dt < limit)) {
      char text[512];
      std::snprintf(text, sizeof(text),
                    "human: a hand of mass=%g, k=%g, zeta=%g is unstable at the loop's dt = %g s: "
                    "sqrt(k/mass)*dt = %.3g, and its symplectic Euler step is stable only below %.3g "
                    "(raise mass, lower k or zeta, or run the loop faster)",
                    mass, k, zeta, context.dt_s, w_dt, limit);
      *error = text;
      return nullptr;
    }
    return std::make_unique<HumanDevice>(target, name, mass, k, zeta, context.dt_s);
  }
  return std::make_unique<ScriptedDevice>(target, name);
}

}  // namespace

std::unique_ptr<Device> MakeDevice(std::string_view spec, const DeviceContext& context, std::string* error) {
  const size_t colon = spec.find(':');
  const std::string_view kind = spec.substr(0, colon);
  const std::string_view args = colon == std::string_view::npos ? std::string_view() : spec.substr(colon + 1);
  std::string why;
  std::unique_ptr<Device> device;
  if (kind == "scripted" || kind == "human") {
    device = MakeScriptDevice(kind == "human", args, context, &why);
  } else if (kind == "udp") {
    device = MakeUdpDevice(args, context.dt_s, &why);
  } else if (kind == "replay") {
    device = MakeReplayDevice(args, context.registration, &why);
  } else {
    why = "expected scripted:SCRIPT, human:SCRIPT, udp:PORT or replay:FILE.mcap";
  }
  if (!device) *error = Cat({"--device '", spec}) + "': " + why;
  return device;
}

bool DeviceScriptName(std::string_view spec, std::string* script) {
  for (std::string_view prefix : {std::string_view("scripted:"), std::string_view("human:")}) {
    if (spec.substr(0, prefix.size()) == prefix) {
      const std::string_view rest = spec.substr(prefix.size());
      *script = std::string(rest.substr(0, rest.find(',')));
      return true;
    }
  }
  return false;
}

}  // namespace idms::agent
