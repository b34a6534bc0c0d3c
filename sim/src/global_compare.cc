#include "idms/sim/global_compare.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include "idms/sim/check.h"
#include "idms/sim/global.h"
#include "idms/sim/preset.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"

namespace idms {

ScriptedTrace RunScripted(const Model& model, const ScriptedRunOptions& o) {
  ToolCommand tool;
  tool.kind = o.script == Script::kPluck ? ToolKind::kTweezers : ToolKind::kSphere;
  const PresetSettings settings = SettingsOf(Preset::kDefault);
  StepOptions step;
  step.integrator = settings.integrator;
  step.full = o.mode == RunMode::kFull;
  step.local_radius = settings.local_radius_per_tool_radius * tool.radius;
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, step);
  std::unique_ptr<GlobalDynamics> global;
  if (o.mode == RunMode::kTwoRate) {
    global = std::make_unique<GlobalDynamics>(model, s, step,
                                              GlobalOptions{.rate_hz = o.global_rate_hz, .phase = o.global_phase});
  }
  const ScriptGeometry geometry = MakeScriptGeometry(model, tool.radius);
  const int64_t script_ticks = std::llround(ScriptDuration(o.script) / step.dt_s);
  const int64_t ticks = o.max_ticks >= 0 ? std::min(o.max_ticks, script_ticks) : script_ticks;
  ScriptedTrace trace;
  trace.force.reserve(ticks);
  ToolInput input;
  input.num_tools = 1;
  int64_t exchanges = 0;
  for (int64_t n = 0; n < ticks; ++n) {
    const ScriptSample sample = SampleScript(o.script, geometry, (n + 1) * step.dt_s);
    tool.pos[0] = sample.pos[0], tool.pos[1] = sample.pos[1], tool.pos[2] = sample.pos[2];
    tool.closed = sample.closed;
    input.tools[0] = tool;
    const StepReport r = Step(model, s, ws, input);
    trace.force.push_back({r.tools[0].force[0], r.tools[0].force[1], r.tools[0].force[2]});
    if (global) {
      global->AfterTick(s, ws);
      if (global->stats().exchanges != exchanges)
        exchanges = global->stats().exchanges, trace.update_ticks.push_back(n + 1);
    }
    if ((n + 1) % o.sample_every == 0) {
      for (const int32_t a : model.external_atoms) {
        for (int c = 0; c < 3; ++c) trace.surface.push_back(s.atom_pos[3 * a + c]);
      }
    }
  }
  if (global && global->stats().reachable_hz > 0) trace.global_step_ms = 1e3 / global->stats().reachable_hz;
  return trace;
}

UpdateJump CompareShifted(const ScriptedTrace& run, const ScriptedTrace& shifted) {
  IDMS_CHECK(run.force.size() == shifted.force.size());
  std::vector<uint8_t> at_update(run.force.size(), 0);
  for (const int64_t t : run.update_ticks) {
    if (t > 0 && t < static_cast<int64_t>(run.force.size())) at_update[t] = 1;
  }
  UpdateJump u;
  for (size_t i = 1; i < run.force.size(); ++i) {
    double d2 = 0;
    for (int c = 0; c < 3; ++c) {
      const double d = (run.force[i][c] - run.force[i - 1][c]) - (shifted.force[i][c] - shifted.force[i - 1][c]);
      d2 += d * d;
    }
    double& m = at_update[i] ? u.at_update_max : u.elsewhere_max;
    m = std::max(m, std::sqrt(d2));
  }
  return u;
}

TraceError CompareTraces(const ScriptedTrace& ref, const ScriptedTrace& run) {
  IDMS_CHECK(ref.force.size() == run.force.size() && ref.surface.size() == run.surface.size());
  TraceError e;
  auto norm = [](double x, double y, double z) { return std::sqrt(x * x + y * y + z * z); };
  double sum2 = 0;
  for (size_t i = 0; i < ref.force.size(); ++i) {
    const auto& f = ref.force[i];
    const auto& g = run.force[i];
    e.peak_force = std::max(e.peak_force, norm(f[0], f[1], f[2]));
    const double d = norm(g[0] - f[0], g[1] - f[1], g[2] - f[2]);
    sum2 += d * d;
    e.force_max = std::max(e.force_max, d);
  }
  e.force_rms = ref.force.empty() ? 0 : std::sqrt(sum2 / static_cast<double>(ref.force.size()));
  sum2 = 0;
  for (size_t i = 0; i + 2 < ref.surface.size(); i += 3) {
    const double d = norm(run.surface[i] - ref.surface[i], run.surface[i + 1] - ref.surface[i + 1],
                          run.surface[i + 2] - ref.surface[i + 2]);
    sum2 += d * d;
    e.surface_max = std::max(e.surface_max, d);
  }
  e.surface_rms = ref.surface.empty() ? 0 : std::sqrt(sum2 / static_cast<double>(ref.surface.size() / 3));
  // The tick after an update (index = update tick: the force of the next tick).
  std::vector<uint8_t> at_update(run.force.size(), 0);
  for (const int64_t t : run.update_ticks) {
    if (t > 0 && t < static_cast<int64_t>(run.force.size())) at_update[t] = 1;
  }
  for (size_t i = 1; i < run.force.size(); ++i) {
    // The change beyond the reference's own (a stroke's contacts change the force abruptly in both).
    double d[3];
    for (int c = 0; c < 3; ++c)
      d[c] = (run.force[i][c] - run.force[i - 1][c]) - (ref.force[i][c] - ref.force[i - 1][c]);
    const double jump = norm(d[0], d[1], d[2]);
    if (at_update[i]) {
      e.jump_at_update_max = std::max(e.jump_at_update_max, jump);
      e.jumps_at_update.push_back(jump);
    } else {
      e.jump_elsewhere_max = std::max(e.jump_elsewhere_max, jump);
    }
  }
  return e;
}

}  // namespace idms
