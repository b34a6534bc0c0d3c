// `idms-sim stability`: eigenvalues and spectral radius of the haptic window (thesis 4.2) for an
// integrator, and `--sweep` root loci as CSV + PNG like figures 4-3 to 4-6.
#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "command.h"
#include "idms/sim/haptic_window.h"
#include "idms/sim/step.h"
#include "plot.h"

namespace idms::tool {
namespace {

constexpr char kCommand[] = "stability";

struct StabilityArgs {
  HapticWindowParams params;  // defaults: the thesis's nominal values
  std::string integrator = "euler";
  bool json = false;
  std::vector<std::string> sweep;  // P FROM TO
  std::string out;
  int steps = 201;
};

// The parameter P of `--sweep P ...`, as the figures of section 4.2 vary them.
struct SweepParam {
  const char* name;
  const char* figure;
  double HapticWindowParams::*field;
  bool zero_allowed;
};
constexpr SweepParam kSweepParams[] = {
    {"k", "4-3", &HapticWindowParams::k, true},
    {"m", "4-4", &HapticWindowParams::m, false},
    {"b", "4-5", &HapticWindowParams::b, true},
    {"dt", "4-6", &HapticWindowParams::dt_s, false},
};

std::string Num(double value) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", value);
  return buf;
}

// "" when `value` is allowed for parameter `name`, else what is wrong with it.
std::string CheckValue(const char* name, double value, bool zero_allowed) {
  if (!std::isfinite(value)) return std::string("--") + name + " must be a finite number (got " + Num(value) + ")";
  if (zero_allowed && value < 0) return std::string("--") + name + " must be >= 0 (got " + Num(value) + ")";
  if (!zero_allowed && value <= 0) return std::string("--") + name + " must be > 0 (got " + Num(value) + ")";
  return "";
}

void ValidateParams(const HapticWindowParams& p) {
  for (const SweepParam& sp : kSweepParams) {
    const std::string problem = CheckValue(sp.name, p.*sp.field, sp.zero_allowed);
    if (!problem.empty()) Fail(kCommand, problem);
  }
  // Parameters whose ratios overflow (k / m beyond double range) are rejected, not analysed.
  if (!HapticWindowA(p).allFinite()) Fail(kCommand, "k / m or b / m overflows a double; use smaller ratios");
}

nlohmann::json Pairs(const std::vector<std::complex<double>>& values) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& v : values) out.push_back({v.real(), v.imag()});
  return out;
}

std::string Complex(const std::complex<double>& v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%15.9g %c %.9gi", v.real(), v.imag() < 0 ? '-' : '+', std::abs(v.imag()));
  return buf;
}

// One system: eigenvalues, radius, verdict; plus the step limits as extra text lines.
void RunPoint(const StabilityArgs& args, Integrator integrator) {
  const HapticWindowParams& p = args.params;
  const StabilityReport report = AnalyzeHapticWindow(p, integrator);
  if (args.json) {
    PrintJson({{"integrator", IntegratorName(integrator)},
               {"eigenvalues", Pairs(report.discrete)},
               {"continuous_eigenvalues", Pairs(report.continuous)},
               {"spectral_radius", report.spectral_radius},
               {"stable", report.stable}});
    return;
  }
  std::cout << "haptic window (thesis fig. 4-2, eq. 4.17): k = " << Num(p.k) << ", b = " << Num(p.b)
            << ", m = " << Num(p.m) << ", dt = " << Num(p.dt_s) << " s, integrator " << IntegratorName(integrator)
            << "\ncontinuous eigenvalues of A (1/s):\n";
  for (const auto& v : report.continuous) std::cout << "  " << Complex(v) << "\n";
  std::cout << "discrete eigenvalues of A_z (z-plane):              |z|\n";
  for (const auto& v : report.discrete) std::cout << "  " << Complex(v) << "  " << Num(std::abs(v)) << "\n";
  std::cout << "spectral radius " << Num(report.spectral_radius) << ": " << (report.stable ? "stable" : "NOT stable")
            << " (stable means < 1 - " << kMarginalTol << ")\n";
  // How far dt could go at these k, b, m: the exact edge, and what stability.h would predict.
  const double limit = StabilityLimitDt(HapticWindowA(p), integrator, 1e3);
  std::cout << "largest stable dt (bisection on the spectral radius): "
            << (std::isinf(limit) ? std::string("none up to 1000 s") : Num(limit) + " s") << "\n";
  if (const auto gershgorin = GershgorinStableDt(p, integrator)) {
    std::cout << "Gershgorin prediction (stability.h): dt <= " << Num(*gershgorin) << " s\n";
  }
}

