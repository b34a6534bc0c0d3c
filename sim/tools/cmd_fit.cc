// idms-sim fit: the element parameters that make a model feel like a recording (thesis 7.2.5,
// issue 34). Replays the recorded path through the real step and fits the home and surface
// elements' stiffness and damping (scale factors per group, globally or per region) to the
// recorded force; with --map, the stiffness map of a scan and the lump in it.
#include <cmath>
#include <cstdio>

#include "command.h"
#include "fit.h"
#include "fit_json.h"
#include "idms/sim/model_io.h"
#include "idms/sim/preset.h"
#include "plot.h"
#if defined(IDMS_SIM_RECORDINGS)
#include "fit_recording.h"
#endif

namespace idms::tool {
namespace {

struct FitArgs {
  std::string model, csv, recording, params = "home_k,surface_k", preset = "default", integrator, tool, out, plot;
  std::vector<std::string> regions;
  int stride = 1;
  bool json = false, map = false;
  const std::string& source() const { return recording.empty() ? csv : recording; }
};

// PREFIX.map.csv: a row per press (times in seconds).
void WriteMapCsv(const std::string& path, const fit::MapResult& r, double dt_s) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) Fail("fit", "--out " + path + ": cannot write");
  std::fprintf(f, "x,y,scale,sigma,peak_force,t0,t1\n");
  for (const fit::MapPoint& p : r.points) {
    std::fprintf(f, "%.6g,%.6g,%.6g,%.3g,%.6g,%.4f,%.4f\n", p.x, p.y, p.scale, p.sigma, p.peak_force,
                 static_cast<double>(p.tick0) * dt_s, static_cast<double>(p.tick1) * dt_s);
  }
  if (std::fclose(f) != 0) Fail("fit", "--out " + path + ": write failed");
}

// The map's PNG: the presses (read back from the CSV) coloured by their factor, and the fitted
// lump's centre and radius.
void PlotMap(const FitArgs& a, const std::string& csv, const fit::MapResult& r) {
  PlotSpec spec;
  spec.title = "idms-sim fit --map: " + a.model + " from " + a.source();
  spec.x_label = "x";
  spec.y_label = "y";
  spec.color_label = "stiffness factor";
  spec.equal_aspect = true;
  spec.key = "off";
  PlotSeries presses{.title = "", .style = "points", .options = "pt 5 ps 4"};
  presses.csv_path = csv;
  presses.x_column = "x", presses.y_column = "y", presses.color_column = "scale";
  spec.series = {presses};
  if (r.lump.found) {
    PlotSeries centre{.title = "", .style = "points", .options = "pt 2 ps 3 lw 2 lc rgb 'black'"};
    centre.points = {{r.lump.x, r.lump.y}};
    spec.series.push_back(centre);
    char circle[160];
    std::snprintf(circle, sizeof(circle), "set object 1 circle at %g,%g size %g fs empty border lc rgb 'black' lw 2",
                  r.lump.x, r.lump.y, r.lump.radius);
    spec.preamble.push_back(circle);
  }
  std::string error;
  if (!PlotPng(spec, a.plot, &error)) Fail("fit", "--plot: " + error);
}

