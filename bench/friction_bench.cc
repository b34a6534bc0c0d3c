// Friction with stiction (issue 30), measured: creep under a held sideways load, the tangential
// force in steady sliding against mu_d f_n, stick/slip transitions, friction's work over every
// shipped script, the cost of a tick with friction against without, the friction force's error
// against a fine-step reference, and the thesis's slow stroke at several mu (fig. 6-5's f_x sign
// change). Prints figures; never fails on time. Run it under `flock /tmp/idms-bench.lock`.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "idms/sim/drag.h"
#include "idms/sim/generate.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"

namespace {

using namespace idms;

ToolCommand Finger(double mu_s, double mu_d) {
  ToolCommand c;
  c.kind = ToolKind::kSphere;
  c.mu_s = mu_s;
  c.mu_d = mu_d;
  return c;
}

double Norm(const double* v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

struct DragFigures {
  double fn = 0;                            // the drag's f_n
  double tool_creep = 0, anchor_creep = 0;  // over the script's last 10 s
  double worst_slip_ratio = 0;              // max |f_t / (mu_d f_n) - 1| over slip ticks with f_n > f_n0 / 2
  int64_t slip_ticks = 0, transitions = 0, min_transition_gap = 1 << 30;
  std::vector<double> ft;  // |f_t| per tick
  double warnings = 0;
};

DragFigures Drag(const Model& model, ToolCommand tool, double fraction, double dt, double b_t = -1) {
  StepOptions options;
  options.dt_s = dt;
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, options);
  DragOptions drag;
  drag.fraction = fraction;
  drag.mu_s = tool.mu_s;
  DragHand hand(MakeScriptGeometry(model, tool.radius), drag);
  tool.friction_damping = b_t;
  ToolInput input;
  input.num_tools = 1;
  double force[3] = {0, 0, 0};
  const auto ticks = static_cast<int64_t>(std::llround(hand.Duration() / dt));
  const auto creep_from = static_cast<int64_t>(std::llround((hand.Duration() - 10.0) / dt));
  DragFigures out;
  double x0 = 0, a0[3] = {0, 0, 0};
  FrictionState last = FrictionState::kNone;
  int64_t last_transition = -(1 << 30);
  for (int64_t n = 0; n < ticks; ++n) {
    const ScriptSample sample = hand.Next((n + 1) * dt, force);
    std::copy(sample.pos, sample.pos + 3, tool.pos);
    input.tools[0] = tool;
    const StepReport r = Step(model, state, ws, input);
    const ToolReport& tr = r.tools[0];
    std::copy(tr.force, tr.force + 3, force);
    double anchor[3] = {0, 0, 0};
    const ToolState& ts = state.tools[0];
    for (int i = 0; i < kAnchorAtoms && ts.anchor_atoms[i] >= 0; ++i) {
      for (int c = 0; c < 3; ++c) anchor[c] += ts.anchor_w[i] * state.atom_pos[3 * ts.anchor_atoms[i] + c];
    }
    if (n == creep_from) x0 = hand.hand_x(), std::copy(anchor, anchor + 3, a0);
    if (n > creep_from) {
      out.tool_creep = std::max(out.tool_creep, std::fabs(hand.hand_x() - x0));
      double d[3] = {anchor[0] - a0[0], anchor[1] - a0[1], anchor[2] - a0[2]};
      out.anchor_creep = std::max(out.anchor_creep, Norm(d));
    }
    const double ft = Norm(tr.friction_force);
    out.ft.push_back(ft);
    if (tr.friction == FrictionState::kSlip) {
      ++out.slip_ticks;
      // Steady sliding: a tick that slipped throughout (its limit was mu_d from its start; the tick
      // that breaks away is bounded by mu_s f_n).
      if (last == FrictionState::kSlip && tr.normal_force > 0.5 * hand.normal_force()) {
        out.worst_slip_ratio = std::max(out.worst_slip_ratio, std::fabs(ft / (tool.mu_d * tr.normal_force) - 1));
      }
    }
    if (tr.friction != last && tr.friction != FrictionState::kNone && last != FrictionState::kNone) {
      ++out.transitions;
      out.min_transition_gap = std::min(out.min_transition_gap, n - last_transition);
      last_transition = n;
    }
    last = tr.friction;
  }
  out.fn = hand.normal_force();
  out.warnings = static_cast<double>(TotalWarnings(state.warnings));
  return out;
}

struct TickFigures {
  double p50 = 0, p99 = 0;
  double max_running_work = 0, work = 0;
  int64_t stick = 0, slip = 0, warnings = 0;
  double mean_fx_accel = 0, mean_fx_decel = 0, mean_fx_after = 0;  // after: 0.2 s after the crossing
  std::vector<double> fx;
};

// A shipped script; tick times from StepReport (steady clock), friction's running work.
TickFigures RunScript(const Model& model, Script script, ToolCommand tool, StepOptions options) {
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, options);
  ResyncWorkspace(model, state, ws);
  const ScriptGeometry g = MakeScriptGeometry(model, tool.radius);
  if (script == Script::kPluck) tool.kind = ToolKind::kTweezers;
  ToolInput input;
  input.num_tools = 1;
  const auto ticks = static_cast<int64_t>(std::llround(ScriptDuration(script) / options.dt_s));
  std::vector<double> us;
  us.reserve(ticks);
  TickFigures out;
  const auto crossings = StrokeCrossings(script);
  int64_t n_accel = 0, n_decel = 0, n_after = 0;
  for (int64_t n = 0; n < ticks; ++n) {
    const double t = (n + 1) * options.dt_s;
    const ScriptSample s = SampleScript(script, g, t);
    std::copy(s.pos, s.pos + 3, tool.pos);
    tool.closed = s.closed;
    input.tools[0] = tool;
    const StepReport r = Step(model, state, ws, input);
    us.push_back(1e-3 * static_cast<double>(r.total_ns));
    const ToolReport& tr = r.tools[0];
    out.work += tr.friction_work;
    out.max_running_work = std::max(out.max_running_work, out.work);
    out.stick += tr.friction == FrictionState::kStick;
    out.slip += tr.friction == FrictionState::kSlip;
    out.fx.push_back(tr.force[0]);
    if (!crossings.empty() && t > crossings[0][0] && t <= crossings[0][1]) {
      if (t < 0.5 * (crossings[0][0] + crossings[0][1])) {
        out.mean_fx_accel += tr.force[0], ++n_accel;
      } else {
        out.mean_fx_decel += tr.force[0], ++n_decel;
      }
    }
    if (!crossings.empty() && t > crossings[0][1] && t <= crossings[0][1] + 0.2)
      out.mean_fx_after += tr.force[0], ++n_after;
  }
  if (n_accel) out.mean_fx_accel /= static_cast<double>(n_accel);
  if (n_decel) out.mean_fx_decel /= static_cast<double>(n_decel);
  if (n_after) out.mean_fx_after /= static_cast<double>(n_after);
  std::sort(us.begin(), us.end());
  out.p50 = us[us.size() / 2];
  out.p99 = us[std::min(us.size() - 1, static_cast<size_t>(0.99 * static_cast<double>(us.size())))];
  out.warnings = TotalWarnings(state.warnings);
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--quick")) {
      quick = true;
    } else {
      std::fprintf(stderr, "usage: %s [--quick]\n", argv[0]);
      return 2;
    }
  }
  const Model hex = GenerateSlab(SlabOptions{});
  const Model slab4 = GenerateSlab(SlabOptions{.rows = 58, .cols = 58});
  const ToolCommand finger = Finger(0.6, 0.4);

  std::printf("Friction with stiction (mu_s 0.6, mu_d 0.4, k_t = k = 400, b_t = k_t dt), symplectic Euler, 1 kHz\n");
  std::printf("\nCreep: drag at 0.5 mu_s f_n, largest displacement over the script's last 10 s\n");
  std::printf("%-18s %8s %8s | %12s %12s | %5s\n", "model", "atoms", "f_n", "tool", "anchor", "warn");
  for (const auto& [name, model] : {std::pair<const char*, const Model*>{"hex fragment", &hex},
                                    std::pair<const char*, const Model*>{"slab 10^4", &slab4}}) {
    if (quick && model == &slab4) continue;
    const DragFigures d = Drag(*model, finger, 0.5, 1e-3);
    std::printf("%-18s %8d %8.4f | %12.3g %12.3g | %5.0f\n", name, model->num_atoms, d.fn, d.tool_creep, d.anchor_creep,
                d.warnings);
  }

  std::printf(
      "\nSlip: drag at 1.3 mu_s f_n; |f_t / (mu_d f_n) - 1| over ticks slipping from their start with f_n > f_n0 / "
      "2\n");
  std::printf("%-18s %10s %12s %12s %16s\n", "model", "slip ticks", "worst ratio", "transitions", "min gap (ticks)");
  for (const auto& [name, model] : {std::pair<const char*, const Model*>{"hex fragment", &hex},
                                    std::pair<const char*, const Model*>{"slab 10^4", &slab4}}) {
    if (quick && model == &slab4) continue;
    const DragFigures d = Drag(*model, finger, 1.3, 1e-3);
    std::printf("%-18s %10lld %12.3g %12lld %16lld\n", name, static_cast<long long>(d.slip_ticks), d.worst_slip_ratio,
                static_cast<long long>(d.transitions),
                static_cast<long long>(d.transitions > 1 ? d.min_transition_gap : -1));
  }

  std::printf("\nFriction's work (work on atoms and device + its spring's energy change), hex fragment\n");
  std::printf("%-14s %-5s %14s %12s %7s %7s %5s\n", "script", "check", "max run. sum", "total", "stick", "slip",
              "warn");
  for (bool check : {true, false}) {
    StepOptions o;
    o.stability.energy_check = check;
    for (Script s :
         {Script::kPalpate, Script::kStrokeSlow, Script::kStrokeFast, Script::kStrokeGentle, Script::kPluck}) {
      const TickFigures f = RunScript(hex, s, finger, o);
      std::printf("%-14s %-5s %14.3g %12.4g %7lld %7lld %5lld\n", ScriptName(s), check ? "on" : "off",
                  f.max_running_work, f.work, static_cast<long long>(f.stick), static_cast<long long>(f.slip),
                  static_cast<long long>(f.warnings));
    }
  }

  std::printf("\nCost: tick p50 / p99 (us, StepReport total), friction off and on, best of 3 runs by p50\n");
  std::printf("%-18s %-13s %9s %9s | %9s %9s\n", "model", "script", "off p50", "off p99", "on p50", "on p99");
  const Model slab5 = quick ? Model{} : GenerateSlab(SlabOptions{.rows = 183, .cols = 183});
  for (const auto& [name, model] : {std::pair<const char*, const Model*>{"hex fragment", &hex},
                                    std::pair<const char*, const Model*>{"slab 10^5", &slab5}}) {
    if (model->num_atoms == 0) continue;
    for (Script s : {Script::kPalpate, Script::kStrokeSlow}) {
      TickFigures best[2];
      for (int on = 0; on < 2; ++on) {
        for (int k = 0; k < 3; ++k) {
          const TickFigures f = RunScript(*model, s, on ? finger : Finger(0, 0), {});
          if (k == 0 || f.p50 < best[on].p50) best[on] = f;
        }
      }
      std::printf("%-18s %-13s %9.2f %9.2f | %9.2f %9.2f\n", name, ScriptName(s), best[0].p50, best[0].p99, best[1].p50,
                  best[1].p99);
    }
  }

  std::printf(
      "\nError against a fine-step reference: |f_t| of the drag at 1.3 mu_s f_n, hex fragment;\n"
      "RMS and max over the script against dt = 0.1 ms (sampled at the coarse ticks), b_t = 0.4 throughout\n");
  const DragFigures ref = Drag(hex, finger, 1.3, 1e-4, 0.4);
  std::printf("%10s %12s %12s %12s\n", "dt (s)", "RMS (N)", "max (N)", "slip ticks");
  for (double dt : {1e-3, 5e-4, 2e-4}) {
    const DragFigures d = Drag(hex, finger, 1.3, dt, 0.4);
    const auto stride = static_cast<size_t>(std::llround(dt / 1e-4));
    double sum2 = 0, worst = 0;
    size_t n = 0;
    for (size_t i = 0; i < d.ft.size() && (i + 1) * stride - 1 < ref.ft.size(); ++i, ++n) {
      const double e = d.ft[i] - ref.ft[(i + 1) * stride - 1];
      sum2 += e * e, worst = std::max(worst, std::fabs(e));
    }
    std::printf("%10.2g %12.4g %12.4g %12lld\n", dt, std::sqrt(sum2 / static_cast<double>(n)), worst,
                static_cast<long long>(d.slip_ticks));
  }

  std::printf(
      "\nThe thesis's slow stroke (fig. 6-5), thesis preset (explicit Euler, r_l 2.25): mean f_x over the\n"
      "crossing's accelerating and decelerating halves and over the 0.2 s after it (held), by mu (mu_d = mu_s);\n"
      "the thesis's f_x changes sign when the hand decelerates\n");
  std::fflush(stdout);
  std::printf("%6s %12s %12s %14s %7s %7s\n", "mu", "f_x accel", "f_x decel", "f_x next 0.2s", "stick", "slip");
  StepOptions thesis;
  thesis.integrator = Integrator::kExplicitEuler;
  thesis.local_radius = 2.25;
  for (double mu : {0.0, 0.1, 0.2, 0.4, 0.6, 1.0, 2.0}) {
    const TickFigures f = RunScript(hex, Script::kStrokeSlow, Finger(mu, mu), thesis);
    std::printf("%6.2f %12.4f %12.4f %14.4f %7lld %7lld\n", mu, f.mean_fx_accel, f.mean_fx_decel, f.mean_fx_after,
                static_cast<long long>(f.stick), static_cast<long long>(f.slip));
  }
  return 0;
}
