// idms-sim fit: the element parameters that make a model feel like a recording (thesis 7.2.5,
// issue 34). Replays the recorded path through the real step and fits the home and surface
// elements' stiffness and damping (scale factors per group) to the recorded force.
#include <cmath>
#include <cstdio>

#include "command.h"
#include "fit.h"
#include "idms/sim/model_io.h"
#include "idms/sim/preset.h"
#include "plot.h"

namespace idms::tool {
namespace {

struct FitArgs {
  std::string model, csv, params = "home_k,surface_k", preset = "default", integrator, tool, out, plot;
  int stride = 1;
  bool json = false;
};

void RunFit(const FitArgs& a) {
  Model model;
  LoadError load_error;
  if (!LoadModel(a.model + ".fem", a.model + ".plg", {}, &model, &load_error)) Fail("fit", load_error.ToString());
  fit::Trace trace;
  std::string error;
  if (!fit::ReadTraceCsv(a.csv, &trace, &error)) Fail("fit", "--csv " + error);
  fit::FitOptions o;
  if (!fit::ParseParams(a.params, &o.params, &error)) Fail("fit", error);
  o.tool.kind = ToolKind::kSphere;
  if (!a.tool.empty() && !ParseToolSpec(a.tool, &o.tool, &error)) Fail("fit", error);
  Preset preset{};
  if (!ParsePresetName(a.preset, &preset)) Fail("fit", "--preset '" + a.preset + "': expected default or thesis");
  const PresetSettings settings = SettingsOf(preset);
  o.step.integrator = settings.integrator;
  if (!a.integrator.empty() && !ParseIntegratorName(a.integrator, &o.step.integrator)) {
    Fail("fit", "--integrator '" + a.integrator + "': expected euler, symplectic, rk4 or implicit");
  }
  o.step.local_radius = settings.local_radius_per_tool_radius * o.tool.radius;
  o.stride = a.stride;

  const fit::FitResult r = fit::Fit(model, trace, o);
  if (!r.ok) Fail("fit", r.message);
  if (!a.out.empty() && !SaveModel(r.fitted, a.out, &error)) Fail("fit", "--out " + error);
  if (!a.plot.empty()) {
    PlotSpec spec;
    spec.title = "idms-sim fit: " + a.model + " against " + a.csv;
    spec.x_label = "t (s)";
    spec.y_label = "f_z";
    spec.height_px = 500;
    PlotSeries measured{.title = "recorded", .style = "lines", .options = "lc rgb '#888888' lw 3"};
    PlotSeries fitted{.title = "fitted model", .style = "lines", .options = "lc rgb '#d62728' lw 1"};
    for (size_t i = 0; i < r.fitted_force.size(); ++i) {
      const size_t n = (i + 1) * static_cast<size_t>(o.stride) - 1;
      const double t = static_cast<double>(n + 1) * trace.dt_s;
      measured.points.push_back({t, trace.force[n][2]});
      fitted.points.push_back({t, r.fitted_force[i][2]});
    }
    spec.series = {measured, fitted};
    if (!PlotPng(spec, a.plot, &error)) Fail("fit", "--plot: " + error);
  }
  nlohmann::json j = {{"samples", r.samples},
                      {"peak_force", r.peak_force},
                      {"rms_before", r.rms_before},
                      {"rms_after", r.rms_after},
                      {"relative_rms_after", r.rms_after / r.peak_force},
                      {"iterations", r.iterations},
                      {"replays", r.replays},
                      {"seconds", r.seconds}};
  for (size_t i = 0; i < r.params.size(); ++i) {
    j["params"][fit::ParamName(r.params[i])] = {
        {"value", r.value[i]}, {"sigma", r.value_sigma[i]}, {"scale", r.scale[i]}, {"scale_sigma", r.scale_sigma[i]}};
  }
  if (a.json) {
    PrintJson(j);
    return;
  }
  std::printf("fit of %s to %s: %d samples (every %d ticks), peak force %.4g\n", a.model.c_str(), a.csv.c_str(),
              r.samples, o.stride, r.peak_force);
  for (size_t i = 0; i < r.params.size(); ++i) {
    std::printf("  %-10s %.6g +- %.2g  (x %.6g of the typed-in value)\n", fit::ParamName(r.params[i]), r.value[i],
                r.value_sigma[i], r.scale[i]);
  }
  std::printf("force RMS error %.4g -> %.4g (%.2g%% of the peak); %d iterations, %d replays, %.2f s\n", r.rms_before,
              r.rms_after, 100 * r.rms_after / r.peak_force, r.iterations, r.replays, r.seconds);
  if (!a.out.empty()) std::printf("wrote %s.fem, %s.plg\n", a.out.c_str(), a.out.c_str());
}

void Setup(CLI::App& app) {
  auto* cmd = app.add_subcommand("fit", "Fit a model's element parameters to a recorded path and force (thesis 7.2.5)");
  static FitArgs a;
  cmd->add_option("--model", a.model, "Model prefix (PREFIX.fem + PREFIX.plg): the parameters' starting point")
      ->required();
  cmd->add_option("--csv", a.csv, "The recording: a CSV as idms-sim run --csv writes it (t,x,y,z,fx,fy,fz,...)")
      ->required();
  cmd->add_option("--params", a.params,
                  "Comma-separated groups to fit: home_k, home_b, surface_k, surface_b (each a factor on the model's "
                  "values), tool_k (the MIO's contact stiffness)")
      ->capture_default_str();
  cmd->add_option("--preset", a.preset, "The step the recording was made with: default | thesis")
      ->capture_default_str();
  cmd->add_option("--integrator", a.integrator, "euler | symplectic | rk4 | implicit (default: the preset's)");
  cmd->add_option("--tool", a.tool,
                  "The recording's tool, as idms-sim run --tool takes it (default sphere r 1.5 k 400)");
  cmd->add_option("--stride", a.stride, "Compare every N-th tick")->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--out", a.out, "Write the fitted model to PREFIX.fem + PREFIX.plg");
  cmd->add_option("--plot", a.plot, "Write a PNG of the recorded and the fitted f_z over time");
  cmd->add_flag("--json", a.json, "Print the result as one JSON object");
  cmd->callback([] { RunFit(a); });
}

IDMS_SIM_COMMAND(45, Setup);

}  // namespace
}  // namespace idms::tool
