// idms-zwidth-bench: the Z-width of the MIO contact without a device (issue 31). A sampled-data
// device (mass, viscous friction, encoder quantum, zero-order hold) held by a simulated hand
// (mass, spring, damper to a scripted target) drives the real DSM step; the largest stable MIO
// stiffness with the passivity controller off and on, at 1 kHz and 700 Hz, 1-DOF and 3-DOF, on the
// hex fragment and a slab, and the controller's transparency cost. docs/passivity.md.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "idms/sim/generate.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/model.h"
#include "idms/sim/passivity.h"
#include "idms/sim/port_model.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"

namespace idms {
namespace {

enum class HandScript { kTap, kPress, kStroke };
const char* HandScriptName(HandScript s) {
  return s == HandScript::kTap ? "tap" : s == HandScript::kPress ? "press" : "stroke";
}

struct Config {
  double rate_hz = 1000;
  int dof = 3;
  const Model* model = nullptr;
  const char* model_name = "";
  double device_damping = 0.02;
  double hand_damping = 0.01;  // a light grip: the case a stiff contact is hardest to keep passive
};

// The hand's target relative to where the MIO first touches the surface (contact_z): down along z
// to `depth` below it, held, and back; the stroke slides along x while pressed. steady: the script
// times whose force is judged (the hand is pressed in and its target still or moving slowly).
struct Target {
  double x0 = 0, y0 = 0, contact_z = 0;
  HandScript script = HandScript::kPress;
  double duration_s = 0, steady0 = 0, steady1 = 0;

