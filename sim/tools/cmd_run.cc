// idms-sim run: an offline scripted interaction (thesis chapter 6) on a model, a CSV row per
// tick, an optional force/position plot and a JSON summary.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <memory>
#include <sstream>
#include <thread>

#include "command.h"
#include "idms/sim/drag.h"
#include "idms/sim/edit.h"
#include "idms/sim/global.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/model_io.h"
#include "idms/sim/preset.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "plot.h"

namespace idms::tool {
namespace {

struct RunArgs {
  std::string model, script = "palpate", preset = "default", integrator, tool, csv, plot, fit_plot;
  double dt = 1e-3, local_radius = 0, lambda = 1.0;  // integrator, local_radius: the preset's unless given
  std::vector<double> plot_window;                   // --plot-window T0,T1: the plot's time axis
  int64_t max_ticks = -1;                            // -1 = the whole script
  bool full = false, json = false;
  int threads = 1;
  int scan_grid = kScanGrid;   // --scan-grid: the scan's points per side
  double global_rate = 0;      // --global-rate: the whole model at this rate beside the local pass
  bool global_thread = false;  // --global-thread: on a thread of its own
  bool friction = false;       // the tool has friction (set by Run): the plot draws f_t and f_n
};

// Figures of merit of one crossing of a stroke (thesis 6.1.2): the forces while the MIO moves
// across the surface pressed in, the first half accelerating and the second decelerating.
struct Crossing {
  double t0 = 0, t1 = 0;
  double max_abs_fx = 0, max_abs_fy = 0, min_fz = INFINITY, max_fz = -INFINITY;
  double sum_fz = 0, sum_fz2 = 0, sum_fx_accel = 0, sum_fx_decel = 0;
  int64_t n = 0, n_accel = 0, n_decel = 0;

