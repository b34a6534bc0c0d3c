// Error against run time (issue 3, DESIGN.md "Integrators"): palpation and gentle stroking on the
// thesis's hex fragment and on a draped ~10^5-atom cap, for every integrator, tick and haptic
// window radius, against an RK4 dt = 1e-5 full-model reference. Writes a CSV, plots and a
// markdown table with the default configuration marked; never fails on time.
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "idms/sim/drape.h"
#include "idms/sim/generate.h"
#include "idms/sim/model_io.h"
#include "report.h"
#include "runner.h"

namespace idms::bench {
namespace {

struct Args {
  bool quick = false, hex = true, curved = true, friction = true;
  std::string out_dir = ".";
  std::string from_csv;  // redo the report from this CSV instead of running
  std::string work_dir;  // curved model cache; default: out_dir
  std::string hex_prefix = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";
  // The curved model: a slab of rows x cols draped onto R_f (about 3 rows x cols atoms).
  int rows = 183, cols = 182;
  double radius = 400;
  double window_s = 0.1;  // script window on the curved model, from just before contact
  int repeats = 3;        // hex runs are repeated and the least CPU time kept
};

void Usage(const char* argv0) {
  std::fprintf(stderr,
               "usage: %s [--quick] [--out DIR] [--work DIR] [--hex PREFIX] [--no-hex] [--no-curved] [--no-friction]\n"
               "          [--from-csv F]\n"
               "          [--curved ROWSxCOLS] [--curved-radius R] [--curved-window S] [--repeats N]\n"
               "  --quick        smoke run: short windows, 2 ticks x 2 radii, a small cap (seconds)\n"
               "  --out DIR      where error-vs-runtime.{csv,md} and the PNGs go (default .)\n"
               "  --work DIR     where the draped curved model is cached (default: --out)\n"
               "  --from-csv F   redo the plots and the document from a CSV this bench wrote (no runs)\n",
               argv0);
}

bool ParseArgs(int argc, char** argv, Args* a) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const bool has_value = i + 1 < argc;
    if (arg == "--quick") {
      a->quick = true;
    } else if (arg == "--no-hex") {
      a->hex = false;
    } else if (arg == "--no-curved") {
      a->curved = false;
    } else if (arg == "--no-friction") {
      a->friction = false;
    } else if (arg == "--from-csv" && has_value) {
      a->from_csv = argv[++i];
    } else if (arg == "--out" && has_value) {
      a->out_dir = argv[++i];
    } else if (arg == "--work" && has_value) {
      a->work_dir = argv[++i];
    } else if (arg == "--hex" && has_value) {
      a->hex_prefix = argv[++i];
    } else if (arg == "--curved" && has_value) {
      if (std::sscanf(argv[++i], "%dx%d", &a->rows, &a->cols) != 2 || a->rows < 2 || a->cols < 1) return false;
    } else if (arg == "--curved-radius" && has_value) {
      a->radius = std::atof(argv[++i]);
      if (!(a->radius > 0)) return false;
    } else if (arg == "--curved-window" && has_value) {
      a->window_s = std::atof(argv[++i]);
      if (!(a->window_s >= 2 * kSamplePeriodS)) return false;
    } else if (arg == "--repeats" && has_value) {
      a->repeats = std::atoi(argv[++i]);
      if (a->repeats < 1) return false;
    } else {
      return false;
    }
  }
  if (a->quick) a->rows = 15, a->cols = 14, a->radius = 14, a->window_s = 0.05, a->repeats = 1;
  if (a->work_dir.empty()) a->work_dir = a->out_dir;
  return true;
}