nlohmann::json EdgesJson(const std::vector<StabilityEdge>& edges) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& e : edges) out.push_back({{"value", e.value}, {"stable_above", e.stable_above}});
  return out;
}

std::string EdgesText(const std::vector<StabilityEdge>& edges, const char* name, bool stable_at_from) {
  if (edges.empty()) return stable_at_from ? "stable over the whole range" : "unstable over the whole range";
  std::string text;
  for (const auto& e : edges) {
    text += (text.empty() ? "" : "; ") + std::string(e.stable_above ? "enters" : "leaves") + " the unit circle at " +
            name + " = " + Num(e.value);
  }
  return text;
}

// A validated sweep: parameter, range, grid, the fixed values of the others and the scheme.
struct Sweep {
  const SweepParam* param = nullptr;
  double from = 0, to = 0;
  int steps = 0;
  HapticWindowParams base;
  Integrator integrator = Integrator::kExplicitEuler;

  HapticWindowParams At(double value) const {
    HapticWindowParams p = base;
    p.*(param->field) = value;
    return p;
  }
  bool ExactStable(double value) const { return AnalyzeHapticWindow(At(value), integrator).stable; }
  // stability.h's verdict, for the schemes it covers (check GershgorinStableDt first).
  bool GershgorinStable(double value) const { return At(value).dt_s < *GershgorinStableDt(At(value), integrator); }
};