// The scan's stiffness map: a table (or JSON), PREFIX.map.csv, and a PNG of the presses coloured
// by their factor.
void RunMap(const FitArgs& a, const Model& model, const fit::Trace& trace, const fit::FitOptions& o) {
  if (!a.plot.empty() && a.out.empty()) Fail("fit", "--map --plot needs --out (the plot reads PREFIX.map.csv)");
  const fit::MapResult r = fit::FitMap(model, trace, o);
  if (!r.ok) Fail("fit", "--map: " + r.message);
  if (!a.out.empty()) WriteMapCsv(a.out + ".map.csv", r, trace.dt_s);
  if (!a.plot.empty()) PlotMap(a, a.out + ".map.csv", r);
  if (a.json) {
    PrintJson(fit::MapJson(r));
    return;
  }
  std::printf("stiffness map of %s from %s: %zu presses, background factor %.4g (scatter %.2g)\n", a.model.c_str(),
              a.source().c_str(), r.points.size(), r.background, r.spread);
  std::printf("  %10s %10s %10s %10s %10s\n", "x", "y", "factor", "sigma", "peak f");
  for (const fit::MapPoint& p : r.points) {
    std::printf("  %10.4g %10.4g %10.4g %10.2g %10.4g\n", p.x, p.y, p.scale, p.sigma, p.peak_force);
  }
  if (r.lump.found) {
    std::printf(
        "lump at x %.4g, y %.4g (+- %.2g), radius %.3g: %.3g +- %.2g times the background's stiffness (%d presses "
        "above half)\n",
        r.lump.x, r.lump.y, r.lump.xy_sigma, r.lump.radius, r.lump.ratio, r.lump.ratio_sigma, r.lump.presses);
  } else {
    std::printf("no lump: no press stands out of the background by more than 25%% and 5 times the scatter\n");
  }
  std::printf("%d replays, %.2f s\n", r.replays, r.seconds);
  if (!a.out.empty()) std::printf("wrote %s.map.csv\n", a.out.c_str());
}

// The recording as a trace, and the step and tool it was made with: from the CSV and the options,
// or from a session recording and its scene.
void ReadSource(const FitArgs& a, const Model& model, fit::Trace* trace, fit::FitOptions* o) {
  std::string error;
  if (a.csv.empty() == a.recording.empty())
    Fail("fit", "give the recording as one of --csv FILE or --recording FILE.mcap");
  if (!a.recording.empty()) {
#if defined(IDMS_SIM_RECORDINGS)
    if (!a.tool.empty() || !a.integrator.empty() || a.preset != "default") {
      Fail("fit", "--recording: the session's scene gives the tool and the step; drop --tool, --preset, --integrator");
    }
    if (!ReadRecordingTrace(a.recording, model, trace, &o->step, &o->tool, &error)) Fail("fit", "--recording " + error);
    return;
#else
    Fail("fit", "--recording: this idms-sim was built without the protocol (a CSV from idms-sim run works)");
#endif
  }
  if (!fit::ReadTraceCsv(a.csv, trace, &error)) Fail("fit", "--csv " + error);
  // A run with a closed column was the tweezers' (idms-sim run --script pluck).
  const bool tweezers = !trace->closed.empty();
  o->tool.kind = tweezers ? ToolKind::kTweezers : ToolKind::kSphere;
  if (!a.tool.empty() && !ParseToolSpec(a.tool, &o->tool, &error)) Fail("fit", error);
  if (tweezers != (o->tool.kind == ToolKind::kTweezers)) {
    Fail("fit", tweezers ? "--csv has the tweezers' closed column: give --tool tweezers:... (or none)"
                         : "--tool tweezers: the CSV has no closed column (idms-sim run writes it for the tweezers)");
  }
  Preset preset{};
  if (!ParsePresetName(a.preset, &preset)) Fail("fit", "--preset '" + a.preset + "': expected default or thesis");
  const PresetSettings settings = SettingsOf(preset);
  o->step.integrator = settings.integrator;
  if (!a.integrator.empty() && !ParseIntegratorName(a.integrator, &o->step.integrator)) {
    Fail("fit", "--integrator '" + a.integrator + "': expected euler, symplectic, rk4 or implicit");
  }
  o->step.local_radius = settings.local_radius_per_tool_radius * o->tool.radius;
}

