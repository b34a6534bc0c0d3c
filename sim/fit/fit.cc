// The fitter: replays a recorded path through Step and lets Ceres Solver's Levenberg-Marquardt
// minimise the force error over the groups' log scale factors, with central differences (the
// step is deterministic and smooth in its parameters between contact changes; a replay of a 10 s
// palpation on the hex fragment costs ~50 ms because local simulation keeps the tick flat).
#include "fit.h"

#include <ceres/ceres.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>

#include "idms/sim/workspace.h"

namespace idms::fit {
namespace {

bool IsElementGroup(Param p) { return p != Param::kToolK; }
bool IsStiffness(Param p) { return p == Param::kHomeK || p == Param::kSurfaceK || p == Param::kK; }

bool InGroup(const Model& m, Param p, int32_t e) {
  if (p == Param::kK || p == Param::kB) return true;
  const bool home = m.elem_home[e] != 0;
  return (p == Param::kHomeK || p == Param::kHomeB) ? home : !home;
}

// Per element: the part it belongs to (Unknown::part), -1 when there are no regions.
std::vector<int> PartsOf(const Model& m, const std::vector<Region>& regions) {
  std::vector<int> parts(m.num_elems, -1);
  if (regions.empty()) return parts;
  for (int32_t e = 0; e < m.num_elems; ++e) {
    const double* p0 = &m.atom_pos_eq[3 * m.elem_atoms[2 * e]];
    const double* p1 = &m.atom_pos_eq[3 * m.elem_atoms[2 * e + 1]];
    const double mid[3] = {(p0[0] + p1[0]) / 2, (p0[1] + p1[1]) / 2, (p0[2] + p1[2]) / 2};
    int part = static_cast<int>(regions.size());
    for (size_t r = 0; r < regions.size() && part == static_cast<int>(regions.size()); ++r) {
      if (regions[r].Contains(mid)) part = static_cast<int>(r);
    }
    parts[e] = part;
  }
  return parts;
}

bool InUnknown(const Model& m, const Unknown& u, const std::vector<int>& parts, int32_t e) {
  return InGroup(m, u.param, e) && (u.part < 0 || parts[e] == u.part);
}

// The unknown's elements' values times `scale`, without re-deriving (tool_k: nothing).
void ScaleValues(Model& m, const Unknown& u, const std::vector<int>& parts, double scale) {
  if (!IsElementGroup(u.param)) return;
  std::vector<double>& v = IsStiffness(u.param) ? m.elem_k : m.elem_b;
  for (int32_t e = 0; e < m.num_elems; ++e) {
    if (InUnknown(m, u, parts, e)) v[e] *= scale;
  }
}

double UnknownMean(const Model& m, const Unknown& u, const std::vector<int>& parts) {
  if (!IsElementGroup(u.param)) return 0;
  const std::vector<double>& v = IsStiffness(u.param) ? m.elem_k : m.elem_b;
  double sum = 0;
  int32_t n = 0;
  for (int32_t e = 0; e < m.num_elems; ++e) {
    if (InUnknown(m, u, parts, e)) sum += v[e], ++n;
  }
  return n > 0 ? sum / n : 0;
}

std::string UnknownName(const Unknown& u, const std::vector<Region>& regions) {
  std::string name = ParamName(u.param);
  if (u.part >= 0) name += "@" + (u.part < static_cast<int>(regions.size()) ? regions[u.part].name : "rest");
  return name;
}

// The model and the tool with every factor applied.
Model Scaled(const Model& base, const FitOptions& o, const std::vector<Unknown>& unknowns,
             const std::vector<int>& parts, const double* log_scale, ToolCommand* tool) {
  Model m = base;
  *tool = o.tool;
  for (size_t i = 0; i < unknowns.size(); ++i) {
    ScaleValues(m, unknowns[i], parts, std::exp(log_scale[i]));
    if (unknowns[i].param == Param::kToolK) tool->stiffness *= std::exp(log_scale[i]);
  }
  FinalizeModel(m);
  return m;
}

// Whether FitOptions::stop has been set.
bool Stopped(const FitOptions& o) { return o.stop != nullptr && o.stop->load(std::memory_order_relaxed); }

// The residuals: simulated minus measured force at the compared ticks, 3 per sample.
struct ForceResidual {
  const Model* model;
  const Trace* trace;
  const FitOptions* options;
  const std::vector<Unknown>* unknowns;
  const std::vector<int>* parts;
  const std::vector<std::array<double, 3>>* measured;
  int* replays;
  // While the solver runs, a stop fails the evaluation at once; the covariance's evaluations run
  // to the end (Ceres 2.1's dense covariance went on to an SVD of what a failed one left, and
  // crashed in it).
  const bool* solving;
  bool operator()(double const* const* x, double* residuals) const {
    if (*solving && Stopped(*options)) return false;
    ToolCommand tool;
    const Model m = Scaled(*model, *options, *unknowns, *parts, x[0], &tool);
    const std::vector<std::array<double, 3>> f = Replay(m, *trace, options->step, tool, options->stride);
    ++*replays;
    for (size_t i = 0; i < f.size(); ++i) {
      for (int c = 0; c < 3; ++c) {
        residuals[3 * i + c] = f[i][c] - (*measured)[i][c];
        if (!std::isfinite(residuals[3 * i + c])) return false;  // the solver backs off
      }
    }
    return true;
  }
};

// The lump's profile over the map: the background b inside an isotropic step of height h = R - b
// at radius rho around (cx, cy), smoothed over a width w (a logistic in the distance). x: cx, cy,
// log rho, log w, log h.
struct LumpProfile {
  double x, y, scale, background;
  template <typename T>
  bool operator()(const T* p, T* residual) const {
    const T dx = T(x) - p[0], dy = T(y) - p[1];
    const T d = sqrt(dx * dx + dy * dy + T(1e-18));  // smooth at the centre
    const T z = (exp(p[2]) - d) / exp(p[3]);
    residual[0] = T(background) + exp(p[4]) / (T(1) + exp(-z)) - T(scale);
    return true;
  }
};

double Magnitude(const std::array<double, 3>& f) { return std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]); }