// The curved model: a thesis-material slab draped onto a sphere (thesis 5.6.1), cached by its
// parameters. Air damping (about critical for the slab's slowest in-plane mode) settles the
// large slab faster; the equilibrium does not depend on it.
constexpr double kCurvedAirDamping = 3;  // 1/s
constexpr double kCurvedMaxTime = 12;    // s
bool CurvedModel(const Args& a, Model* model, std::string* note) {
  char name[64];
  std::snprintf(name, sizeof name, "cap_%dx%d_r%g", a.rows, a.cols, a.radius);
  const std::string prefix = (std::filesystem::path(a.work_dir) / name).string();
  LoadError error;
  char text[256];
  std::snprintf(text, sizeof text,
                "%s: a %dx%d thesis-material slab draped onto a sphere of radius %g (idms::Drape, form defaults, "
                "air damping %g/s, at most %g s)",
                name, a.rows, a.cols, a.radius, kCurvedAirDamping, kCurvedMaxTime);
  *note = text;
  if (LoadModel(prefix + ".fem", prefix + ".plg", {}, model, &error)) {
    std::printf("curved model: %s (cached, %d atoms, %d elements)\n", prefix.c_str(), model->num_atoms,
                model->num_elems);
    return true;
  }
  SlabOptions slab;
  slab.rows = a.rows, slab.cols = a.cols, slab.name = name;
  DrapeOptions o;
  o.form.radius = a.radius;
  o.step.air_damping = kCurvedAirDamping;
  o.step.dt_s = std::min(1e-3, 0.9 * DrapeStableDt(StripHomeElements(GenerateSlab(slab)), o.form, o.step));
  o.max_time_s = kCurvedMaxTime;
  o.settle_speed = 1e-2;
  o.settle_kinetic = 1e-3;
  o.progress_every_s = 0.25;
  o.name = name;
  const auto start = std::chrono::steady_clock::now();
  std::printf("curved model: draping %dx%d onto R_f = %g ...\n", a.rows, a.cols, a.radius);
  std::fflush(stdout);
  const DrapeResult r = Drape(GenerateSlab(slab), o, [](const DrapeProgress& p) {
    std::fprintf(stderr, "  drape t %.2f s  kinetic %.3e  max speed %.3e\n", p.time_s, p.kinetic, p.max_speed);
  });
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "curved model: %s after %.2f s simulated in %.0f s wall; %d atoms, %d elements, %d folded triangles, "
      "lower layer %.3f..%.3f from the sphere\n",
      r.settled ? "settled" : "stopped", r.time_s, wall, r.model.num_atoms, r.model.num_elems, r.folded_triangles,
      r.internal_min, r.internal_max);
  *note += r.settled ? "; settled" : "; stopped at the time limit (the model is at rest by construction)";
  std::string save_error;
  std::filesystem::create_directories(a.work_dir);
  if (!SaveModel(r.model, prefix, &save_error)) {
    std::fprintf(stderr, "cannot cache the curved model: %s\n", save_error.c_str());
  }
  *model = r.model;
  return true;
}

std::vector<Config> Sweep(bool quick, const Config& default_config) {
  const std::vector<Integrator> integrators = {Integrator::kExplicitEuler, Integrator::kSymplecticEuler,
                                               Integrator::kRk4, Integrator::kImplicitEuler};
  const std::vector<double> dts =
      quick ? std::vector<double>{5e-4, 1e-3} : std::vector<double>{1e-4, 2e-4, 5e-4, 1e-3, 2e-3};
  const std::vector<double> radii = quick ? std::vector<double>{1.5, 0} : std::vector<double>{1.0, 1.5, 2.0, 3.0, 0};
  std::vector<Config> configs;
  for (Integrator integrator : integrators) {
    for (double dt : dts) {
      for (double ratio : radii) configs.push_back({integrator, dt, ratio});
    }
  }
  // The default is always measured, even if StepOptions' defaults leave the grid.
  bool found = false;
  for (const Config& c : configs) found = found || c == default_config;
  if (!found) configs.push_back(default_config);
  return configs;
}

CaseResult RunSweep(const Case& c, const std::vector<Config>& configs, int repeats) {
  CaseResult out;
  out.c = c;
  out.onset_s = ContactOnset(c);
  out.atoms = c.model->num_atoms;
  std::printf("\n== %s / %s: t %.3f .. %.3f s (contact at %.3f s), %d atoms, %d samples\n", c.model_name.c_str(),
              c.script_name.c_str(), c.t0_s, c.t1_s, out.onset_s, c.model->num_atoms, c.samples());
  std::fflush(stdout);

  // Reference: RK4, dt 1e-5, full model.
  Reference ref;
  const RunResult ref_run = RunCase(c, {Integrator::kRk4, 1e-5, 0}, nullptr, &ref);
  out.reference_cpu_s = ref_run.cpu_us_per_ms * 1e-6 * (c.t1_s - c.t0_s) * 1e3;
  out.reference_peak_force = ref.peak_force;
  out.reference_bytes = ref.bytes();
  out.reference_warnings = ref_run.warnings;
  std::printf("reference rk4 dt 1e-5 full: %.1f s CPU, peak force %.4g, %lld warnings, %.1f MB recorded\n",
              out.reference_cpu_s, ref.peak_force, static_cast<long long>(ref_run.warnings), ref.bytes() / 1e6);
  std::fflush(stdout);

  // Every configuration against it.
  for (const Config& config : configs) {
    const RunResult r = RunCase(c, config, &ref, nullptr, repeats);
    std::printf(
        "  %-32s %10.1f us/ms  force rms %.3e max %.3e  pos max %.3e  active %6d  substeps %.2f  fallbacks %lld\n",
        ConfigLabel(config).c_str(), r.cpu_us_per_ms, r.force_rms, r.force_max, r.pos_max, r.max_active,
        r.substeps_mean, static_cast<long long>(r.fallbacks));
    std::fflush(stdout);
    out.runs.push_back(r);
  }
  return out;
}

// The window of a script on the curved model: from a whole 10 ms before first contact, for
// window_s. Before contact nothing moves, so every run starting there at rest is the run from 0.
void CurvedWindow(Case* c, double window_s) {
  c->t0_s = 0;
  c->t1_s = ScriptDuration(c->script);
  const double onset = ContactOnset(*c);
  c->t0_s = std::max(0.0, std::floor((onset - 0.01) * 100) / 100);
  c->t1_s = std::min(ScriptDuration(c->script), c->t0_s + window_s);
}

