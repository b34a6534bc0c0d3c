// The fitter: replays a recorded path through Step and lets Ceres Solver's Levenberg-Marquardt
// minimise the force error over the groups' log scale factors, with central differences (the
// step is deterministic and smooth in its parameters between contact changes; a replay of a 10 s
// palpation on the hex fragment costs ~50 ms because local simulation keeps the tick flat).
#include "fit.h"

#include <ceres/ceres.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>

#include "idms/sim/workspace.h"

namespace idms::fit {
namespace {

bool InGroup(const Model& m, Param p, int32_t e) {
  const bool home = m.elem_home[e] != 0;
  return (p == Param::kHomeK || p == Param::kHomeB) ? home : !home;
}

bool IsElementGroup(Param p) { return p != Param::kToolK; }

// The element group's values times `scale`, without re-deriving (tool_k: nothing).
void ScaleValues(Model& m, Param p, double scale) {
  if (!IsElementGroup(p)) return;
  std::vector<double>& v = (p == Param::kHomeK || p == Param::kSurfaceK) ? m.elem_k : m.elem_b;
  for (int32_t e = 0; e < m.num_elems; ++e) {
    if (InGroup(m, p, e)) v[e] *= scale;
  }
}

// The model and the tool with every factor applied.
Model Scaled(const Model& base, const FitOptions& o, const double* log_scale, ToolCommand* tool) {
  Model m = base;
  *tool = o.tool;
  for (size_t i = 0; i < o.params.size(); ++i) {
    ScaleValues(m, o.params[i], std::exp(log_scale[i]));
    if (o.params[i] == Param::kToolK) tool->stiffness *= std::exp(log_scale[i]);
  }
  FinalizeModel(m);
  return m;
}

// The residuals: simulated minus measured force at the compared ticks, 3 per sample.
struct ForceResidual {
  const Model* model;
  const Trace* trace;
  const FitOptions* options;
  const std::vector<std::array<double, 3>>* measured;
  int* replays;
  bool operator()(double const* const* x, double* residuals) const {
    ToolCommand tool;
    const Model m = Scaled(*model, *options, x[0], &tool);
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
               "' (expected each of home_k, home_b, surface_k, surface_b, tool_k at most once)";
      return false;
    }
    params->push_back(p);
  }
  if (params->empty()) {
    *error = "--params: name at least one of home_k, home_b, surface_k, surface_b, tool_k";
    return false;
  }
  return true;
}

double GroupMean(const Model& m, Param p) {
  if (!IsElementGroup(p)) return 0;
  const std::vector<double>& v = (p == Param::kHomeK || p == Param::kSurfaceK) ? m.elem_k : m.elem_b;
  double sum = 0;
  int32_t n = 0;
  for (int32_t e = 0; e < m.num_elems; ++e) {
    if (InGroup(m, p, e)) sum += v[e], ++n;
  }
  return n > 0 ? sum / n : 0;
}

void ScaleGroup(Model& m, Param p, double scale) {
  ScaleValues(m, p, scale);
  FinalizeModel(m);
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
  double t_first = 0, t_last = 0;
  for (int number = 2; std::getline(in, line); ++number) {
    double v[7];
    std::stringstream fields(line);
    std::string field;
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
    input.tools[0] = tool;
    const StepReport report = Step(model, state, ws, input);
    if ((n + 1) % stride == 0)
      out.push_back({report.tools[0].force[0], report.tools[0].force[1], report.tools[0].force[2]});
  }
  return out;
}

FitResult Fit(const Model& model, const Trace& trace, const FitOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  FitResult r;
  r.params = options.params;
  const size_t p = options.params.size();
  if (p == 0 || options.stride < 1) {
    r.message = "nothing to fit (no parameters, or a stride below 1)";
    return r;
  }
  for (Param param : options.params) {
    if (param == Param::kToolK && !(options.tool.stiffness > 0 && std::isfinite(options.tool.stiffness))) {
      r.message = "tool_k: the tool's stiffness must be a finite number > 0 to scale";
      return r;
    }
    if (IsElementGroup(param) && !(GroupMean(model, param) > 0)) {
      r.message = std::string(ParamName(param)) + ": the model has no " +
                  (param == Param::kHomeK || param == Param::kHomeB ? "home" : "surface") +
                  " elements with a nonzero value to scale";
      return r;
    }
  }
  std::vector<std::array<double, 3>> measured;
  for (size_t n = 0; n < trace.force.size(); ++n) {
    if ((n + 1) % options.stride == 0) measured.push_back(trace.force[n]);
    const auto& f = trace.force[n];
    r.peak_force = std::max(r.peak_force, std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]));
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
  auto* cost = new ceres::DynamicNumericDiffCostFunction<ForceResidual, ceres::CENTRAL>(
      new ForceResidual{&model, &trace, &options, &measured, &r.replays});
  cost->AddParameterBlock(static_cast<int>(p));
  cost->SetNumResiduals(static_cast<int>(3 * measured.size()));
  ceres::Problem problem;
  problem.AddResidualBlock(cost, nullptr, x.data());
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = options.max_iterations;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-10;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  r.iterations = static_cast<int>(summary.iterations.size());
  r.rms_before = std::sqrt(2 * summary.initial_cost / static_cast<double>(measured.size()));
  r.rms_after = std::sqrt(2 * summary.final_cost / static_cast<double>(measured.size()));
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
        IsElementGroup(options.params[i]) ? GroupMean(model, options.params[i]) : options.tool.stiffness;
    r.scale.push_back(scale);
    r.scale_sigma.push_back(sigma);
    r.value.push_back(mean * scale);
    r.value_sigma.push_back(mean * sigma);
  }
  r.fitted = Scaled(model, options, x.data(), &r.fitted_tool);
  r.fitted_force = Replay(r.fitted, trace, options.step, r.fitted_tool, options.stride);
  r.ok = true;
  r.message = summary.BriefReport();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

Trace ScriptedTrace(const Model& truth, Script script, double noise, uint32_t seed, double tool_stiffness) {
  Trace t;
  t.dt_s = 1e-3;
  const ScriptGeometry g = MakeScriptGeometry(truth, 1.5);
  const int64_t ticks = std::llround(ScriptDuration(script) / t.dt_s);
  for (int64_t n = 0; n < ticks; ++n) {
    const ScriptSample s = SampleScript(script, g, static_cast<double>(n + 1) * t.dt_s);
    t.pos.push_back({s.pos[0], s.pos[1], s.pos[2]});
  }
  ToolCommand tool;
  tool.kind = ToolKind::kSphere;
  tool.stiffness = tool_stiffness;
  t.force = Replay(truth, t, StepOptions{}, tool, 1);
  double peak = 0;
  for (const auto& f : t.force) peak = std::max(peak, std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]));
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, noise * peak);
  for (auto& f : t.force) {
    for (double& c : f) c += normal(rng);
  }
  return t;
}

}  // namespace idms::fit
