// RunCase: steps a scripted interaction with one configuration, samples the device force and the
// atom positions every simulated ms, and times the steps in thread CPU time.
#include "runner.h"

#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "idms/sim/workspace.h"

namespace idms::bench {
namespace {

int64_t CpuNs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return int64_t{ts.tv_sec} * 1000000000 + ts.tv_nsec;
}

// Cost of one CpuNs pair, subtracted from every timed segment (it is a syscall, ~0.1-0.5 us:
// not negligible against a 58-atom tick).
double ClockPairNs() {
  static const double cost = [] {
    constexpr int kPairs = 2000;
    const int64_t start = CpuNs();
    volatile int64_t sink = 0;
    for (int i = 0; i < kPairs; ++i) sink = sink + (CpuNs() - CpuNs());
    return static_cast<double>(CpuNs() - start) / kPairs;
  }();
  return cost;
}

// The tick whose state a sample at t0 + k ms shows: the latest one that ended by then (a device
// holds the last force until the next tick; a display shows the last state).
int64_t TickAtSample(int32_t k, double dt) { return static_cast<int64_t>(std::floor(k * kSamplePeriodS / dt + 1e-6)); }

// Records the sample (reference run): the force and the atoms off their rest position.
void RecordSample(const Model& m, const State& s, const double f[3], const double ft[3], Reference* ref) {
  ref->force.push_back({f[0], f[1], f[2]});
  ref->friction.push_back({ft[0], ft[1], ft[2]});
  ref->peak_force = std::max(ref->peak_force, std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]));
  if (ref->moved_adr.empty()) ref->moved_adr.push_back(0);
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    const Real* p = &s.atom_pos[3 * a];
    const double* q = &m.atom_pos_eq[3 * a];
    const double d2 = (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) + (p[2] - q[2]) * (p[2] - q[2]);
    if (!(d2 <= Reference::kMovedThreshold * Reference::kMovedThreshold)) {
      ref->moved_atom.push_back(a);
      ref->moved_pos.insert(ref->moved_pos.end(), {double(p[0]), double(p[1]), double(p[2])});
    }
  }
  ref->moved_adr.push_back(static_cast<int64_t>(ref->moved_atom.size()));
}

// Max |p - p_ref| over all atoms at sample k; ref_pos is p_eq on entry and on return.
double PositionError(const Model& m, const State& s, const Reference& ref, int32_t k, std::vector<double>& ref_pos) {
  const int64_t begin = ref.moved_adr[k], end = ref.moved_adr[k + 1];
  for (int64_t i = begin; i < end; ++i) {
    std::copy_n(&ref.moved_pos[3 * i], 3, &ref_pos[3 * ref.moved_atom[i]]);
  }
  double worst2 = 0;
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    const Real* p = &s.atom_pos[3 * a];
    const double* q = &ref_pos[3 * a];
    const double d2 = (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) + (p[2] - q[2]) * (p[2] - q[2]);
    worst2 = std::isnan(d2) ? std::numeric_limits<double>::infinity() : std::max(worst2, d2);
  }
  for (int64_t i = begin; i < end; ++i) {
    const int32_t a = ref.moved_atom[i];
    std::copy_n(&m.atom_pos_eq[3 * a], 3, &ref_pos[3 * a]);
  }
  return std::sqrt(worst2);
}

RunResult RunOnce(const Case& c, const Config& config, const Reference* reference, Reference* record) {
  const Model& m = *c.model;
  StepOptions options = OptionsFor(config);
  // The reference needs no energy check at dt = 1e-5 (it never fails there) and is long.
  if (record) options.stability.energy_check = false;
  State s = MakeState(m);
  Workspace ws = MakeWorkspace(m, options);
  ResyncWorkspace(m, s, ws);  // keep the first tick's O(atoms) refile out of the timing
  std::vector<double> ref_pos(m.atom_pos_eq);

  ToolInput input;
  input.num_tools = 1;
  ToolCommand tool;
  tool.kind = ToolKind::kSphere;
  tool.radius = c.geometry.mio_radius;
  tool.mu_s = c.mu_s;
  tool.mu_d = c.mu_d;
  tool.friction_damping = c.friction_damping;
  RunResult r;
  r.config = config;
  const int64_t total_ticks = std::llround((c.t1_s - c.t0_s) / config.dt_s);
  const double clock_pair = ClockPairNs();
  double cpu_ns = 0, force_sq_sum = 0, friction_sq_sum = 0;
  int64_t n = 0, substeps = 0;
  double f[3] = {0, 0, 0}, ft[3] = {0, 0, 0};
  for (int32_t k = 1; k <= c.samples(); ++k) {
    // Timed: the ticks up to this sample.
    const int64_t target = std::min(total_ticks, TickAtSample(k, config.dt_s));
    const int64_t cpu0 = CpuNs();
    for (; n < target; ++n) {
      const ScriptSample pose = SampleScript(c.script, c.geometry, c.t0_s + static_cast<double>(n + 1) * config.dt_s);
      std::copy_n(pose.pos, 3, tool.pos);
      input.tools[0] = tool;
      const StepReport report = Step(m, s, ws, input);
      std::copy_n(report.tools[0].force, 3, f);
      std::copy_n(report.tools[0].friction_force, 3, ft);
      substeps += report.substeps;
      r.fallbacks += report.fallback;
      r.max_active = std::max(r.max_active, report.active_atoms);
    }
    cpu_ns += static_cast<double>(CpuNs() - cpu0) - clock_pair;

    // Untimed: the sample.
    if (record) {
      RecordSample(m, s, f, ft, record);
      continue;
    }
    const std::array<double, 3>& g = reference->force[k - 1];
    const double e2 = (f[0] - g[0]) * (f[0] - g[0]) + (f[1] - g[1]) * (f[1] - g[1]) + (f[2] - g[2]) * (f[2] - g[2]);
    force_sq_sum += e2;
    r.force_max = std::max(r.force_max, std::sqrt(e2));
    const std::array<double, 3>& gt = reference->friction[k - 1];
    const double t2 =
        (ft[0] - gt[0]) * (ft[0] - gt[0]) + (ft[1] - gt[1]) * (ft[1] - gt[1]) + (ft[2] - gt[2]) * (ft[2] - gt[2]);
    friction_sq_sum += t2;
    r.friction_max = std::max(r.friction_max, std::sqrt(t2));
    r.pos_max = std::max(r.pos_max, PositionError(m, s, *reference, k - 1, ref_pos));
  }
  r.ticks = n;
  r.cpu_us_per_ms = std::max(0.0, cpu_ns) * 1e-3 / ((c.t1_s - c.t0_s) * 1e3);
  r.force_rms = std::sqrt(force_sq_sum / std::max(1, c.samples()));
  r.friction_rms = std::sqrt(friction_sq_sum / std::max(1, c.samples()));
  r.substeps_mean = n > 0 ? static_cast<double>(substeps) / static_cast<double>(n) : 0;
  r.warnings = TotalWarnings(s.warnings);
  return r;
}

}  // namespace