void RunFit(const FitArgs& a) {
  Model model;
  LoadError load_error;
  if (!LoadModel(a.model + ".fem", a.model + ".plg", {}, &model, &load_error)) Fail("fit", load_error.ToString());
  fit::Trace trace;
  fit::FitOptions o;
  ReadSource(a, model, &trace, &o);
  std::string error;
  if (!fit::ParseParams(a.params, &o.params, &error)) Fail("fit", error);
  for (size_t i = 0; i < a.regions.size(); ++i) {
    fit::Region region;
    if (!fit::ParseRegion(a.regions[i], static_cast<int>(i), &region, &error)) Fail("fit", error);
    for (const fit::Region& other : o.regions) {
      if (other.name == region.name)
        Fail("fit", "--region '" + a.regions[i] + "': a second region named " + other.name);
    }
    o.regions.push_back(region);
  }
  o.stride = a.stride;
  if (a.map) {
    if (!a.regions.empty()) Fail("fit", "--map fits every press on its own; it takes no --region");
    RunMap(a, model, trace, o);
    return;
  }

  const fit::FitResult r = fit::Fit(model, trace, o);
  if (!r.ok) Fail("fit", r.message);
  if (!a.out.empty() && !SaveModel(r.fitted, a.out, &error)) Fail("fit", "--out " + error);
  if (!a.plot.empty()) {
    PlotSpec spec;
    spec.title = "idms-sim fit: " + a.model + " against " + a.source();
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
  for (size_t i = 0; i < r.names.size(); ++i) {
    j["params"][r.names[i]] = {
        {"value", r.value[i]}, {"sigma", r.value_sigma[i]}, {"scale", r.scale[i]}, {"scale_sigma", r.scale_sigma[i]}};
  }
  if (a.json) {
    PrintJson(j);
    return;
  }
  std::printf("fit of %s to %s: %d samples (every %d ticks), peak force %.4g\n", a.model.c_str(), a.source().c_str(),
              r.samples, o.stride, r.peak_force);
  for (const fit::Region& g : o.regions) {
    if (g.shape == fit::Region::Shape::kSphere) {
      std::printf("  region %s: sphere at %g,%g,%g, r %g\n", g.name.c_str(), g.v[0], g.v[1], g.v[2], g.v[3]);
    } else {
      std::printf("  region %s: box %g,%g,%g to %g,%g,%g\n", g.name.c_str(), g.v[0], g.v[1], g.v[2], g.v[3], g.v[4],
                  g.v[5]);
    }
  }
  for (size_t i = 0; i < r.names.size(); ++i) {
    std::printf("  %-14s %.6g +- %.2g  (x %.6g of the typed-in value)\n", r.names[i].c_str(), r.value[i],
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
  cmd->add_option("--csv", a.csv, "The recording: a CSV as idms-sim run --csv writes it (t,x,y,z,fx,fy,fz,...)");
  cmd->add_option("--recording", a.recording,
                  "The recording: a session's MCAP from idms-server (its /device ticks; the tool and the step "
                  "from its scene)");
  cmd->add_option("--params", a.params,
                  "Comma-separated groups to fit: home_k, home_b, surface_k, surface_b, k, b (every element's) "
                  "(each a factor on the model's values), tool_k (the MIO's contact stiffness)")
      ->capture_default_str();
  cmd->add_option("--region", a.regions,
                  "[NAME=]sphere:cx,cy,cz,r or [NAME=]box:x0,y0,z0,x1,y1,z1 (repeatable): fit each element "
                  "parameter inside every region (elements by midpoint) and outside them all (NAME@rest)");
  cmd->add_flag("--map", a.map,
                "A scan's stiffness map: fit k on every press of the recording on its own and look for a lump "
                "(--out PREFIX writes PREFIX.map.csv)");
  cmd->add_option("--preset", a.preset, "The step the recording was made with: default | thesis")
      ->capture_default_str();
  cmd->add_option("--integrator", a.integrator, "euler | symplectic | rk4 | implicit (default: the preset's)");
  cmd->add_option("--tool", a.tool,
                  "The recording's tool, as idms-sim run --tool takes it (default sphere r 1.5 k 400)");
  cmd->add_option("--stride", a.stride, "Compare every N-th tick")->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--out", a.out, "Write the fitted model to PREFIX.fem + PREFIX.plg (--map: PREFIX.map.csv)");
  cmd->add_option("--plot", a.plot,
                  "Write a PNG of the recorded and the fitted f_z over time (--map: the presses coloured by factor)");
  cmd->add_flag("--json", a.json, "Print the result as one JSON object");
  cmd->callback([] { RunFit(a); });
}

IDMS_SIM_COMMAND(45, Setup);

}  // namespace
}  // namespace idms::tool