  void At(double t, double out[3]) const {
    const double above = 0.3, depth = 0.25;
    auto ramp = [](double u) { return u <= 0 ? 0.0 : u >= 1 ? 1.0 : 0.5 - 0.5 * std::cos(M_PI * u); };
    double down = 0, dx = 0;
    switch (script) {
      case HandScript::kTap:  // down in 60 ms, 0.4 s in, up in 60 ms
        down = ramp((t - 0.2) / 0.06) - ramp((t - 0.66) / 0.06);
        break;
      case HandScript::kPress:  // down in 0.4 s, 1 s held, up in 0.4 s
        down = ramp((t - 0.2) / 0.4) - ramp((t - 1.6) / 0.4);
        break;
      case HandScript::kStroke:  // pressed, then 1 unit along x and back over 1.2 s
        down = ramp((t - 0.2) / 0.4) - ramp((t - 2.2) / 0.4);
        dx = ramp((t - 0.8) / 0.6) - ramp((t - 1.4) / 0.6);
        break;
    }
    out[0] = x0 + dx;
    out[1] = y0;
    out[2] = contact_z + above - (above + depth) * down;
  }
};

Target MakeTarget(const Model& model, HandScript script) {
  const ScriptGeometry g = MakeScriptGeometry(model, 1.5);
  Target t;
  t.x0 = g.center[0] - (script == HandScript::kStroke ? 0.5 : 0.0);
  t.y0 = g.center[1];
  t.contact_z = g.top_z + g.mio_radius;
  t.script = script;
  t.duration_s = script == HandScript::kTap ? 1.0 : script == HandScript::kPress ? 2.2 : 2.8;
  t.steady0 = script == HandScript::kTap ? 0.36 : 0.8;
  t.steady1 = script == HandScript::kTap ? 0.64 : script == HandScript::kPress ? 1.6 : 2.2;
  return t;
}

struct Run {
  bool finite = true;
  double band_rms = 0;        // 10-200 Hz part of |F| in the steady part's second half, force units
  double band_rms_early = 0;  // the same in its first half
  double mean_force = 0;      // |F| in the steady part
  double dissipated = 0, work_in = 0;
  double min_window = 0;
  std::vector<double> steady_force;  // |F| per tick of the steady part (for the transparency cost)
};

// Centred moving average of x over n samples (n odd), edges shortened.
std::vector<double> MovingAverage(const std::vector<double>& x, int n) {
  std::vector<double> out(x.size());
  const int h = n / 2;
  for (size_t i = 0; i < x.size(); ++i) {
    const size_t a = i >= static_cast<size_t>(h) ? i - h : 0, b = std::min(x.size(), i + h + 1);
    double s = 0;
    for (size_t j = a; j < b; ++j) s += x[j];
    out[i] = s / static_cast<double>(b - a);
  }
  return out;
}

Run RunOne(const Config& c, double k, HandScript script, bool controller) {
  const Model& model = *c.model;
  const double dt = 1 / c.rate_hz;
  StepOptions so;
  so.dt_s = dt;
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, so);
  ResyncWorkspace(model, state, ws);
  ToolInput input;
  input.num_tools = 1;
  ToolCommand& tool = input.tools[0];
  tool.kind = ToolKind::kSphere;
  tool.radius = 1.5;
  tool.stiffness = k;
  const Target target = MakeTarget(model, script);
  PortModelOptions po;
  po.dof = c.dof;
  po.dt_s = dt;
  po.device_damping = c.device_damping;
  po.hand_damping = c.hand_damping;
  po.quantum = 2.5e-4;
  double start[3];
  target.At(0, start);
  PortModel port(po, start);
  PassivityOptions pco;
  pco.enabled = controller;
  pco.dt_s = dt;
  pco.window_s = 0.1;
  pco.max_damping = po.device_mass / dt;  // a sampled damper on the device alone turns active past m / T
  pco.quantum = po.quantum;
  PassivityController pc(pco);
  Run run;
  std::vector<double> force;
  const auto ticks = static_cast<int64_t>(std::llround(target.duration_s / dt));
  int64_t s0 = -1, s1 = -1;
  for (int64_t n = 0; n < ticks; ++n) {
    const double t = n * dt;
    // Encoder, step, controller, the device's clamp, the held force on the device and hand.
    port.Read(tool.pos);
    const StepReport r = Step(model, state, ws, input);
    double f[3];
    pc.Update(tool.pos, true, r.tools[0].force, r.energy_after, f);
    const double norm = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    if (!(norm <= 10)) {
      const double keep = std::isfinite(norm) ? 10 / norm : 0;
      for (double& v : f) v = std::isfinite(v) ? v * keep : 0;
    }
    pc.Commanded(f);
    double aim[3];
    target.At(t + dt, aim);
    port.Advance(f, aim);
    run.finite = run.finite && std::isfinite(port.pos()[2]);
    force.push_back(std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]));
    if (s0 < 0 && t >= target.steady0) s0 = n;
    if (t < target.steady1) s1 = n;
  }
  // The steady part's 10-200 Hz band: a 5 ms average (a zero near 200 Hz) less a 100 ms one.
  const auto fast = MovingAverage(force, std::max(1, static_cast<int>(std::lround(0.005 / dt))) | 1);
  const auto slow = MovingAverage(force, static_cast<int>(std::lround(0.1 / dt)) | 1);
  // Its halves: a transient decays from the first to the second; a limit cycle or a growing
  // oscillation does not.
  double band2[2] = {0, 0}, sum = 0;
  const int64_t mid = (s0 + s1) / 2;
  for (int64_t n = s0; n <= s1; ++n) {
    const double b = fast[n] - slow[n];
    band2[n > mid] += b * b;
    sum += force[n];
    run.steady_force.push_back(force[n]);
  }
  run.band_rms_early = std::sqrt(band2[0] / static_cast<double>(mid - s0 + 1));
  run.band_rms = std::sqrt(band2[1] / static_cast<double>(s1 - mid));
  run.mean_force = sum / static_cast<double>(s1 - s0 + 1);
  run.dissipated = pc.dissipated();
  run.work_in = pc.work_in();
  run.min_window = pc.min_window_energy();
  return run;
}

// Stable: finite, and in the steady part's second half the 10-200 Hz band of |F| is either below 3%
// of the mean force (0.02 force units at least: the encoder's own noise through the contact) or
// below 0.7 times the first half's (a transient dying out, not a limit cycle or a growing one).
bool Stable(const Run& r) {
  return r.finite && (r.band_rms <= std::max(0.03 * r.mean_force, 0.02) || r.band_rms < 0.7 * r.band_rms_early);
}