int32_t Case::samples() const { return static_cast<int32_t>(std::floor((t1_s - t0_s) / kSamplePeriodS + 1e-6)); }

int64_t Reference::bytes() const {
  return static_cast<int64_t>((force.size() + friction.size()) * sizeof(force[0]) + moved_adr.size() * sizeof(int64_t) +
                              moved_atom.size() * sizeof(int32_t) + moved_pos.size() * sizeof(double));
}

StepOptions OptionsFor(const Config& config) {
  StepOptions o;
  o.integrator = config.integrator;
  o.dt_s = config.dt_s;
  o.full = config.radius_ratio <= 0;
  if (!o.full) o.local_radius = config.radius_ratio * kMioRadius;
  return o;
}

RunResult RunCase(const Case& c, const Config& config, const Reference* reference, Reference* record, int repeats) {
  RunResult best = RunOnce(c, config, reference, record);
  for (int i = 1; i < repeats && !record; ++i) {
    const RunResult again = RunOnce(c, config, reference, nullptr);
    best.cpu_us_per_ms = std::min(best.cpu_us_per_ms, again.cpu_us_per_ms);
  }
  return best;
}

double ContactOnset(const Case& c) {
  const Model& m = *c.model;
  const double duration = ScriptDuration(c.script), step = 1e-4, r = c.geometry.mio_radius;
  const int64_t n = static_cast<int64_t>(std::ceil(duration / step));
  // The external atoms the tool can reach: near the xy box of its whole path.
  double lo[2] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
  double hi[2] = {-lo[0], -lo[1]};
  for (int64_t i = 0; i <= n; ++i) {
    const ScriptSample pose = SampleScript(c.script, c.geometry, static_cast<double>(i) * step);
    for (int d = 0; d < 2; ++d) lo[d] = std::min(lo[d], pose.pos[d]), hi[d] = std::max(hi[d], pose.pos[d]);
  }
  std::vector<int32_t> near;
  for (int32_t a : m.external_atoms) {
    const double* p = &m.atom_pos_eq[3 * a];
    if (p[0] >= lo[0] - r && p[0] <= hi[0] + r && p[1] >= lo[1] - r && p[1] <= hi[1] + r) near.push_back(a);
  }
  for (int64_t i = 0; i <= n; ++i) {
    const double t = static_cast<double>(i) * step;
    const ScriptSample pose = SampleScript(c.script, c.geometry, t);
    for (int32_t a : near) {
      const double* p = &m.atom_pos_eq[3 * a];
      const double d2 = (p[0] - pose.pos[0]) * (p[0] - pose.pos[0]) + (p[1] - pose.pos[1]) * (p[1] - pose.pos[1]) +
                        (p[2] - pose.pos[2]) * (p[2] - pose.pos[2]);
      if (d2 < r * r) return t;
    }
  }
  return duration;
}

std::string ConfigLabel(const Config& config) {
  char buf[96];
  if (config.radius_ratio <= 0) {
    std::snprintf(buf, sizeof buf, "%s dt %g r_l full", IntegratorName(config.integrator), config.dt_s);
  } else {
    std::snprintf(buf, sizeof buf, "%s dt %g r_l %gr", IntegratorName(config.integrator), config.dt_s,
                  config.radius_ratio);
  }
  return buf;
}

}  // namespace idms::bench