std::string Machine() {
  std::string cpu = "unknown CPU";
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("model name", 0) == 0) {
      cpu = line.substr(line.find(':') + 2);
      break;
    }
  }
  double load[3] = {0, 0, 0};
  if (getloadavg(load, 3) < 0) load[0] = -1;
  char buf[256];
  std::snprintf(buf, sizeof buf, "%s, load average %.1f at the end of the run", cpu.c_str(), load[0]);
  return buf;
}

}  // namespace
}  // namespace idms::bench

int main(int argc, char** argv) {
  using namespace idms;
  using namespace idms::bench;
  Args a;
  if (!ParseArgs(argc, argv, &a)) {
    Usage(argv[0]);
    return 2;
  }
  const auto start = std::chrono::steady_clock::now();
  const StepOptions defaults;
  const Config default_config{defaults.integrator, defaults.dt_s, defaults.local_radius / kMioRadius};
  if (!a.from_csv.empty()) {
    std::vector<CaseResult> cases;
    ReportOptions report{.out_dir = a.out_dir,
                         .default_config = default_config,
                         .quick = a.quick,
                         .machine = "(rebuilt from " + a.from_csv + ")"};
    std::string error;
    std::filesystem::create_directories(a.out_dir);
    if (!ReadCsv(a.from_csv, &cases, &error) || !WriteReport(cases, report, &error)) {
      std::fprintf(stderr, "%s\n", error.c_str());
      return 1;
    }
    return 0;
  }
  const std::vector<Config> configs = Sweep(a.quick, default_config);
  std::printf("error against run time: %zu configurations per case; default %s (StepOptions defaults)\n",
              configs.size(), ConfigLabel(default_config).c_str());

  std::vector<CaseResult> results;
  Model hex, curved;
  ReportOptions report;
  if (a.hex) {
    LoadError error;
    if (!LoadModel(a.hex_prefix + ".fem", a.hex_prefix + ".plg", {}, &hex, &error)) {
      std::fprintf(stderr, "%s\n", error.ToString().c_str());
      return 1;
    }
    // The thesis's fragment: whole scripts (the quick run keeps the press of the palpation).
    for (Script script : {Script::kPalpate, Script::kStrokeGentle}) {
      Case c{.model_name = "hex_4x5_home",
             .script_name = ScriptName(script),
             .model = &hex,
             .script = script,
             .geometry = MakeScriptGeometry(hex, kMioRadius),
             .t0_s = 0,
             .t1_s = ScriptDuration(script)};
      if (a.quick && script == Script::kStrokeGentle) continue;
      if (a.quick) c.t0_s = 2.0, c.t1_s = 2.6;
      results.push_back(RunSweep(c, configs, a.repeats));
    }
  }
  if (a.hex && a.friction) {
    // The gentle stroke with friction (issue 30): the tests' and benches' coefficients, and the
    // tangential damper fixed at the default tick's k_t dt (its default changes with dt). The
    // quick run keeps the press and the stroke's first half second.
    Case c{.model_name = "hex_4x5_home",
           .script_name = std::string(ScriptName(Script::kStrokeGentle)) + "-friction",
           .model = &hex,
           .script = Script::kStrokeGentle,
           .geometry = MakeScriptGeometry(hex, kMioRadius),
           .t0_s = 0,
           .t1_s = ScriptDuration(Script::kStrokeGentle),
           .mu_s = 0.6,
           .mu_d = 0.4,
           .friction_damping = 400 * 1e-3};
    if (a.quick) c.t0_s = std::floor((ContactOnset(c) - 0.01) * 100) / 100, c.t1_s = 3.5;
    results.push_back(RunSweep(c, configs, a.repeats));
  }
  if (a.curved) {
    CurvedModel(a, &curved, &report.curved_note);
    const std::string name = curved.name;
    for (Script script : {Script::kPalpate, Script::kStrokeGentle}) {
      Case c{.model_name = name,
             .script_name = ScriptName(script),
             .model = &curved,
             .script = script,
             .geometry = MakeScriptGeometry(curved, kMioRadius)};
      if (script == Script::kStrokeGentle) {
        // The default stroke line (60% of the width at one height) would leave a curved surface
        // at once: stroke 6 units across the crown instead, at the palpation point.
        c.geometry.x_min = c.geometry.center[0] - 3;
        c.geometry.x_max = c.geometry.center[0] + 3;
        c.geometry.stroke_y = c.geometry.center[1];
      }
      CurvedWindow(&c, a.window_s);
      results.push_back(RunSweep(c, configs, 1));
    }
  }

  report.out_dir = a.out_dir;
  report.default_config = default_config;
  report.quick = a.quick;
  report.machine = Machine();
  report.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  report.cpu_s = static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
                 1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
  std::string error;
  std::filesystem::create_directories(a.out_dir);
  const bool ok = WriteReport(results, report, &error);
  if (!ok) std::fprintf(stderr, "report: %s\n", error.c_str());
  std::printf("\nwall time %.0f s, CPU time %.0f s\n", report.wall_s, report.cpu_s);
  return ok ? 0 : 1;
}