  void Add(double t, const double* f) {
    max_abs_fx = std::max(max_abs_fx, std::abs(f[0]));
    max_abs_fy = std::max(max_abs_fy, std::abs(f[1]));
    min_fz = std::min(min_fz, f[2]), max_fz = std::max(max_fz, f[2]);
    sum_fz += f[2], sum_fz2 += f[2] * f[2], ++n;
    if (t < 0.5 * (t0 + t1)) {
      sum_fx_accel += f[0], ++n_accel;
    } else {
      sum_fx_decel += f[0], ++n_decel;
    }
  }
  nlohmann::json Json() const {
    const double mean = n ? sum_fz / static_cast<double>(n) : 0;
    const double var = n ? std::max(0.0, sum_fz2 / static_cast<double>(n) - mean * mean) : 0;
    return {{"t", {t0, t1}},
            {"max_abs_fx", max_abs_fx},
            {"max_abs_fy", max_abs_fy},
            {"mean_fz", mean},
            {"sd_fz", std::sqrt(var)},
            {"fz_range", {n ? min_fz + 0.0 : 0, n ? max_fz : 0}},  // + 0.0: no "-0"
            {"mean_fx_accelerating", n_accel ? sum_fx_accel / static_cast<double>(n_accel) : 0},
            {"mean_fx_decelerating", n_decel ? sum_fx_decel / static_cast<double>(n_decel) : 0}};
  }
};

// CPU time of this thread, s: what a tick cost, whatever else the machine runs (the benches'
// clock, docs/performance.md).
double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

// The thesis's figures 6-2 to 6-8: position (top) and force (bottom) histories.
void Plot(const RunArgs& a, const std::string& title) {
  PlotSpec spec;
  spec.title = title;
  spec.x_label = "t (s)";
  spec.y_label = "MIO position (model units) / force (N)";
  spec.width_px = 1000, spec.height_px = 700;
  spec.key = "outside right";
  if (a.plot_window.size() == 2) spec.x_range = std::array<double, 2>{a.plot_window[0], a.plot_window[1]};
  std::vector<std::array<const char*, 2>> columns = {{"x", "x"},    {"y", "y"},    {"z", "z"},
                                                     {"fx", "f_x"}, {"fy", "f_y"}, {"fz", "f_z"}};
  if (a.friction) columns.push_back({"ft", "|f_t| (friction)"}), columns.push_back({"fn", "f_n"});
  for (const auto& c : columns) {
    spec.series.push_back({.title = c[1],
                           .csv_path = a.csv,
                           .x_column = "t",
                           .y_column = c[0],
                           .style = "lines",
                           .options = c[0][0] == 'f' ? "lw 2" : "dt 2"});
  }
  std::string error;
  if (!PlotPng(spec, a.plot, &error)) Fail("run", "--plot: " + error);
}

// Thesis figure 6-3: f_z against z while the MIO presses in, and its least-squares line.
struct StiffnessFit {
  double slope = 0, intercept = 0, r2 = 0;  // f_z = slope * z + intercept (slope < 0 when pressing)
  int64_t points = 0;
};

StiffnessFit FitStiffness(const std::vector<std::array<double, 2>>& zf) {
  StiffnessFit fit;
  double sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0;
  for (const auto& [z, f] : zf) sx += z, sy += f, sxx += z * z, sxy += z * f, syy += f * f;
  const double n = static_cast<double>(zf.size());
  const double den = n * sxx - sx * sx;
  if (zf.size() < 2 || den == 0) return fit;
  fit.points = static_cast<int64_t>(zf.size());
  fit.slope = (n * sxy - sx * sy) / den;
  fit.intercept = (sy - fit.slope * sx) / n;
  const double ss_tot = syy - sy * sy / n;
  double ss_res = 0;
  for (const auto& [z, f] : zf) ss_res += std::pow(f - (fit.slope * z + fit.intercept), 2);
  fit.r2 = ss_tot > 0 ? 1 - ss_res / ss_tot : 1;
  return fit;
}

void PlotFit(const RunArgs& a, const std::vector<std::array<double, 2>>& zf, const StiffnessFit& fit) {
  PlotSpec spec;
  spec.title = "Interaction stiffness normal to the surface (thesis fig. 6-3): k = " + std::to_string(-fit.slope) +
               " N/unit, R^2 = " + std::to_string(fit.r2);
  spec.x_label = "MIO z (model units)";
  spec.y_label = "f_z (N)";
  spec.key = "top right";
  spec.series.push_back({.title = "measured", .points = zf, .style = "points", .options = "pt 7 ps 0.3"});
  const double z0 = zf.front()[0], z1 = zf.back()[0];
  spec.series.push_back({.title = "least-squares fit",
                         .points = {{z0, fit.slope * z0 + fit.intercept}, {z1, fit.slope * z1 + fit.intercept}},
                         .style = "lines",
                         .options = "lw 2"});
  std::string error;
  if (!PlotPng(spec, a.fit_plot, &error)) Fail("run", "--fit-plot: " + error);
}

void Run(RunArgs& a) {
  // Model, script, tool, integrator.
  Model model;
  LoadError load_error;
  std::string fem, plg;
  ModelPaths(a.model, &fem, &plg);
  if (!LoadModel(fem, plg, {}, &model, &load_error)) Fail("run", load_error.ToString());
  Script script = Script::kPalpate;
  const bool drag = a.script == "drag" || a.script.rfind("drag:", 0) == 0;
  if (!drag && !ParseScriptName(a.script, &script)) {
    Fail("run", "--script '" + a.script +
                    "': expected palpate, stroke-slow, stroke-fast, pluck, stroke-gentle, scan, pierce, stitch, "
                    "suture or drag[:fraction=F,...]");
  }
  const bool pierce = !drag && script == Script::kPierce;
  const bool stitch = !drag && script == Script::kStitch;
  const bool suture = !drag && script == Script::kSuture;
  ToolCommand tool;
  tool.kind = !drag && script == Script::kPluck ? ToolKind::kTweezers : ToolKind::kSphere;
  if (pierce) tool = PierceNeedle();
  if (stitch) tool = StitchNeedle();
  if (suture) tool = SutureScriptNeedle();
  std::string error;
  if ((pierce || stitch || suture) && !a.tool.empty())
    Fail("run", "--tool: the " + a.script + "'s needle is the script's own (docs/needle.md)");
  if (!a.tool.empty() && !ParseToolSpec(a.tool, &tool, &error)) Fail("run", error);
  DragOptions drag_options;
  if (drag && !ParseDragSpec(a.script, &drag_options, &error)) Fail("run", "--script: " + error);
  if (drag && !(tool.mu_s > 0))
    Fail("run", "--script drag pushes at a fraction of mu_s f_n: give --tool sphere:mu_s=...");
  drag_options.mu_s = tool.mu_s;
  a.friction = tool.mu_s > 0;
  Preset preset{};
  if (!ParsePresetName(a.preset, &preset)) Fail("run", "--preset '" + a.preset + "': expected default or thesis");
  const PresetSettings settings = SettingsOf(preset);
  StepOptions options;
  options.integrator = settings.integrator;
  if (!a.integrator.empty() && !ParseIntegratorName(a.integrator, &options.integrator)) {
    Fail("run", "--integrator '" + a.integrator + "': expected euler, symplectic, rk4 or implicit");
  }
  if (!(a.dt > 0 && a.dt <= 0.1)) Fail("run", "--dt: expected 0 < dt <= 0.1 s");
  if (a.local_radius < 0 || (a.local_radius > 0 && a.local_radius < tool.radius)) {
    Fail("run", "--local-radius " + std::to_string(a.local_radius) + ": expected at least the tool's radius " +
                    std::to_string(tool.radius) + " (so that every contact atom is simulated)");
  }
  if (a.threads > 1 && !a.full && !(a.global_rate > 0))
    Fail("run", "--threads is for the whole model's pass: give --full or --global-rate");
  options.dt_s = a.dt;
  options.full = a.full;
  options.threads = a.full ? a.threads : 1;
  options.local_radius = a.local_radius > 0 ? a.local_radius
                         : suture           ? kSutureLocalRadius
                                            : settings.local_radius_per_tool_radius * tool.radius;
  options.lambda = a.lambda;

  // Step through the script, a CSV row per tick.
  State state = MakeState(model);
  Workspace workspace = MakeWorkspace(model, options);
  // Full mode streams the whole model every tick: past the caches, huge pages save page walks.
  if (options.full) AdviseHugePages(state, workspace);
  const ScriptGeometry geometry = MakeScriptGeometry(model, tool.radius, a.scan_grid);
  DragHand hand(geometry, drag_options);
  // The suture's scalpel (it incises before the needle comes), and the incision's figures: its gap
  // when the needle comes, at the end, the widest while held; stitches across it; elements cut.
  ToolCommand scalpel = IncisionScalpel();
  if (suture && geometry.num_incision_rows == 0) Fail("run", "--script suture: found no rows of top atoms to incise");
  double gap_open = NAN, gap_widest_held = 0;
  int64_t stitches = 0, cut_elements = 0;
  const double hold_from = ScriptDuration(script, geometry) - kSutureHold;
  std::unique_ptr<GlobalDynamics> global;
  if (a.global_rate > 0) {
    global = std::make_unique<GlobalDynamics>(
        model, state, options,
        GlobalOptions{.rate_hz = a.global_rate, .threaded = a.global_thread, .threads = a.threads});
  }
  const int64_t script_ticks = std::llround((drag ? hand.Duration() : ScriptDuration(script, geometry)) / a.dt);
  const int64_t ticks = a.max_ticks >= 0 ? std::min(a.max_ticks, script_ticks) : script_ticks;
  std::FILE* csv = a.csv.empty() ? nullptr : std::fopen(a.csv.c_str(), "w");
  if (!a.csv.empty() && !csv) Fail("run", "--csv " + a.csv + ": cannot write");
  // Friction's columns come after the ten of a frictionless run, so their readers keep working.
  // The tweezers' closed state last (0 or 1: what the fitter replays them with); the suture's gap.
  const bool tweezers = tool.kind == ToolKind::kTweezers;
  if (csv) {
    std::fputs(a.friction ? "t,x,y,z,fx,fy,fz,active_atoms,substeps,compute_us,ftx,fty,ftz,ft,fn,friction"
                          : "t,x,y,z,fx,fy,fz,active_atoms,substeps,compute_us",
               csv);
    std::fputs(tweezers ? ",closed" : "", csv);
    std::fputs(suture ? ",gap\n" : "\n", csv);  // the suture: its incision's gap over the stitched rows
  }
  int64_t stick_ticks = 0, slip_ticks = 0, transitions = 0;
  // The needle: punctures (entries), the first one's time, the deepest insertion, in at the end.
  int64_t punctures = 0;
  double punctured_s = NAN, max_inserted = 0;
  bool inside = false;
  // The suture: the needle through the far side, drawn through, the thread's punctures, ties,
  // refused ties and breaks; its largest tension; the largest per-tick change of the device force.
  int64_t exits = 0, draws = 0, thread_punctures = 0, ties = 0, ties_refused = 0, breaks = 0;
  bool exited = false;
  double max_tension = 0, max_force_step = 0;
  double friction_work = 0, friction_work_max_sum = 0, max_ft = 0;
  FrictionState last_friction = FrictionState::kNone;
  double last_force[3] = {0, 0, 0};
  ToolInput input;
  input.num_tools = 1;
  std::vector<double> compute_us, cpu_us;
  compute_us.reserve(ticks);
  cpu_us.reserve(ticks);
  double max_force = 0, max_fz = 0, onset_z = NAN, last_z = INFINITY;
  std::vector<std::array<double, 2>> loading;  // (z, f_z) while pressing in, in contact
  int64_t fallbacks = 0, fused_ticks = 0, substeps = 0;
  int32_t sections = 1;  // threads full mode's pass ran on
  std::vector<Crossing> crossings;
  for (const auto& [t0, t1] : StrokeCrossings(drag ? Script::kPalpate : script))
    crossings.push_back({.t0 = t0, .t1 = t1});
  const auto run_start = std::chrono::steady_clock::now();
  for (int64_t n = 0; n < ticks; ++n) {
    const ScriptSample sample =
        drag ? hand.Next((n + 1) * a.dt, last_force) : SampleScript(script, geometry, (n + 1) * a.dt);
    ToolCommand& held = sample.kind == ToolKind::kScalpel ? scalpel : tool;
    held.pos[0] = sample.pos[0], held.pos[1] = sample.pos[1], held.pos[2] = sample.pos[2];
    held.closed = sample.closed;
    if (sample.oriented) NeedleAxisOf(sample.orientation, held.axis);
    held.tie = held.kind == ToolKind::kNeedle && sample.closed;  // a needle's button ties
    if (suture && sample.kind == ToolKind::kNeedle && std::isnan(gap_open))
      gap_open = IncisionGap(geometry, state.atom_pos.data(), true);
    input.tools[0] = held;
    const auto start = std::chrono::steady_clock::now();
    const double cpu_start = a.full ? ThreadCpuSeconds() : 0.0;  // a system call: full mode only
    const StepReport report = Step(model, state, workspace, input);
    if (report.pending_cuts > 0) ApplyPendingEdits(model, state, workspace);
    if (global) global->AfterTick(state, workspace);
    const double us = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start).count();
    compute_us.push_back(us);
    // On its own thread the global pass runs at its wall-clock rate: the ticks are paced at T, as
    // a device's are, so that it can keep up (unpaced, every exchange would find it stepping).
    if (global && a.global_thread) {
      std::this_thread::sleep_until(run_start + std::chrono::duration<double>((n + 1) * a.dt));
    }
    if (a.full) cpu_us.push_back(1e6 * (ThreadCpuSeconds() - cpu_start));
    const double* f = report.tools[0].force;
    max_force_step =
        std::max(max_force_step, std::hypot(f[0] - last_force[0], f[1] - last_force[1], f[2] - last_force[2]));
    std::copy(f, f + 3, last_force);
    const ToolReport& tr = report.tools[0];
    const double ft =
        std::sqrt(tr.friction_force[0] * tr.friction_force[0] + tr.friction_force[1] * tr.friction_force[1] +
                  tr.friction_force[2] * tr.friction_force[2]);
    max_ft = std::max(max_ft, ft);
    if (tr.punctured && !inside) ++punctures, punctured_s = std::isnan(punctured_s) ? state.time_s : punctured_s;
    inside = tr.punctured;
    max_inserted = std::max(max_inserted, tr.inserted);
    exits += tr.exited && !exited;
    exited = tr.exited;
    draws += tr.drawn_through;
    thread_punctures += report.suture.new_punctures;
    ties += report.suture.tied;
    cut_elements += report.tools[0].cut_elements;
    if (suture && report.suture.tied && state.suture.num_ties > 0) {
      // A stitch: the tie's punctures lie on both sides of the incision (at rest).
      const SutureTie& tie = state.suture.ties[state.suture.num_ties - 1];
      bool side[2] = {false, false};
      for (int32_t j = tie.first; j <= tie.last; ++j) {
        const SuturePuncture& pu = state.suture.punctures[j];
        double x = 0;
        for (int i = 0; i < kAnchorAtoms && pu.atoms[i] >= 0; ++i) x += pu.w[i] * model.atom_pos_eq[3 * pu.atoms[i]];
        side[x < geometry.incision_x ? 0 : 1] = true;
      }
      stitches += side[0] && side[1];
    }
    if (suture && state.time_s >= hold_from - 1e-9)
      gap_widest_held = std::max(gap_widest_held, IncisionGap(geometry, state.atom_pos.data(), true));
    ties_refused += report.suture.tie_refused;
    breaks += report.suture.broke;
    max_tension = std::max(max_tension, report.suture.max_tension);
    stick_ticks += tr.friction == FrictionState::kStick;
    slip_ticks += tr.friction == FrictionState::kSlip;
    transitions +=
        tr.friction != last_friction && tr.friction != FrictionState::kNone && last_friction != FrictionState::kNone;
    last_friction = tr.friction;
    friction_work += tr.friction_work;
    friction_work_max_sum = std::max(friction_work_max_sum, friction_work);
    max_force = std::max(max_force, std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]));
    max_fz = std::max(max_fz, f[2]);
    if (std::isnan(onset_z) && std::abs(f[2]) > 1e-3) onset_z = held.pos[2];
    if (f[2] > 1e-3 && held.pos[2] < last_z - 1e-12) loading.push_back({held.pos[2], f[2]});
    last_z = held.pos[2];
    fallbacks += report.fallback;
    fused_ticks += report.fused;
    sections = std::max(sections, GetFusedPassStatus(workspace).sections);
    substeps += report.substeps;
    for (Crossing& c : crossings) {
      if (state.time_s > c.t0 && state.time_s <= c.t1 + 1e-9) c.Add(state.time_s, f);
    }
    if (csv) {
      std::fprintf(csv, "%.6f,%.6f,%.6f,%.6f,%.6g,%.6g,%.6g,%d,%d,%.2f", state.time_s, held.pos[0], held.pos[1],
                   held.pos[2], f[0], f[1], f[2], report.active_atoms, report.substeps, us);
      if (a.friction) {
        static constexpr const char* kState[] = {"none", "stick", "slip"};
        std::fprintf(csv, ",%.6g,%.6g,%.6g,%.6g,%.6g,%s", tr.friction_force[0], tr.friction_force[1],
                     tr.friction_force[2], ft, tr.normal_force, kState[static_cast<int>(tr.friction)]);
      }
      if (tweezers) std::fprintf(csv, ",%d", tool.closed ? 1 : 0);
      if (suture) std::fprintf(csv, ",%.6g", IncisionGap(geometry, state.atom_pos.data(), true));
      std::fputc('\n', csv);
    }
  }
  if (csv) std::fclose(csv);
  if (!a.plot.empty()) {
    if (a.csv.empty()) Fail("run", "--plot needs --csv (the plot is drawn from it)");
    Plot(a, model.name + ": " + a.script + " (" + IntegratorName(options.integrator) + ", dt " + std::to_string(a.dt) +
                " s)");
  }

  // Summary.
  const StiffnessFit fit = FitStiffness(loading);
  if (!a.fit_plot.empty()) {
    if (fit.points < 2) Fail("run", "--fit-plot: the tool never pressed into the surface");
    PlotFit(a, loading, fit);
  }
  nlohmann::json crossings_json = nlohmann::json::array();
  for (const Crossing& c : crossings) crossings_json.push_back(c.Json());
  nlohmann::json warnings_by_kind = nlohmann::json::object();
  for (const WarningKind& k : WarningKinds(state.warnings)) warnings_by_kind[k.name] = k.count;
  nlohmann::json summary = {
      {"stiffness_fit", {{"k", -fit.slope}, {"intercept", fit.intercept}, {"r2", fit.r2}, {"points", fit.points}}},
      {"ticks", ticks},
      {"crossings", crossings_json},
      {"preset", PresetName(preset)},
      {"integrator", IntegratorName(options.integrator)},
      {"local_radius", options.full ? nlohmann::json(nullptr) : nlohmann::json(options.local_radius)},
      {"max_force", max_force},
      {"max_fz", max_fz},
      {"onset_z", std::isnan(onset_z) ? nlohmann::json(nullptr) : nlohmann::json(onset_z)},
      {"warnings", TotalWarnings(state.warnings)},
      {"warnings_by_kind", warnings_by_kind},
      {"fallbacks", fallbacks},
      // Ticks full mode's fused pass computed (the rest took the general path), and element
      // updates per second at the median tick: elements x substeps per tick / its compute time.
      {"fused_ticks", fused_ticks},
      {"elements", model.num_elems},
      {"substeps_mean", ticks > 0 ? static_cast<double>(substeps) / ticks : 0.0},
      // Full mode: the tick's CPU time (this thread's), and element updates per second at its
      // median, elements x substeps per tick / CPU time, as idms-step-throughput-bench counts.
      {"compute_cpu_us", {{"p50", Percentile(cpu_us, 0.5)}, {"p99", Percentile(cpu_us, 0.99)}}},
      // On several threads (--threads), per wall-clock second at the median tick instead: this
      // thread's CPU time leaves the others' out.
      {"element_updates_per_s", ticks > 0 && Percentile(sections > 1 ? compute_us : cpu_us, 0.5) > 0
                                    ? model.num_elems * (static_cast<double>(substeps) / ticks) /
                                          (1e-6 * Percentile(sections > 1 ? compute_us : cpu_us, 0.5))
                                    : 0.0},
      {"threads", sections},
      {"global", global ? nlohmann::json{{"rate_hz", 1.0 / (global->ticks_per_step() * a.dt)},
                                         {"ticks_per_step", global->ticks_per_step()},
                                         {"threaded", a.global_thread},
                                         {"steps", global->stats().steps},
                                         {"late", global->stats().late},
                                         {"last_step_ms", global->stats().last_step_ms},
                                         {"reachable_hz", global->stats().reachable_hz}}
                        : nlohmann::json(nullptr)},
      {"cross_elements", GetFusedPassStatus(workspace).cross_elements},
      {"compute_us",
       {{"p50", Percentile(compute_us, 0.5)},
        {"p99", Percentile(compute_us, 0.99)},
        {"max", compute_us.empty() ? 0.0 : *std::max_element(compute_us.begin(), compute_us.end())}}}};
  // Only with friction, so a frictionless run's summary is what it always was.
  if (a.friction) {
    summary["friction"] = {{"mu_s", tool.mu_s},          {"mu_d", tool.mu_d},
                           {"stick_ticks", stick_ticks}, {"slip_ticks", slip_ticks},
                           {"transitions", transitions}, {"max_ft", max_ft},
                           {"work", friction_work},      {"work_max_running_sum", friction_work_max_sum}};
  }
  if (tool.kind == ToolKind::kNeedle) {
    summary["needle"] = {
        {"punctures", punctures},
        {"punctured_s", std::isnan(punctured_s) ? nlohmann::json(nullptr) : nlohmann::json(punctured_s)},
        {"max_inserted", max_inserted},
        {"inside_at_end", inside},
        {"exits", exits},
        {"drawn_through", draws},
        {"max_force_step", max_force_step}};
  }
  if (tool.kind == ToolKind::kNeedle && tool.suture.length > 0) {
    summary["suture"] = {{"punctures", thread_punctures}, {"ties", ties},
                         {"ties_refused", ties_refused},  {"breaks", breaks},
                         {"max_tension", max_tension},    {"nodes", state.suture.num_nodes}};
  }
  // The suture's incision (model units): its gap over the stitched rows when the needle came and
  // at the end, the widest over the last kSutureHold s, and over every row it crossed at the end.
  if (suture) {
    const double gap_final = IncisionGap(geometry, state.atom_pos.data(), true);
    auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
    summary["gap_open"] = number(gap_open);
    summary["gap_final"] = number(gap_final);
    summary["gap_final_fraction"] = number(gap_final / gap_open);
    summary["gap_widest_held"] = number(gap_widest_held);
    summary["gap_incision_final"] = number(IncisionGap(geometry, state.atom_pos.data(), false));
    summary["stitches"] = stitches;
    summary["ties"] = ties;
    summary["incision"] = {{"rows", geometry.num_incision_rows},
                           {"elements_cut", cut_elements},
                           {"x", geometry.incision_x},
                           {"y", {geometry.incision_y[0], geometry.incision_y[1]}}};
  }
  if (a.json) {
    PrintJson(summary);
  } else {
    std::printf(
        "%s on %s (%s, r_l %.4g): %lld ticks, max |f| %.4g N, max f_z %.4g N, onset z %.4g, %lld warnings, "
        "%lld fallbacks, compute p50 %.2f us p99 %.2f us\n",
        a.script.c_str(), model.name.c_str(), IntegratorName(options.integrator),
        options.full ? NAN : options.local_radius, static_cast<long long>(ticks), max_force, max_fz, onset_z,
        static_cast<long long>(TotalWarnings(state.warnings)), static_cast<long long>(fallbacks),
        summary["compute_us"]["p50"].get<double>(), summary["compute_us"]["p99"].get<double>());
    if (a.friction) {
      std::printf(
          "friction mu_s %.3g mu_d %.3g: %lld stick, %lld slip ticks, %lld transitions, max |f_t| %.4g N, work %.4g "
          "(largest running sum %.3g)\n",
          tool.mu_s, tool.mu_d, static_cast<long long>(stick_ticks), static_cast<long long>(slip_ticks),
          static_cast<long long>(transitions), max_ft, friction_work, friction_work_max_sum);
    }
    for (const nlohmann::json& c : crossings_json) {
      std::printf(
          "  crossing %.2f-%.2f s: max |f_x| %.3g N, max |f_y| %.3g N, f_z %.3g +- %.2g N (%.3g to %.3g), "
          "mean f_x accelerating %.3g N, decelerating %.3g N\n",
          c["t"][0].get<double>(), c["t"][1].get<double>(), c["max_abs_fx"].get<double>(),
          c["max_abs_fy"].get<double>(), c["mean_fz"].get<double>(), c["sd_fz"].get<double>(),
          c["fz_range"][0].get<double>(), c["fz_range"][1].get<double>(), c["mean_fx_accelerating"].get<double>(),
          c["mean_fx_decelerating"].get<double>());
    }
    if (a.full) {
      std::printf(
          "full mode: %lld of %lld ticks in the fused pass; CPU p50 %.2f ms per tick, %.3g element updates "
          "per second\n",
          static_cast<long long>(fused_ticks), static_cast<long long>(ticks),
          1e-3 * summary["compute_cpu_us"]["p50"].get<double>(), summary["element_updates_per_s"].get<double>());
    }
  }
}