struct Scan {
  double k_max = 0;  // largest k with every scanned k' <= k stable in every script
  bool capped = false;
};

std::vector<HandScript> ScriptsFor(int dof) {
  if (dof == 1) return {HandScript::kTap, HandScript::kPress};
  return {HandScript::kTap, HandScript::kPress, HandScript::kStroke};
}

// Stability is judged on the tap and the press (their steady parts are a held contact); the stroke's
// slide over the atoms is texture in the same band, so it counts for passivity and transparency only.
bool StableAt(const Config& c, double k, bool controller) {
  for (HandScript s : ScriptsFor(1))
    if (!Stable(RunOne(c, k, s, controller))) return false;
  return true;
}

// Geometric scan from k_lo by `ratio`, then bisections between the last stable and first unstable.
Scan FindKMax(const Config& c, bool controller, double k_lo, double k_hi, double ratio, int bisections) {
  Scan out;
  double good = 0, bad = 0;
  for (double k = k_lo; k <= k_hi * 1.0001; k *= ratio) {
    if (StableAt(c, k, controller)) {
      good = k;
    } else {
      bad = k;
      break;
    }
  }
  if (bad == 0) {
    out.k_max = good;
    out.capped = true;
    return out;
  }
  if (good == 0) return out;
  for (int i = 0; i < bisections; ++i) {
    const double mid = std::sqrt(good * bad);
    (StableAt(c, mid, controller) ? good : bad) = mid;
  }
  out.k_max = good;
  return out;
}

// Transparency at k (stable both ways): RMS of |F_on| - |F_off| over the steady parts against the
// RMS of |F_off|, and the controller's dissipation against the work the hand did.
void Transparency(const Config& c, double k, double* rms_error, double* dissipated_fraction) {
  double e2 = 0, f2 = 0, dissipated = 0, work = 0;
  for (HandScript s : ScriptsFor(c.dof)) {
    const Run off = RunOne(c, k, s, false), on = RunOne(c, k, s, true);
    for (size_t i = 0; i < std::min(off.steady_force.size(), on.steady_force.size()); ++i) {
      const double d = on.steady_force[i] - off.steady_force[i];
      e2 += d * d;
      f2 += off.steady_force[i] * off.steady_force[i];
    }
    dissipated += on.dissipated;
    work += on.work_in;
  }
  *rms_error = f2 > 0 ? std::sqrt(e2 / f2) : 0;
  *dissipated_fraction = work > 0 ? dissipated / work : 0;
}

// The lowest windowed port energy over every script at k (the controller's passivity, off and on).
double MinWindow(const Config& c, double k, bool controller) {
  double lowest = 0;
  for (HandScript s : ScriptsFor(c.dof)) lowest = std::min(lowest, RunOne(c, k, s, controller).min_window);
  return lowest;
}

}  // namespace
}  // namespace idms

using namespace idms;