double Median(std::vector<double> x) {
  std::sort(x.begin(), x.end());
  const size_t n = x.size();
  return n % 2 ? x[n / 2] : 0.5 * (x[n / 2 - 1] + x[n / 2]);
}

// The presses of a recording, [first, end) ticks: runs of ticks above 5% of the largest force
// (well above a 1% noise), with gaps shorter than 50 ms bridged (noise at the edges) and runs
// shorter than 20 ms dropped.
std::vector<std::array<int64_t, 2>> FindPresses(const Trace& trace, double peak) {
  const int64_t ticks = static_cast<int64_t>(trace.force.size());
  const double threshold = 0.05 * peak;
  const int64_t bridge = std::llround(0.05 / trace.dt_s), shortest = std::llround(0.02 / trace.dt_s);
  std::vector<std::array<int64_t, 2>> presses;
  for (int64_t n = 0; n < ticks; ++n) {
    if (!(Magnitude(trace.force[n]) > threshold)) continue;
    if (!presses.empty() && n - presses.back()[1] <= bridge) {
      presses.back()[1] = n + 1;
    } else {
      presses.push_back({n, n + 1});
    }
  }
  std::erase_if(presses, [&](const auto& p) { return p[1] - p[0] < shortest; });
  return presses;
}

// The lump of a map whose largest excess over the background is points[top]: a first guess from
// the presses above half that excess (their excess-weighted mean and extent), then the profile
// fitted to every press, so the centre comes from the lump's edges, not from where the grid
// happened to fall inside it. The first guess stands if the profile's fit fails.
Lump FitLump(const std::vector<MapPoint>& points, double background, size_t top) {
  Lump lump;
  lump.found = true;
  const double excess = points[top].scale - background;
  double wsum = 0, cx = 0, cy = 0;
  for (const MapPoint& p : points) {
    const double w = p.scale - background;
    if (w < 0.5 * excess) continue;
    cx += w * p.x, cy += w * p.y, wsum += w;
    ++lump.presses;
  }
  cx /= wsum, cy /= wsum;
  double rho = 0, spacing = std::numeric_limits<double>::infinity();
  for (const MapPoint& p : points) {
    if (p.scale - background >= 0.5 * excess) rho = std::max(rho, std::hypot(p.x - cx, p.y - cy));
    for (const MapPoint& q : points) {
      const double d = std::hypot(p.x - q.x, p.y - q.y);
      if (d > 0) spacing = std::min(spacing, d);
    }
  }
  rho += 0.5 * spacing;

  // The profile.
  double x[5] = {cx, cy, std::log(rho), std::log(0.25 * rho), std::log(excess)};
  ceres::Problem problem;
  for (const MapPoint& p : points) {
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<LumpProfile, 1, 5>(new LumpProfile{p.x, p.y, p.scale, background}), nullptr, x);
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 100;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  const double height = std::exp(x[4]);
  const double ratio = (background + height) / background;
  if (!summary.IsSolutionUsable() || !std::isfinite(ratio)) {
    lump.x = cx, lump.y = cy, lump.radius = rho;
    lump.ratio = points[top].scale / background;
    return lump;
  }
  lump.x = x[0], lump.y = x[1], lump.radius = std::exp(x[2]), lump.ratio = ratio;

  // Its uncertainty: the covariance (a pseudo-inverse: a profile with a flat edge leaves the width
  // loose, not the rest) scaled by the residuals' variance.
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = -1;
  ceres::Covariance covariance(co);
  std::vector<std::pair<const double*, const double*>> blocks = {{x, x}};
  double cov[25] = {};
  if (covariance.Compute(blocks, &problem) && covariance.GetCovarianceBlock(x, x, cov)) {
    const double s2 = 2 * summary.final_cost / std::max(1.0, static_cast<double>(points.size()) - 5);
    lump.xy_sigma = std::sqrt(std::max(0.0, (cov[0] + cov[6]) * s2));
    lump.ratio_sigma = height / background * std::sqrt(std::max(0.0, cov[24] * s2));
  }
  return lump;
}

}  // namespace