void Setup(CLI::App& app) {
  auto* cmd = app.add_subcommand("run", "Run a scripted thesis interaction offline (thesis ch. 6)");
  static RunArgs a;
  cmd->add_option("--model", a.model, "Model prefix (PREFIX.fem + PREFIX.plg)")->required();
  cmd->add_option("--script", a.script,
                  "palpate | stroke-slow | stroke-fast | pluck | stroke-gentle (thesis 6.1 at its speeds; gentle: a "
                  "slow stroke to watch) | scan (7 x 7 shallow presses, for fit --map; --scan-grid) | pierce (a "
                  "needle, docs/needle.md) | stitch (a needle drawn through, its thread tied) | "
                  "drag[:fraction=F,depth=D,mass=M,damping=B,push=S] (press, then push "
                  "sideways at F mu_s f_n through a simulated hand; needs mu_s)")
      ->capture_default_str();
  cmd->add_option("--preset", a.preset,
                  "default (symplectic Euler, r_l = 2 r: the error-against-run-time choice) | thesis (explicit "
                  "Euler, r_l = 1.5 r: thesis 6.2, what docs/figures use)")
      ->capture_default_str();
  cmd->add_option("--integrator", a.integrator, "euler | symplectic | rk4 | implicit (default: the preset's)");
  cmd->add_option("--dt", a.dt, "Time step T, s")->capture_default_str();
  auto* radius = cmd->add_option("--local-radius", a.local_radius, "Haptic window radius r_l (default: the preset's)");
  auto* full = cmd->add_flag("--full", a.full, "Simulate every atom (local simulation off)")->excludes(radius);
  auto* global_rate =
      cmd->add_option("--global-rate", a.global_rate,
                      "The whole model at this rate (Hz) beside the local pass (thesis 7.2.2); 0 = local only")
          ->check(CLI::Range(0.0, 1000.0))
          ->excludes(full);
  cmd->add_flag("--global-thread", a.global_thread,
                "Run the global pass on a thread of its own (else at each exchange: reproducible)")
      ->needs(global_rate);
  cmd->add_option("--threads", a.threads,
                  "Full mode or the global pass: threads for the whole model's pass, in sections of a renumbered "
                  "model (idms-sim reorder); "
                  "the same results as one")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  cmd->add_option("--lambda", a.lambda, "Eq. 4.6 filter weight (1 = backward difference)")->capture_default_str();
  cmd->add_option("--scan-grid", a.scan_grid, "The scan's points per side (default 7: 7 x 7 over the middle 60%)")
      ->check(CLI::Range(kMinScanGrid, kMaxScanGrid));
  cmd->add_option("--ticks", a.max_ticks, "Stop after this many ticks (default: the whole script)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--tool", a.tool,
                  "sphere:r=1.5,k=400[,law=thesis|linear][,mu_s=S,mu_d=D,k_t=K,b_t=B] or tweezers:... (pluck); "
                  "mu_s > 0: Coulomb friction with stiction (mu_d defaults to mu_s, k_t to k, b_t to k_t dt)");
  cmd->add_option("--csv", a.csv,
                  "Write t,x,y,z,fx,fy,fz,active_atoms,substeps,compute_us per tick (with friction, then "
                  "ftx,fty,ftz,ft,fn,friction)");
  cmd->add_option("--plot", a.plot, "Write a PNG of the position and force histories (needs --csv)");
  cmd->add_option("--plot-window", a.plot_window, "T0,T1: the plot's time axis, s (default: the whole run)")
      ->delimiter(',')
      ->expected(2);
  cmd->add_option("--fit-plot", a.fit_plot, "Write a PNG of f_z against z while pressing, with its fit (fig. 6-3)");
  cmd->add_flag("--json", a.json, "Print the summary as one JSON object");
  cmd->callback([] { Run(a); });
}

IDMS_SIM_COMMAND(40, Setup);

}  // namespace
}  // namespace idms::tool