int main(int argc, char** argv) {
  bool quick = false, json = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--quick")) {
      quick = true;
    } else if (!std::strcmp(argv[i], "--json")) {
      json = true;
    } else if (!std::strcmp(argv[i], "--probe") && i + 1 < argc) {
      // --probe K: each script's verdict at one stiffness, off and on (hex, 1 kHz, 3-DOF, b 0.02).
      // IDMS_ZW_TISSUE_K: the elements' and home elements' k (default the thesis's 15).
      const char* tk = std::getenv("IDMS_ZW_TISSUE_K");
      const double tissue_k = tk != nullptr ? std::atof(tk) : 15;
      const Model hex = GenerateSlab(SlabOptions{.k = tissue_k, .home_k = tissue_k});
      Config c;
      c.model = &hex;
      const double k = std::atof(argv[++i]);
      for (HandScript s : ScriptsFor(3)) {
        for (bool on : {false, true}) {
          const Run r = RunOne(c, k, s, on);
          std::printf("k %g %-6s %-3s band %.4g mean %.4g %s dissipated %.4g of %.4g, min W %.3g\n", k,
                      HandScriptName(s), on ? "on" : "off", r.band_rms, r.mean_force, Stable(r) ? "stable" : "UNSTABLE",
                      r.dissipated, r.work_in, r.min_window);
        }
      }
      return 0;
    } else {
      std::fprintf(stderr, "usage: %s [--quick] [--json]\n", argv[0]);
      return 1;
    }
  }
  // The hex fragment (thesis 6.1: elements k 15), the same fragment a hundred times stiffer (a
  // tissue whose port stiffness follows the MIO's: what makes a sampled-data port active), and a
  // 20 x 20 slab of the thesis's tissue.
  const Model hex = GenerateSlab(SlabOptions{});
  const Model stiff = GenerateSlab(SlabOptions{.k = 1500, .home_k = 1500, .name = "hex_stiff"});
  const Model slab = quick ? Model{} : GenerateSlab(SlabOptions{.rows = 20, .cols = 20, .name = "slab"});
  struct Named {
    const Model* model;
    const char* name;
  };
  std::vector<Named> models = {{&hex, "hex"}, {&stiff, "hex_k1500"}};
  if (!quick) models.push_back({&slab, "slab20"});
  const std::vector<double> dampings = quick ? std::vector<double>{0.005} : std::vector<double>{0.005, 0.02};
  const double ratio = quick ? 2.0 : 1.5;
  const int bisections = quick ? 2 : 4;
  const double hand_damping = Config{}.hand_damping;
  if (!json) {
    std::printf(
        "Z-width of the MIO contact (thesis law, sphere r 1.5), device m 0.002 + hand m 0.005, k_h 10, c_h %g, "
        "encoder 2.5e-4, force clamp 10; controller window 0.1 s, damping cap m_device / T\n",
        hand_damping);
    std::printf("%-9s %-5s %-3s %-6s %-9s %-9s %-9s %-6s %-9s %-9s %-9s %-9s %-9s\n", "model", "rate", "dof", "b_dev",
                "2(b+c)/T", "k_max_off", "k_max_on", "ratio", "rms_err", "dissip", "at k", "minW400", "minW400on");
  }
  for (const Named& m : models) {
    for (double rate : {1000.0, 700.0}) {
      for (int dof : {1, 3}) {
        for (double b : dampings) {
          Config c;
          c.rate_hz = rate, c.dof = dof, c.model = m.model, c.model_name = m.name, c.device_damping = b;
          const Scan off = FindKMax(c, false, 25, 1e5, ratio, bisections);
          const Scan on = FindKMax(c, true, std::max(25.0, off.k_max), 1e5, ratio, bisections);
          double rms = 0, frac = 0;
          if (off.k_max > 0) Transparency(c, off.k_max, &rms, &frac);
          const double colgate = 2 * (b + hand_damping) * rate;
          const double w_off = MinWindow(c, 400, false), w_on = MinWindow(c, 400, true);
          if (json) {
            std::printf(
                "{\"model\":\"%s\",\"rate_hz\":%g,\"dof\":%d,\"device_damping\":%g,\"colgate_bound\":%g,"
                "\"k_max_off\":%.4g,\"k_max_off_capped\":%s,\"k_max_on\":%.4g,\"k_max_on_capped\":%s,"
                "\"rms_force_error\":%.4g,\"dissipated_fraction\":%.4g,\"transparency_at_k\":%.4g,"
                "\"min_window_energy_k400_off\":%.4g,\"min_window_energy_k400_on\":%.4g}\n",
                m.name, rate, dof, b, colgate, off.k_max, off.capped ? "true" : "false", on.k_max,
                on.capped ? "true" : "false", rms, frac, off.k_max, w_off, w_on);
          } else {
            std::printf("%-9s %-5.0f %-3d %-6g %-9.4g %-9.4g %-9.4g %-6.2f %-9.4g %-9.4g %-9.4g %-9.3g %-9.3g%s\n",
                        m.name, rate, dof, b, colgate, off.k_max, on.k_max, off.k_max > 0 ? on.k_max / off.k_max : 0.0,
                        rms, frac, off.k_max, w_off, w_on, on.capped ? "  (on: stable to the scan's end)" : "");
          }
          std::fflush(stdout);
        }
      }
    }
  }
  return 0;
}