// Parses the three words of --sweep; fails with a message naming the bad one.
Sweep ParseSweep(const StabilityArgs& args, Integrator integrator) {
  Sweep sweep{.steps = args.steps, .base = args.params, .integrator = integrator};
  for (const SweepParam& sp : kSweepParams) {
    if (args.sweep[0] == sp.name) sweep.param = &sp;
  }
  if (!sweep.param) Fail(kCommand, "--sweep parameter must be one of k, b, m, dt (got '" + args.sweep[0] + "')");
  const auto number = [&](const std::string& word, const char* what) {
    size_t used = 0;
    double value = 0;
    try {
      value = std::stod(word, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != word.size()) {
      Fail(kCommand, std::string("--sweep ") + what + " '" + word + "' is not a number");
    }
    const std::string problem = CheckValue(sweep.param->name, value, sweep.param->zero_allowed);
    if (!problem.empty()) Fail(kCommand, std::string("--sweep ") + what + ": " + problem);
    return value;
  };
  sweep.from = number(args.sweep[1], "FROM");
  sweep.to = number(args.sweep[2], "TO");
  if (!(sweep.from < sweep.to)) {
    Fail(kCommand, "--sweep needs FROM < TO (got " + args.sweep[1] + " and " + args.sweep[2] + ")");
  }
  if (args.steps < 2) Fail(kCommand, "--steps must be >= 2 (got " + std::to_string(args.steps) + ")");
  if (args.out.empty()) Fail(kCommand, "--sweep needs --out PREFIX");
  ValidateParams(sweep.At(sweep.from));
  ValidateParams(sweep.At(sweep.to));
  return sweep;
}

// A row per (value, eigenvalue); the first column is named after the swept parameter.
// Returns the largest spectral radius met.
double WriteLocusCsv(const Sweep& sweep, const std::string& csv_path) {
  std::ofstream csv(csv_path);
  if (!csv) Fail(kCommand, "cannot write " + csv_path);
  csv << sweep.param->name << ",index,re,im,abs_z,spectral_radius,stable\n";
  double max_radius = 0;
  for (int i = 0; i < sweep.steps; ++i) {
    const double value = sweep.from + (sweep.to - sweep.from) * i / (sweep.steps - 1);
    const StabilityReport r = AnalyzeHapticWindow(sweep.At(value), sweep.integrator);
    max_radius = std::max(max_radius, r.spectral_radius);
    for (size_t j = 0; j < r.discrete.size(); ++j) {
      const auto& z = r.discrete[j];
      csv << Num(value) << "," << j << "," << Num(z.real()) << "," << Num(z.imag()) << "," << Num(std::abs(z)) << ","
          << Num(r.spectral_radius) << "," << (r.stable ? 1 : 0) << "\n";
    }
  }
  csv.close();
  if (!csv) Fail(kCommand, "error while writing " + csv_path);
  return max_radius;
}

std::string FixedValues(const HapticWindowParams& p) {
  return "k = " + Num(p.k) + ", b = " + Num(p.b) + ", m = " + Num(p.m) + ", T = " + Num(p.dt_s) + " s";
}

// The z-plane picture of figures 4-3 to 4-6: unit circle, the poles coloured by the swept
// value, 'x' at the nominal poles.
bool PlotLocus(const Sweep& sweep, const std::string& csv_path, const std::string& png_path, std::string* error) {
  PlotSpec spec;
  spec.title = "Z-plane root locus of the haptic window (cf. thesis fig. " + std::string(sweep.param->figure) +
               "): " + Num(sweep.from) + " < " + sweep.param->name + " < " + Num(sweep.to) + ", " +
               IntegratorName(sweep.integrator);
  spec.x_label = "Re z";
  spec.y_label = "Im z";
  spec.color_label = sweep.param->name;
  spec.equal_aspect = true;
  spec.key = "bottom left box opaque";
  spec.preamble = {"set offsets graph 0.05, graph 0.05, graph 0.05, graph 0.05"};
  PlotSeries circle{.title = "unit circle", .style = "lines", .options = "lc rgb 'black' lw 1.5"};
  for (int i = 0; i <= 360; ++i) {
    const double angle = i * std::numbers::pi / 180;
    circle.points.push_back({std::cos(angle), std::sin(angle)});
  }
  PlotSeries poles{.title = std::string("poles as ") + sweep.param->name + " varies (colour)",
                   .csv_path = csv_path,
                   .x_column = "re",
                   .y_column = "im",
                   .color_column = sweep.param->name,
                   .style = "points",
                   .options = "pt 7 ps 0.6"};
  PlotSeries marks{
      .title = "nominal: " + FixedValues(sweep.base), .style = "points", .options = "pt 2 ps 2.5 lw 2.5 lc rgb 'red'"};
  for (const auto& z : AnalyzeHapticWindow(sweep.base, sweep.integrator).discrete) {
    marks.points.push_back({z.real(), z.imag()});
  }
  spec.series = {circle, poles, marks};
  return PlotPng(spec, png_path, error);
}

// Root locus: PREFIX.csv, PREFIX.png, and where the system crosses the unit circle, exactly
// and as stability.h predicts. A missing PNG fails the command after the CSV and report are out.
void RunSweep(const StabilityArgs& args, Integrator integrator) {
  const Sweep sweep = ParseSweep(args, integrator);
  const std::string csv_path = args.out + ".csv", png_path = args.out + ".png";
  const double max_radius = WriteLocusCsv(sweep, csv_path);

  // Edges on the same grid, refined by bisection.
  const std::vector<StabilityEdge> edges =
      FindStabilityEdges([&](double v) { return sweep.ExactStable(v); }, sweep.from, sweep.to, sweep.steps);
  const bool has_gershgorin = GershgorinStableDt(sweep.base, integrator).has_value();
  std::vector<StabilityEdge> g_edges;
  if (has_gershgorin) {
    g_edges =
        FindStabilityEdges([&](double v) { return sweep.GershgorinStable(v); }, sweep.from, sweep.to, sweep.steps);
  }
  std::string png_error;
  const bool png_ok = PlotLocus(sweep, csv_path, png_path, &png_error);

  // Report: JSON summary or text.
  const char* name = sweep.param->name;
  if (args.json) {
    const HapticWindowParams& p = sweep.base;
    nlohmann::json j = {{"param", name},
                        {"from", sweep.from},
                        {"to", sweep.to},
                        {"steps", sweep.steps},
                        {"integrator", IntegratorName(integrator)},
                        {"nominal", {{"k", p.k}, {"b", p.b}, {"m", p.m}, {"dt", p.dt_s}}},
                        {"stable_at_from", sweep.ExactStable(sweep.from)},
                        {"edges", EdgesJson(edges)},
                        {"gershgorin_edges", has_gershgorin ? EdgesJson(g_edges) : nlohmann::json(nullptr)},
                        {"max_spectral_radius", max_radius},
                        {"csv", csv_path},
                        {"png", png_ok ? nlohmann::json(png_path) : nlohmann::json(nullptr)}};
    if (!png_ok) j["png_error"] = png_error;
    PrintJson(j);
  } else {
    std::cout << "swept " << name << " from " << Num(sweep.from) << " to " << Num(sweep.to) << " (" << sweep.steps
              << " values), integrator " << IntegratorName(integrator) << ", others at " << FixedValues(sweep.base)
              << "\n"
              << "exact (eigenvalues): " << EdgesText(edges, name, sweep.ExactStable(sweep.from))
              << "; max spectral radius " << Num(max_radius) << "\n";
    if (has_gershgorin) {
      std::cout << "Gershgorin prediction (stability.h): "
                << EdgesText(g_edges, name, sweep.GershgorinStable(sweep.from)) << "\n";
    }
    std::cout << "wrote " << csv_path << (png_ok ? " and " + png_path : "") << "\n";
  }
  if (!png_ok) Fail(kCommand, "wrote " + csv_path + " but not " + png_path + ": " + png_error);
}

void Setup(CLI::App& app) {
  auto args = std::make_shared<StabilityArgs>();
  CLI::App* cmd = app.add_subcommand(
      kCommand, "Eigenvalues and spectral radius of the 6th-order haptic window (thesis fig. 4-2, eqs. 4.16-4.18)");
  cmd->add_option("--k", args->params.k, "element stiffness (>= 0)")->capture_default_str();
  cmd->add_option("--b", args->params.b, "element viscosity (>= 0)")->capture_default_str();
  cmd->add_option("--m", args->params.m, "atom mass (> 0)")->capture_default_str();
  cmd->add_option("--dt", args->params.dt_s, "time step T in s (> 0)")->capture_default_str();
  cmd->add_option("--integrator", args->integrator, "euler | symplectic | rk4 | implicit")->capture_default_str();
  cmd->add_flag("--json", args->json, "print one JSON object instead of text");
  cmd->add_option("--sweep", args->sweep, "P FROM TO: vary P (k, b, m or dt) over [FROM, TO], others fixed")
      ->expected(3)
      ->type_name("WORD");
  cmd->add_option("--out", args->out, "with --sweep: write PREFIX.csv and PREFIX.png");
  CLI::Option* steps =
      cmd->add_option("--steps", args->steps, "with --sweep: number of values, ends included")->capture_default_str();
  cmd->callback([args, steps] {
    // Validate everything before computing anything.
    Integrator integrator{};
    if (!ParseIntegratorName(args->integrator, &integrator)) {
      Fail(kCommand, "unknown --integrator '" + args->integrator + "' (expected euler, symplectic, rk4 or implicit)");
    }
    ValidateParams(args->params);
    if (args->sweep.empty()) {
      if (!args->out.empty() || steps->count() > 0) Fail(kCommand, "--out and --steps are only used with --sweep");
      RunPoint(*args, integrator);
    } else {
      RunSweep(*args, integrator);
    }
  });
}

}  // namespace

IDMS_SIM_COMMAND(40, Setup);

}  // namespace idms::tool