const char* ParamName(Param p) {
  switch (p) {
    case Param::kHomeK:
      return "home_k";
    case Param::kHomeB:
      return "home_b";
    case Param::kSurfaceK:
      return "surface_k";
    case Param::kSurfaceB:
      return "surface_b";
    case Param::kToolK:
      return "tool_k";
    case Param::kK:
      return "k";
    case Param::kB:
      return "b";
  }
  return "?";
}

bool ParseParams(const std::string& list, std::vector<Param>* params, std::string* error) {
  params->clear();
  std::stringstream in(list);
  std::string item;
  while (std::getline(in, item, ',')) {
    Param p{};
    bool found = false;
    for (int i = 0; i < kNumParams && !found; ++i) {
      p = static_cast<Param>(i);
      found = item == ParamName(p);
    }
    if (!found || std::find(params->begin(), params->end(), p) != params->end()) {
      *error = "--params: bad item '" + item +
               "' (expected each of home_k, home_b, surface_k, surface_b, k, b, tool_k at most once)";
      return false;
    }
    params->push_back(p);
  }
  if (params->empty()) {
    *error = "--params: name at least one of home_k, home_b, surface_k, surface_b, k, b, tool_k";
    return false;
  }
  auto has = [&](Param q) { return std::find(params->begin(), params->end(), q) != params->end(); };
  for (Param whole : {Param::kK, Param::kB}) {
    const Param home = whole == Param::kK ? Param::kHomeK : Param::kHomeB;
    const Param surface = whole == Param::kK ? Param::kSurfaceK : Param::kSurfaceB;
    if (has(whole) && (has(home) || has(surface))) {
      *error = std::string("--params: ") + ParamName(whole) + " (every element) overlaps " +
               ParamName(has(home) ? home : surface) + "; fit one or the other";
      return false;
    }
  }
  return true;
}

double GroupMean(const Model& m, Param p) { return UnknownMean(m, Unknown{p, -1}, {}); }

void ScaleGroup(Model& m, Param p, double scale) {
  ScaleValues(m, Unknown{p, -1}, {}, scale);
  FinalizeModel(m);
}

bool Region::Contains(const double* p) const {
  if (shape == Shape::kSphere) {
    const double dx = p[0] - v[0], dy = p[1] - v[1], dz = p[2] - v[2];
    return dx * dx + dy * dy + dz * dz <= v[3] * v[3];
  }
  for (int c = 0; c < 3; ++c) {
    if (p[c] < std::min(v[c], v[c + 3]) || p[c] > std::max(v[c], v[c + 3])) return false;
  }
  return true;
}

