// The analysis and outputs of the error-against-run-time bench: Pareto fronts, CSV, PNG plots
// (through idms-sim's PlotPng) and the markdown document.
#include "report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "plot.h"

namespace idms::bench {
namespace {

// The columns before friction came (issue 30); a CSV with only these reads back frictionless.
constexpr const char* kCsvHeaderFrictionless =
    "model,script,t0_s,t1_s,atoms,onset_s,ref_cpu_s,ref_peak_force,ref_warnings,integrator,dt_s,radius_ratio,"
    "local_radius,cpu_us_per_ms,force_rms,force_max,pos_max,ticks,substeps_mean,fallbacks,warnings,max_active,"
    "in_budget,on_front_force,on_front_pos,default";
constexpr int kFieldsFrictionless = 26;
constexpr const char* kFrictionColumns = ",mu_s,mu_d,friction_damping,friction_rms,friction_max";
constexpr int kFields = kFieldsFrictionless + 5;
const std::string kCsvHeader = std::string(kCsvHeaderFrictionless) + kFrictionColumns;

const Integrator kIntegrators[] = {Integrator::kExplicitEuler, Integrator::kSymplecticEuler, Integrator::kRk4,
                                   Integrator::kImplicitEuler};

bool InBudget(const RunResult& r) { return r.cpu_us_per_ms <= kBudgetUsPerMs; }

bool Dominates(const RunResult& a, const RunResult& b, double RunResult::*error) {
  return a.cpu_us_per_ms <= b.cpu_us_per_ms && a.*error <= b.*error &&
         (a.cpu_us_per_ms < b.cpu_us_per_ms || a.*error < b.*error);
}

int FindConfig(const std::vector<RunResult>& runs, const Config& config) {
  for (size_t i = 0; i < runs.size(); ++i) {
    if (runs[i].config == config) return static_cast<int>(i);
  }
  return -1;
}

std::string Radius(double ratio) {
  char buf[32];
  if (ratio <= 0) return "full";
  std::snprintf(buf, sizeof buf, "%gr", ratio);
  return buf;
}

std::string Fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

std::string CaseSlug(const CaseResult& c) { return c.c.model_name + "-" + c.c.script_name; }

bool WriteCsv(const std::vector<CaseResult>& cases, const ReportOptions& o, const std::string& path,
              std::string* error) {
  std::ofstream out(path);
  if (!out) {
    *error = "cannot write " + path;
    return false;
  }
  out << kCsvHeader << "\n";
  for (const CaseResult& c : cases) {
    const std::vector<bool> front_f = ParetoFront(c.runs, &RunResult::force_rms);
    const std::vector<bool> front_p = ParetoFront(c.runs, &RunResult::pos_max);
    for (size_t i = 0; i < c.runs.size(); ++i) {
      const RunResult& r = c.runs[i];
      char line[640];
      std::snprintf(line, sizeof line,
                    "%s,%s,%.17g,%.17g,%d,%.6g,%.4g,%.6g,%lld,%s,%g,%g,%g,%.4g,%.6g,%.6g,%.6g,%lld,%.4g,%lld,%lld,%d,"
                    "%d,%d,%d,%d,%g,%g,%g,%.6g,%.6g\n",
                    c.c.model_name.c_str(), c.c.script_name.c_str(), c.c.t0_s, c.c.t1_s, c.atoms, c.onset_s,
                    c.reference_cpu_s, c.reference_peak_force, static_cast<long long>(c.reference_warnings),
                    IntegratorName(r.config.integrator), r.config.dt_s, r.config.radius_ratio,
                    r.config.radius_ratio * kMioRadius, r.cpu_us_per_ms, r.force_rms, r.force_max, r.pos_max,
                    static_cast<long long>(r.ticks), r.substeps_mean, static_cast<long long>(r.fallbacks),
                    static_cast<long long>(r.warnings), r.max_active, InBudget(r) ? 1 : 0, front_f[i] ? 1 : 0,
                    front_p[i] ? 1 : 0, r.config == o.default_config ? 1 : 0, c.c.mu_s, c.c.mu_d, c.c.friction_damping,
                    r.friction_rms, r.friction_max);
      out << line;
    }
  }
  return static_cast<bool>(out);
}

// Log-log force RMS error against CPU time: per integrator its points (labelled "dt ms / r_l")
// and its own front as a line; the default ringed; the 1 kHz budget as a dashed line.
bool Plot(const CaseResult& c, const ReportOptions& o, std::string* error) {
  namespace fs = std::filesystem;
  const fs::path labels = fs::temp_directory_path() / ("idms-error-labels-" + CaseSlug(c) + ".csv");
  {
    std::ofstream out(labels);
    out << "us,err,label\n";
    for (const RunResult& r : c.runs) {
      out << r.cpu_us_per_ms << "," << std::max(r.force_rms, 1e-12) << "," << Fmt("%g", r.config.dt_s * 1e3) << "/"
          << (r.config.radius_ratio <= 0 ? "F" : Fmt("%g", r.config.radius_ratio)) << "\n";
    }
  }
  tool::PlotSpec spec;
  spec.title = c.c.model_name + ", " + c.c.script_name +
               ": device-force error against compute (labels: dt ms / r_l in r, F = full)";
  spec.x_label = "compute per simulated ms (us, thread CPU time)";
  spec.y_label = "RMS device-force error vs RK4 dt 1e-5 full (force units)";
  spec.log_x = spec.log_y = true;
  spec.width_px = 1200, spec.height_px = 850;
  spec.key = "top right";
  // Wide enough to show the budget line.
  double lo = kBudgetUsPerMs, hi = kBudgetUsPerMs;
  for (const RunResult& r : c.runs) lo = std::min(lo, r.cpu_us_per_ms), hi = std::max(hi, r.cpu_us_per_ms);
  spec.x_range = std::array<double, 2>{lo / 1.5, hi * 2};
  spec.preamble.push_back("set arrow from " + Fmt("%g", kBudgetUsPerMs) + ", graph 0 to " + Fmt("%g", kBudgetUsPerMs) +
                          ", graph 1 nohead dt 2 lc rgb 'red'");
  spec.preamble.push_back("set label '1 kHz budget' at " + Fmt("%g", kBudgetUsPerMs * 1.05) +
                          ", graph 0.03 tc rgb 'red'");
  const char* colors[] = {"#1b9e77", "#d95f02", "#7570b3", "#e7298a"};
  int ci = 0;
  for (Integrator integrator : kIntegrators) {
    std::vector<RunResult> mine;
    for (const RunResult& r : c.runs) {
      if (r.config.integrator == integrator) mine.push_back(r);
    }
    // This integrator's own front (ignoring the budget), left to right.
    std::vector<std::array<double, 2>> points, front;
    for (size_t i = 0; i < mine.size(); ++i) {
      points.push_back({mine[i].cpu_us_per_ms, std::max(mine[i].force_rms, 1e-12)});
      bool dominated = false;
      for (size_t j = 0; j < mine.size() && !dominated; ++j)
        dominated = Dominates(mine[j], mine[i], &RunResult::force_rms);
      if (!dominated) front.push_back(points.back());
    }
    std::sort(front.begin(), front.end());
    const std::string color = std::string("lc rgb '") + colors[ci++] + "'";
    spec.series.push_back(
        {.title = IntegratorName(integrator), .points = points, .style = "points", .options = "pt 7 ps 0.9 " + color});
    spec.series.push_back({.title = "", .points = front, .style = "lines", .options = "lw 2 " + color});
  }
  spec.series.push_back({.title = "",
                         .csv_path = labels.string(),
                         .x_column = "us",
                         .y_column = "err",
                         .label_column = "label",
                         .options = "font ',7' offset char 0.4,0.35 left tc rgb 'gray35'"});
  const int d = FindConfig(c.runs, o.default_config);
  if (d >= 0) {
    spec.series.push_back({.title = "default (" + ConfigLabel(o.default_config) + ")",
                           .points = {{c.runs[d].cpu_us_per_ms, std::max(c.runs[d].force_rms, 1e-12)}},
                           .style = "points",
                           .options = "pt 6 ps 3.5 lw 2 lc rgb 'black'"});
  }
  const std::string png = (fs::path(o.out_dir) / ("error-vs-runtime-" + CaseSlug(c) + ".png")).string();
  const bool ok = tool::PlotPng(spec, png, error);
  fs::remove(labels);
  return ok;
}

// Whether the default is on the force-error front, and if not, who beats it.
struct Verdict {
  bool on_front_force = false, on_front_pos = false, in_budget = false;
  std::vector<int> beaten_by;  // dominators on the force metric
};

Verdict Judge(const CaseResult& c, const Config& default_config) {
  Verdict v;
  const int d = FindConfig(c.runs, default_config);
  if (d < 0) return v;
  v.in_budget = InBudget(c.runs[d]);
  v.on_front_force = ParetoFront(c.runs, &RunResult::force_rms)[d];
  v.on_front_pos = ParetoFront(c.runs, &RunResult::pos_max)[d];
  v.beaten_by = Dominators(c.runs, d, &RunResult::force_rms);
  std::sort(v.beaten_by.begin(), v.beaten_by.end(),
            [&](int a, int b) { return c.runs[a].force_rms < c.runs[b].force_rms; });
  return v;
}

std::string RunLine(const RunResult& r, double peak) {
  std::ostringstream s;
  s << "`" << ConfigLabel(r.config) << "`: " << Fmt("%.3g", r.cpu_us_per_ms) << " us/ms, force RMS error "
    << Fmt("%.3g", r.force_rms) << " (" << Fmt("%.2g", 100 * r.force_rms / std::max(peak, 1e-300))
    << "% of peak), position " << Fmt("%.3g", r.pos_max) << ", " << Fmt("%.2f", r.substeps_mean)
    << " substeps per tick";
  return s.str();
}

// A table of the case's runs: a row per integrator and tick, a column per haptic window, the
// cell cell(run index) (the default's in bold).
template <typename Cell>
void WriteGrid(std::ostream& md, const CaseResult& c, const std::vector<double>& ratios, const Config& default_config,
               Cell cell) {
  md << "| integrator | dt (s) |";
  for (double ratio : ratios) md << " r_l " << Radius(ratio) << " |";
  md << "\n|---|---|";
  for (size_t i = 0; i < ratios.size(); ++i) md << "---|";
  md << "\n";
  std::set<std::pair<int, double>> rows;
  for (const RunResult& r : c.runs) rows.insert({static_cast<int>(r.config.integrator), r.config.dt_s});
  for (const auto& [integrator, dt] : rows) {
    md << "| " << IntegratorName(static_cast<Integrator>(integrator)) << " | " << Fmt("%g", dt) << " |";
    for (double ratio : ratios) {
      const int i = FindConfig(c.runs, {static_cast<Integrator>(integrator), dt, ratio});
      if (i < 0) {
        md << " |";
        continue;
      }
      const std::string text = cell(i);
      md << " " << (c.runs[i].config == default_config ? "**" + text + "**" : text) << " |";
    }
    md << "\n";
  }
}

void WriteCaseSection(std::ostream& md, const CaseResult& c, const ReportOptions& o) {
  const double peak = c.reference_peak_force;
  md << "\n### " << c.c.model_name << ", " << c.c.script_name << "\n\n";
  md << "Window t = " << Fmt("%g", c.c.t0_s) << " .. " << Fmt("%g", c.c.t1_s) << " s (first contact at "
     << Fmt("%.3f", c.onset_s) << " s), " << c.atoms << " atoms, " << c.c.samples()
     << " samples. Reference: " << Fmt("%.1f", c.reference_cpu_s) << " s CPU, peak device force " << Fmt("%.3g", peak)
     << ", " << c.reference_warnings << " warnings.\n\n";
  md << "![error against run time](error-vs-runtime-" << CaseSlug(c) << ".png)\n\n";

  // The grid: force RMS error as % of the peak force, and compute.
  std::vector<double> ratios;
  for (const RunResult& r : c.runs) {
    if (std::find(ratios.begin(), ratios.end(), r.config.radius_ratio) == ratios.end())
      ratios.push_back(r.config.radius_ratio);
  }
  std::sort(ratios.begin(), ratios.end(), [](double a, double b) { return (a <= 0 ? 1e9 : a) < (b <= 0 ? 1e9 : b); });
  const std::vector<bool> front = ParetoFront(c.runs, &RunResult::force_rms);
  md << "Force RMS error in % of the peak force, and (us of CPU per simulated ms). ◆ = on the Pareto front within the "
        "budget; **bold** = the default.\n\n";
  WriteGrid(md, c, ratios, o.default_config, [&](int i) {
    const RunResult& r = c.runs[i];
    std::string cell =
        Fmt("%.3g%%", 100 * r.force_rms / std::max(peak, 1e-300)) + " (" + Fmt("%.3g", r.cpu_us_per_ms) + ")";
    return front[i] ? cell + " ◆" : cell;
  });

  // With friction, its own force's error (the tangential part of the device force) on the same grid.
  if (c.c.mu_s > 0) {
    md << "\nFriction (mu_s " << Fmt("%g", c.c.mu_s) << ", mu_d " << Fmt("%g", c.c.mu_d) << ", b_t "
       << Fmt("%g", c.c.friction_damping)
       << " at every tick): the RMS and max error of friction's force |f_t - f_t,ref|, force units.\n\n";
    WriteGrid(md, c, ratios, o.default_config,
              [&](int i) { return Fmt("%.3g", c.runs[i].friction_rms) + " / " + Fmt("%.3g", c.runs[i].friction_max); });
  }

  // The front, fastest first, with every metric.
  std::vector<int> order;
  for (size_t i = 0; i < c.runs.size(); ++i) {
    if (front[i]) order.push_back(static_cast<int>(i));
  }
  std::sort(order.begin(), order.end(),
            [&](int a, int b) { return c.runs[a].cpu_us_per_ms < c.runs[b].cpu_us_per_ms; });
  md << "\nThe front within the budget, fastest first:\n\n| configuration | us/ms | force RMS | force max | position "
        "max | "
        "max active atoms | substeps | fallbacks |\n|---|---|---|---|---|---|---|---|\n";
  for (int i : order) {
    const RunResult& r = c.runs[i];
    md << "| " << ConfigLabel(r.config) << (r.config == o.default_config ? " (default)" : "") << " | "
       << Fmt("%.3g", r.cpu_us_per_ms) << " | " << Fmt("%.3g", r.force_rms) << " | " << Fmt("%.3g", r.force_max)
       << " | " << Fmt("%.3g", r.pos_max) << " | " << r.max_active << " | " << Fmt("%.2f", r.substeps_mean) << " | "
       << r.fallbacks << " |\n";
  }

  // The verdict.
  const Verdict v = Judge(c, o.default_config);
  const int d = FindConfig(c.runs, o.default_config);
  md << "\n**Default:** " << RunLine(c.runs[d], peak) << ". ";
  if (!v.in_budget) {
    md << "It is over the 1 kHz budget here.\n";
  } else if (v.on_front_force) {
    md << "It is on the Pareto front (force error)" << (v.on_front_pos ? " and on the position-error front too" : "")
       << ".\n";
  } else {
    md << "It is **not** on the front: " << v.beaten_by.size()
       << " configuration(s) are as fast or faster and at least "
       << "as accurate. The most accurate of them: " << RunLine(c.runs[v.beaten_by.front()], peak) << ".\n";
  }
}

// A replacement default for when the current one is off the front somewhere: among the
// configurations that update the force every ms (dt <= 1 ms: a 2 ms tick is cheaper but serves a
// 1 kHz device at 500 Hz), are within the budget in every case and are never less accurate
// (force RMS) than the current default, the one on the most fronts; ties go to the most accurate
// in its worst case (every candidate is far inside the budget, so cost is not the tie-breaker).
struct Proposal {
  bool found = false;
  Config config;
  int fronts = 0;
  double worst_cost = 0;                   // us per simulated ms, over the cases
  double best_ratio = 0, worst_ratio = 0;  // its force RMS / the default's, over the cases
};

Proposal Propose(const std::vector<CaseResult>& cases, const Config& default_config) {
  Proposal best;
  if (cases.empty()) return best;
  for (const RunResult& candidate : cases.front().runs) {
    Proposal p;
    p.config = candidate.config;
    p.best_ratio = 1e300;
    bool ok = !(candidate.config == default_config) && candidate.config.dt_s <= kSamplePeriodS;
    for (const CaseResult& c : cases) {
      const int i = FindConfig(c.runs, candidate.config), d = FindConfig(c.runs, default_config);
      if (i < 0 || d < 0 || !InBudget(c.runs[i]) || c.runs[i].force_rms > c.runs[d].force_rms) {
        ok = false;
        break;
      }
      p.fronts += ParetoFront(c.runs, &RunResult::force_rms)[i];
      p.worst_cost = std::max(p.worst_cost, c.runs[i].cpu_us_per_ms);
      const double ratio = c.runs[i].force_rms / std::max(c.runs[d].force_rms, 1e-300);
      p.best_ratio = std::min(p.best_ratio, ratio);
      p.worst_ratio = std::max(p.worst_ratio, ratio);
    }
    if (!ok) continue;
    p.found = true;
    if (!best.found || p.fronts > best.fronts || (p.fronts == best.fronts && p.worst_ratio < best.worst_ratio))
      best = p;
  }
  return best;
}

// What widening the haptic window buys at the default's integrator and tick, per case.
std::string WindowNote(const std::vector<CaseResult>& cases, const Config& d) {
  std::ostringstream s;
  s << "At the default's integrator and tick, the force RMS error (in % of the peak force) and cost against r_l:";
  for (const CaseResult& c : cases) {
    s << "\n- " << c.c.model_name << ", " << c.c.script_name << ":";
    const double peak = std::max(c.reference_peak_force, 1e-300);
    for (double ratio : {1.0, 1.5, 2.0, 3.0, 0.0}) {
      const int i = FindConfig(c.runs, {d.integrator, d.dt_s, ratio});
      if (i < 0) continue;
      s << " " << Radius(ratio) << " " << Fmt("%.2g%%", 100 * c.runs[i].force_rms / peak) << " ("
        << Fmt("%.3g", c.runs[i].cpu_us_per_ms) << " us/ms);";
    }
  }
  return s.str();
}

}  // namespace

bool ReadCsv(const std::string& path, std::vector<CaseResult>* cases, std::string* error) {
  std::ifstream in(path);
  std::string line;
  if (!in || !std::getline(in, line) || (line != kCsvHeader && line != kCsvHeaderFrictionless)) {
    *error = path + ": not an error-vs-runtime CSV of this version (expected the header " + kCsvHeader + ")";
    return false;
  }
  const size_t columns = line == kCsvHeader ? kFields : kFieldsFrictionless;
  for (int number = 2; std::getline(in, line); ++number) {
    std::vector<std::string> f;
    std::stringstream fields(line);
    for (std::string field; std::getline(fields, field, ',');) f.push_back(field);
    RunResult r;
    if (f.size() != columns || !ParseIntegratorName(f[9], &r.config.integrator)) {
      *error = path + ":" + std::to_string(number) + ": expected " + std::to_string(columns) +
               " fields with an integrator name in the 10th";
      return false;
    }
    const double t0 = std::stod(f[2]), t1 = std::stod(f[3]);
    if (cases->empty() || cases->back().c.model_name != f[0] || cases->back().c.script_name != f[1]) {
      CaseResult c;
      c.c.model_name = f[0], c.c.script_name = f[1], c.c.t0_s = t0, c.c.t1_s = t1;
      c.atoms = std::stoi(f[4]);
      c.onset_s = std::stod(f[5]);
      c.reference_cpu_s = std::stod(f[6]);
      c.reference_peak_force = std::stod(f[7]);
      c.reference_warnings = std::stoll(f[8]);
      if (columns == kFields) {
        c.c.mu_s = std::stod(f[26]), c.c.mu_d = std::stod(f[27]), c.c.friction_damping = std::stod(f[28]);
      }
      cases->push_back(c);
    }
    r.config.dt_s = std::stod(f[10]);
    r.config.radius_ratio = std::stod(f[11]);
    r.cpu_us_per_ms = std::stod(f[13]);
    r.force_rms = std::stod(f[14]);
    r.force_max = std::stod(f[15]);
    r.pos_max = std::stod(f[16]);
    r.ticks = std::stoll(f[17]);
    r.substeps_mean = std::stod(f[18]);
    r.fallbacks = std::stoll(f[19]);
    r.warnings = std::stoll(f[20]);
    r.max_active = std::stoi(f[21]);
    if (columns == kFields) r.friction_rms = std::stod(f[29]), r.friction_max = std::stod(f[30]);
    cases->back().runs.push_back(r);
  }
  return true;
}

std::vector<bool> ParetoFront(const std::vector<RunResult>& runs, double RunResult::*error) {
  std::vector<bool> front(runs.size(), false);
  for (size_t i = 0; i < runs.size(); ++i) {
    if (!InBudget(runs[i])) continue;
    bool dominated = false;
    for (size_t j = 0; j < runs.size() && !dominated; ++j) {
      dominated = j != i && InBudget(runs[j]) && Dominates(runs[j], runs[i], error);
    }
    front[i] = !dominated;
  }
  return front;
}

std::vector<int> Dominators(const std::vector<RunResult>& runs, int i, double RunResult::*error) {
  std::vector<int> out;
  for (size_t j = 0; j < runs.size(); ++j) {
    if (static_cast<int>(j) != i && InBudget(runs[j]) && Dominates(runs[j], runs[i], error))
      out.push_back(static_cast<int>(j));
  }
  return out;
}

// What a case's verdict rests on. The errors are deterministic; the run times are measured, so
// the verdict can flip with timing noise: how far apart the default and the fastest configuration
// at least as accurate are is how much noise it takes.
std::string VerdictMargin(const CaseResult& c, const Config& default_config) {
  const int d = FindConfig(c.runs, default_config);
  if (d < 0) return CaseSlug(c) + ": no default run";
  const RunResult& def = c.runs[d];
  int more_accurate = 0, fastest = -1;
  for (size_t i = 0; i < c.runs.size(); ++i) {
    if (static_cast<int>(i) == d || c.runs[i].force_rms > def.force_rms) continue;
    more_accurate += c.runs[i].force_rms < def.force_rms;
    if (fastest < 0 || c.runs[i].cpu_us_per_ms < c.runs[fastest].cpu_us_per_ms) fastest = static_cast<int>(i);
  }
  std::string out =
      CaseSlug(c) + ": default force rms " + Fmt("%.4e", def.force_rms) + " max " + Fmt("%.4e", def.force_max) +
      ", pos max " + Fmt("%.4e", def.pos_max) +
      (c.c.mu_s > 0 ? ", friction rms " + Fmt("%.4e", def.friction_rms) + " max " + Fmt("%.4e", def.friction_max)
                    : std::string()) +
      "; " + std::to_string(more_accurate) + " of " + std::to_string(c.runs.size() - 1) +
      " configurations more accurate";
  if (fastest < 0) return out;
  const double ratio = c.runs[fastest].cpu_us_per_ms / std::max(def.cpu_us_per_ms, 1e-300);
  return out + ", the fastest of them " + ConfigLabel(c.runs[fastest].config) + " at " + Fmt("%.2f", ratio) +
         "x the default's run time: " + (ratio > 1 ? "the default leaves the front" : "the default joins the front") +
         " if timing noise moves that ratio " + (ratio > 1 ? "down" : "up") + " by " +
         Fmt("%.0f", 100 * std::abs(ratio - 1) / std::max(ratio, 1.0)) + "%";
}

bool WriteReport(const std::vector<CaseResult>& cases, const ReportOptions& o, std::string* error) {
  namespace fs = std::filesystem;
  if (!WriteCsv(cases, o, (fs::path(o.out_dir) / "error-vs-runtime.csv").string(), error)) return false;
  std::string plot_error;
  for (const CaseResult& c : cases) {
    if (!Plot(c, o, &plot_error)) std::fprintf(stderr, "plot %s: %s\n", CaseSlug(c).c_str(), plot_error.c_str());
  }

  // Verdicts across cases, and which configuration beats the default most often.
  int on_front = 0;
  std::map<std::string, std::pair<int, Config>> beaters;  // label -> (cases it dominates the default in, config)
  for (const CaseResult& c : cases) {
    const Verdict v = Judge(c, o.default_config);
    on_front += v.in_budget && v.on_front_force;
    for (int i : v.beaten_by) {
      auto& slot = beaters[ConfigLabel(c.runs[i].config)];
      ++slot.first;
      slot.second = c.runs[i].config;
    }
  }

  std::ofstream md(fs::path(o.out_dir) / "error-vs-runtime.md");
  md << "# Error against run time\n\n";
  md << "Generated by `idms-error-vs-runtime-bench" << (o.quick ? " --quick" : "") << "` (bench/error/) in "
     << Fmt("%.0f", o.wall_s) << " s wall (" << Fmt("%.0f", o.cpu_s) << " s CPU) on " << o.machine
     << ". Do not edit by hand: re-run the bench (or `--from-csv` it to redo the plots and text).\n\n";
  md << "Each case runs a scripted interaction of thesis chapter 6 (palpation 6.1.1; stroking 6.1.2 as "
        "`stroke-gentle`, one "
        "crossing in 4 s, 13 times slower than the thesis's slow stroke) with the "
        "thesis's MIO (sphere, r = 1.5, k = 400, thesis law) for every integrator, tick dt and haptic-window radius "
        "r_l, and compares it with a reference run (RK4, dt = 1e-5 s, full model) every simulated millisecond:\n\n"
        "- **force error**: |f - f_ref| of the device force (after the step's clamps), RMS and max over the samples;\n"
        "- **position error**: the largest |p - p_ref| over every atom of the model and every sample (atoms outside "
        "the haptic window are frozen, so this counts what local simulation leaves out);\n"
        "- **run time**: thread CPU time of the steps (not the sampling) per simulated ms, so other processes on the "
        "machine do not inflate it; the hex runs take the least of several repeats.\n\n"
        "The script is a function of time and each run samples the tool pose at its own ticks (the pose at the end of "
        "the tick, as `idms-sim run` does); a sample shows the latest tick that ended by then (a device holds the "
        "last force until the next tick), so dt = 2 ms is also charged for its 500 Hz update. All other step options "
        "are StepOptions defaults (energy check, substeps, implicit fallback, settling): what a user gets. "
        "The budget is real time at 1 kHz: at most "
     << Fmt("%g", kBudgetUsPerMs)
     << " us of compute per simulated ms. The Pareto front is taken over the configurations within the budget; "
        "the default is what StepOptions defaults to: `"
     << ConfigLabel(o.default_config) << "` (r_l = " << Fmt("%g", o.default_config.radius_ratio * kMioRadius)
     << ", thesis 6.2).\n\n";
  md << "A case named `...-friction` is the same script with Coulomb friction and stiction on the tool "
        "(docs/friction.md; its coefficients in the case's section): its force error includes friction's, and "
        "friction's own force |f_t - f_t,ref| is given as well. The break-away and the re-sticking at a turn are "
        "discontinuous: a run that makes them one tick apart from the reference is charged the whole jump "
        "(mu_s - mu_d) f_n at that sample, which is what the max shows.\n\n";
  if (!o.curved_note.empty()) {
    md << "The curved model is " << o.curved_note
       << ". Its scripts are shortened to a window from 10 ms before first contact: before contact nothing moves, "
          "so a run from rest there is the run from t = 0. Its stroke runs 6 units across the crown (the script's "
          "default stroke line, 60% of the width at one height, would leave a curved surface at once).\n\n";
  }
  md << "## Verdict\n\n";
  md << "The default is on the force-error Pareto front within the budget in " << on_front << " of " << cases.size()
     << " cases.";
  if (!beaters.empty()) {
    auto best = std::max_element(beaters.begin(), beaters.end(),
                                 [](const auto& a, const auto& b) { return a.second.first < b.second.first; });
    md << " Where it is not, it is dominated (as fast or faster, and as accurate or more) most often by `"
       << best->first << "` (" << best->second.first << " case(s)); see each case for the numbers.";
  }
  if (on_front < static_cast<int>(cases.size())) {
    const Proposal p = Propose(cases, o.default_config);
    if (p.found) {
      md << "\n\n**Proposal:** make `" << ConfigLabel(p.config)
         << "` the default (r_l = " << Fmt("%g", p.config.radius_ratio * kMioRadius)
         << "). Among the configurations that update the force every "
         << "ms, it is within the budget in every case (at most " << Fmt("%.3g", p.worst_cost)
         << " us per simulated ms), on the force-error front in " << p.fronts << " of " << cases.size()
         << " cases, and never less accurate than the current default (its force RMS error is "
         << Fmt("%.2g", p.best_ratio) << " to " << Fmt("%.2g", p.worst_ratio) << " times the current default's).";
      std::printf("proposal: %s (front in %d of %zu cases, at most %.3g us/ms, error %.2g..%.2g x the default's)\n",
                  ConfigLabel(p.config).c_str(), p.fronts, cases.size(), p.worst_cost, p.best_ratio, p.worst_ratio);
    } else {
      md << "\n\nNo configuration measured in every case is within the budget everywhere and at least as accurate "
            "as the default everywhere: no single replacement is proposed.";
    }
  }
  md << "\n\nWhat the verdict rests on: the errors are deterministic, the run times are measured, so a verdict "
        "can flip with timing noise. Per case, the default's errors and the fastest configuration at least as "
        "accurate:\n";
  std::printf("what the verdict rests on (errors are deterministic, run times are not):\n");
  for (const CaseResult& c : cases) {
    const std::string margin = VerdictMargin(c, o.default_config);
    md << "- " << margin << ";\n";
    std::printf("  %s\n", margin.c_str());
  }
  md << "\n" << WindowNote(cases, o.default_config);
  md << "\n\nAll figures: error-vs-runtime.csv (one row per case and configuration).\n";
  for (const CaseResult& c : cases) WriteCaseSection(md, c, o);
  std::printf("\ndefault %s on the force-error front in %d of %zu cases\n", ConfigLabel(o.default_config).c_str(),
              on_front, cases.size());
  for (const auto& [label, entry] : beaters)
    std::printf("  dominated by %s in %d case(s)\n", label.c_str(), entry.first);
  if (!md) {
    *error = "cannot write error-vs-runtime.md in " + o.out_dir;
    return false;
  }
  return true;
}

}  // namespace idms::bench