bool ParseRegion(const std::string& spec, int index, Region* region, std::string* error) {
  *region = {};
  std::string body = spec;
  const size_t eq = spec.find('=');
  region->name = "region" + std::to_string(index + 1);
  if (eq != std::string::npos) {
    region->name = spec.substr(0, eq);
    body = spec.substr(eq + 1);
    const bool word = !region->name.empty() && std::all_of(region->name.begin(), region->name.end(), [](char c) {
      return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
    });
    if (!word || region->name == "rest") {
      *error = "--region '" + spec + "': the name must be letters, digits, _ or - (and not 'rest')";
      return false;
    }
  }
  const size_t colon = body.find(':');
  const std::string shape = body.substr(0, colon);
  int want = 0;
  if (shape == "sphere") region->shape = Region::Shape::kSphere, want = 4;
  if (shape == "box") region->shape = Region::Shape::kBox, want = 6;
  if (want == 0 || colon == std::string::npos) {
    *error = "--region '" + spec + "': expected [NAME=]sphere:cx,cy,cz,r or [NAME=]box:x0,y0,z0,x1,y1,z1";
    return false;
  }
  std::stringstream in(body.substr(colon + 1));
  std::string item;
  int n = 0;
  while (std::getline(in, item, ',')) {
    char* end = nullptr;
    const double value = std::strtod(item.c_str(), &end);
    if (n >= want || item.empty() || *end != '\0' || !std::isfinite(value)) {
      *error = "--region '" + spec + "': " + shape + " takes " + std::to_string(want) + " numbers, value " +
               std::to_string(n + 1) + " ('" + item + "') is not one";
      return false;
    }
    region->v[n++] = value;
  }
  if (n != want) {
    *error =
        "--region '" + spec + "': " + shape + " takes " + std::to_string(want) + " numbers, got " + std::to_string(n);
    return false;
  }
  if (region->shape == Region::Shape::kSphere && !(region->v[3] > 0)) {
    *error = "--region '" + spec + "': the radius must be > 0";
    return false;
  }
  return true;
}

bool ReadTraceCsv(const std::string& path, Trace* trace, std::string* error) {
  std::ifstream in(path);
  if (!in) {
    *error = path + ": cannot read";
    return false;
  }
  std::string line;
  if (!std::getline(in, line) || line.rfind("t,x,y,z,fx,fy,fz", 0) != 0) {
    *error = path + ":1: expected the header of idms-sim run --csv (t,x,y,z,fx,fy,fz,...)";
    return false;
  }
  *trace = {};
  // The tweezers' column, where the header names one.
  int closed_column = -1, columns = 0;
  {
    std::stringstream names(line);
    for (std::string name; std::getline(names, name, ','); ++columns) {
      if (name == "closed") closed_column = columns;
    }
  }
  double t_first = 0, t_last = 0;
  for (int number = 2; std::getline(in, line); ++number) {
    double v[7];
    std::stringstream fields(line);
    std::string field;
    if (closed_column >= 0) {
      // The row's closed value: 0 or 1.
      std::stringstream all(line);
      std::string value;
      for (int i = 0; i <= closed_column; ++i) {
        if (!std::getline(all, value, ',')) value.clear();
      }
      if (value != "0" && value != "1") {
        *error = path + ":" + std::to_string(number) + ": column " + std::to_string(closed_column + 1) +
                 " (closed) is not 0 or 1";
        return false;
      }
      trace->closed.push_back(value == "1" ? 1 : 0);
    }
    for (int i = 0; i < 7; ++i) {
      char* end = nullptr;
      if (!std::getline(fields, field, ',') || (v[i] = std::strtod(field.c_str(), &end), *end != '\0') ||
          field.empty() || !std::isfinite(v[i])) {
        *error = path + ":" + std::to_string(number) + ": column " + std::to_string(i + 1) + " is not a finite number";
        return false;
      }
    }
    const size_t n = trace->pos.size();
    if (n == 0) t_first = v[0];
    if (n == 1) trace->dt_s = v[0] - t_first;
    if (n >= 1 && !(std::abs(v[0] - t_last - trace->dt_s) <= 1e-6)) {
      *error = path + ":" + std::to_string(number) + ": t = " + std::to_string(v[0]) + " breaks the uniform tick of " +
               std::to_string(trace->dt_s) + " s";
      return false;
    }
    t_last = v[0];
    trace->pos.push_back({v[1], v[2], v[3]});
    trace->force.push_back({v[4], v[5], v[6]});
  }
  if (trace->pos.size() < 2 || !(trace->dt_s > 0)) {
    *error = path + ": fewer than two ticks";
    return false;
  }
  if (std::abs(t_first - trace->dt_s) > 1e-6) {
    *error = path + ":2: the first row must be the first tick (t = dt), got t = " + std::to_string(t_first);
    return false;
  }
  return true;
}

std::vector<std::array<double, 3>> Replay(const Model& model, const Trace& trace, const StepOptions& step,
                                          const ToolCommand& tool_in, int stride) {
  StepOptions options = step;
  options.dt_s = trace.dt_s;
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, options);
  ToolInput input;
  input.num_tools = 1;
  ToolCommand tool = tool_in;
  std::vector<std::array<double, 3>> out;
  out.reserve(trace.pos.size() / std::max(1, stride) + 1);
  for (size_t n = 0; n < trace.pos.size(); ++n) {
    std::copy(trace.pos[n].begin(), trace.pos[n].end(), tool.pos);
    tool.closed = n < trace.closed.size() && trace.closed[n] != 0;
    input.tools[0] = tool;
    const StepReport report = Step(model, state, ws, input);
    if ((n + 1) % stride == 0)
      out.push_back({report.tools[0].force[0], report.tools[0].force[1], report.tools[0].force[2]});
  }
  return out;
}

namespace {

// FitOptions::progress after every solver iteration; its false, or a stop, ends the solve
// (USER_FAILURE).
class ProgressCallback final : public ceres::IterationCallback {
 public:
  ProgressCallback(const FitOptions& options, const int* replays, size_t samples)
      : options_(options), replays_(replays), samples_(static_cast<double>(samples)) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    const FitProgress p{.iteration = s.iteration, .replays = *replays_, .rms = std::sqrt(2 * s.cost / samples_)};
    const bool go_on = !options_.progress || options_.progress(p);
    return go_on && !Stopped(options_) ? ceres::SOLVER_CONTINUE : ceres::SOLVER_ABORT;
  }

 private:
  const FitOptions& options_;
  const int* replays_;
  double samples_;
};

}  // namespace

FitResult Fit(const Model& model, const Trace& trace, const FitOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  FitResult r;
  const std::vector<int> parts = PartsOf(model, options.regions);
  for (Param param : options.params) {
    if (!IsElementGroup(param) || options.regions.empty()) {
      r.unknowns.push_back({param, -1});
      continue;
    }
    for (int part = 0; part <= static_cast<int>(options.regions.size()); ++part) r.unknowns.push_back({param, part});
  }
  for (const Unknown& u : r.unknowns) r.names.push_back(UnknownName(u, options.regions));
  const size_t p = r.unknowns.size();
  if (p == 0 || options.stride < 1) {
    r.message = "nothing to fit (no parameters, or a stride below 1)";
    return r;
  }
  for (size_t i = 0; i < p; ++i) {
    const Param param = r.unknowns[i].param;
    if (param == Param::kToolK && !(options.tool.stiffness > 0 && std::isfinite(options.tool.stiffness))) {
      r.message = "tool_k: the tool's stiffness must be a finite number > 0 to scale";
      return r;
    }
    if (IsElementGroup(param) && !(UnknownMean(model, r.unknowns[i], parts) > 0)) {
      const char* group = param == Param::kHomeK || param == Param::kHomeB         ? "home"
                          : param == Param::kSurfaceK || param == Param::kSurfaceB ? "surface"
                                                                                   : "";
      const int part = r.unknowns[i].part;
      const std::string where = part < 0 ? ""
                                : part < static_cast<int>(options.regions.size())
                                    ? " inside region " + options.regions[part].name
                                    : " outside every region";
      r.message = r.names[i] + ": the model has no " + group + (*group ? " " : "") +
                  "elements with a nonzero value to scale" + where;
      return r;
    }
  }
  std::vector<std::array<double, 3>> measured;
  for (size_t n = 0; n < trace.force.size(); ++n) {
    if ((n + 1) % options.stride == 0) measured.push_back(trace.force[n]);
    const auto& f = trace.force[n];
    r.peak_force = std::max(r.peak_force, Magnitude(f));
  }
  r.samples = static_cast<int>(measured.size());
  if (!(r.peak_force > 1e-9)) {
    r.message = "the recording never touches the model (its largest force is " + std::to_string(r.peak_force) +
                "): there is nothing to fit";
    return r;
  }
  if (measured.size() * 3 <= p) {
    r.message = "too few samples (" + std::to_string(measured.size()) + ") for " + std::to_string(p) + " parameters";
    return r;
  }

  std::vector<double> x(p, 0.0);  // log scale factors, starting at the typed-in values
  bool solving = true;
  auto* cost = new ceres::DynamicNumericDiffCostFunction<ForceResidual, ceres::CENTRAL>(
      new ForceResidual{&model, &trace, &options, &r.unknowns, &parts, &measured, &r.replays, &solving});
  cost->AddParameterBlock(static_cast<int>(p));
  cost->SetNumResiduals(static_cast<int>(3 * measured.size()));
  ceres::Problem problem;
  problem.AddResidualBlock(cost, nullptr, x.data());
  ceres::Solver::Options so;
  ProgressCallback callback(options, &r.replays, measured.size());
  if (options.progress || options.stop != nullptr) {
    so.callbacks.push_back(&callback);
    so.update_state_every_iteration = false;
  }
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = options.max_iterations;
  so.function_tolerance = options.function_tolerance;
  so.parameter_tolerance = 1e-10;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  r.iterations = static_cast<int>(summary.iterations.size());
  r.rms_before = std::sqrt(2 * summary.initial_cost / static_cast<double>(measured.size()));
  r.rms_after = std::sqrt(2 * summary.final_cost / static_cast<double>(measured.size()));
  if (summary.termination_type == ceres::USER_FAILURE || Stopped(options)) {
    r.message = "stopped";
    return r;
  }
  if (!summary.IsSolutionUsable()) {
    r.message = "the solver found no usable solution: " + summary.message;
    return r;
  }

  // Uncertainty: the covariance of the log factors, scaled by the residuals' variance (Ceres
  // assumes unit variance), to first order the factor's relative sigma.
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = 0;  // a rank-deficient Jacobian fails Compute: the parameter is undetermined
  ceres::Covariance covariance(co);
  std::vector<std::pair<const double*, const double*>> blocks = {{x.data(), x.data()}};
  std::vector<double> cov(p * p, 0.0);
  solving = false;
  if (!covariance.Compute(blocks, &problem) || !covariance.GetCovarianceBlock(x.data(), x.data(), cov.data())) {
    r.message =
        "the recording does not determine every parameter asked for (a singular Jacobian: a damping fitted "
        "from a path that never moves, or a group the tool never loads); fit fewer";
    return r;
  }
  const double dof = static_cast<double>(3 * measured.size() - p);
  const double s2 = 2 * summary.final_cost / dof;
  for (size_t i = 0; i < p; ++i) {
    const double scale = std::exp(x[i]);
    const double sigma = scale * std::sqrt(std::max(0.0, cov[i * p + i] * s2));
    const double mean =
        IsElementGroup(r.unknowns[i].param) ? UnknownMean(model, r.unknowns[i], parts) : options.tool.stiffness;
    r.scale.push_back(scale);
    r.scale_sigma.push_back(sigma);
    r.value.push_back(mean * scale);
    r.value_sigma.push_back(mean * sigma);
  }
  r.fitted = Scaled(model, options, r.unknowns, parts, x.data(), &r.fitted_tool);
  r.fitted_force = Replay(r.fitted, trace, options.step, r.fitted_tool, options.stride);
  r.ok = true;
  r.message = summary.BriefReport();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

MapResult FitMap(const Model& model, const Trace& trace, const FitOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  MapResult r;
  const int64_t ticks = static_cast<int64_t>(trace.force.size());
  double peak = 0;
  for (const auto& f : trace.force) peak = std::max(peak, Magnitude(f));
  if (!(peak > 1e-9)) {
    r.message = "the recording never touches the model: there is nothing to map";
    return r;
  }
  const std::vector<std::array<int64_t, 2>> presses = FindPresses(trace, peak);
  if (presses.size() < 3) {
    r.message = "the recording holds " + std::to_string(presses.size()) +
                " separate presses; a map needs at least 3 (a scan: idms-sim run --script scan)";
    return r;
  }

  // Each press on its own: one factor on every element's k. A map needs each factor to a fraction
  // of a percent, not to the last digit: a few replays per press fewer (a 7 x 7 scan of the 40 x 40
  // slab: ~29 replays a press at 1e-12).
  FitOptions one = options;
  one.params = {Param::kK};
  one.regions.clear();
  one.function_tolerance = std::max(options.function_tolerance, 1e-7);
  one.progress = nullptr;
  for (size_t i = 0; i < presses.size(); ++i) {
    if (Stopped(options) ||
        (options.progress && !options.progress({.replays = r.replays,
                                                .presses_done = static_cast<int>(i),
                                                .presses_total = static_cast<int>(presses.size())}))) {
      r.message = "stopped";
      return r;
    }
    // The ticks from halfway after the last press to halfway before the next, replayed from rest.
    const int64_t t0 = i == 0 ? 0 : (presses[i - 1][1] + presses[i][0]) / 2;
    const int64_t t1 = i + 1 == presses.size() ? ticks : (presses[i][1] + presses[i + 1][0]) / 2;
    Trace slice;
    slice.dt_s = trace.dt_s;
    slice.pos.assign(trace.pos.begin() + t0, trace.pos.begin() + t1);
    slice.force.assign(trace.force.begin() + t0, trace.force.begin() + t1);
    if (!trace.closed.empty()) slice.closed.assign(trace.closed.begin() + t0, trace.closed.begin() + t1);
    const FitResult f = Fit(model, slice, one);
    r.replays += f.replays;
    if (!f.ok) {
      r.message = "the press at t = " + std::to_string(static_cast<double>(presses[i][0] + 1) * trace.dt_s) +
                  " s: " + f.message;
      return r;
    }
    int64_t top = presses[i][0];
    for (int64_t n = presses[i][0]; n < presses[i][1]; ++n) {
      if (Magnitude(trace.force[n]) > Magnitude(trace.force[top])) top = n;
    }
    r.points.push_back({.x = trace.pos[top][0],
                        .y = trace.pos[top][1],
                        .scale = f.scale[0],
                        .sigma = f.scale_sigma[0],
                        .peak_force = Magnitude(trace.force[top]),
                        .tick0 = t0,
                        .tick1 = t1});
  }

  // The background and its scatter, robustly (a lump's presses must not raise them), and the lump.
  std::vector<double> v;
  for (const MapPoint& p : r.points) v.push_back(p.scale);
  r.background = Median(v);
  for (double& x : v) x = std::abs(x - r.background);
  r.spread = 1.4826 * Median(v);
  size_t top = 0;
  for (size_t i = 0; i < r.points.size(); ++i) {
    if (r.points[i].scale > r.points[top].scale) top = i;
  }
  if (r.points[top].scale - r.background > std::max(0.25 * r.background, 5 * r.spread)) {
    r.lump = FitLump(r.points, r.background, top);
  }
  r.ok = true;
  r.message = std::to_string(r.points.size()) + " presses mapped";
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

Trace ScriptedTrace(const Model& truth, Script script, double noise, uint32_t seed, double tool_stiffness) {
  Trace t;
  t.dt_s = 1e-3;
  const ScriptGeometry g = MakeScriptGeometry(truth, 1.5);
  const int64_t ticks = std::llround(ScriptDuration(script) / t.dt_s);
  const bool tweezers = script == Script::kPluck;
  for (int64_t n = 0; n < ticks; ++n) {
    const ScriptSample s = SampleScript(script, g, static_cast<double>(n + 1) * t.dt_s);
    t.pos.push_back({s.pos[0], s.pos[1], s.pos[2]});
    if (tweezers) t.closed.push_back(s.closed ? 1 : 0);
  }
  ToolCommand tool;
  tool.kind = tweezers ? ToolKind::kTweezers : ToolKind::kSphere;
  tool.stiffness = tool_stiffness;
  t.force = Replay(truth, t, StepOptions{}, tool, 1);
  double peak = 0;
  for (const auto& f : t.force) peak = std::max(peak, Magnitude(f));
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, noise * peak);
  for (auto& f : t.force) {
    for (double& c : f) c += normal(rng);
  }
  return t;
}

}  // namespace idms::fit
