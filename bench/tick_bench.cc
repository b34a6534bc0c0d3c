// Local-simulation tick cost against model size: the thesis palpation (interaction_script.h) on
// slabs of 10^3 to 10^6 atoms with the default step (StepOptions{}: local window, thesis MIO); tick
// compute p50 / p99 / max, and the 10^6 : 10^4 ratio. Prints a table (CSV with --csv); never
// fails on time. Goal (issue 3): flat, the 10^6 tick within 1.5x of the 10^4 tick, p99 < 100 us.
// The suture row (issue 32): the scripted stitch on the hex fragment (interaction_script.h) with
// a 100-segment thread, the ticks with the needle in the tissue or the thread through it; goal
// p99 <= 100 us.
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "idms/sim/generate.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/step.h"
#include "idms/sim/tool.h"
#include "idms/sim/workspace.h"

namespace {

using namespace idms;

double ThreadCpuNs() {
  timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return 1e9 * static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec);
}

struct Percentiles {
  double p50 = 0, p99 = 0, max = 0;  // us
};

Percentiles Summarize(std::vector<double> us) {
  std::sort(us.begin(), us.end());
  auto at = [&](double q) {
    return us[std::min(us.size() - 1, static_cast<size_t>(q * static_cast<double>(us.size())))];
  };
  return {at(0.5), at(0.99), us.back()};
}

struct SizeResult {
  int32_t atoms = 0, elements = 0;
  int64_t ticks = 0, warnings = 0;
  double mean_active = 0;
  int32_t max_active = 0;
  double peak_fz = 0;
  Percentiles wall, cpu;     // tick compute: steady clock around Step / this thread's CPU time
  int64_t slowest_tick = 0;  // by CPU time
  StepReport slowest;        // its stage times
  double setup_s = 0;        // generate + MakeWorkspace + ResyncWorkspace
};

// One palpation (the whole script, 1 kHz) on a slab of about `atoms` atoms.
SizeResult RunSize(int64_t atoms, double duration_s, double local_radius, Integrator integrator) {
  SizeResult r;
  const auto t0 = std::chrono::steady_clock::now();
  const int32_t side = std::max<int32_t>(2, static_cast<int32_t>(std::lround(std::sqrt(atoms / 3.0))));
  const Model model = GenerateSlab(SlabOptions{.rows = side, .cols = side});
  const ScriptGeometry geometry = MakeScriptGeometry(model, 1.5);
  StepOptions options;  // the default: local window, checks on
  options.local_radius = local_radius;
  options.integrator = integrator;
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, options);
  // The first Step would refile the hash from the State (O(atoms)); do it before timing.
  ResyncWorkspace(model, state, ws);
  r.setup_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.atoms = model.num_atoms;
  r.elements = model.num_elems;

  const int64_t ticks = static_cast<int64_t>(std::llround(duration_s / options.dt_s));
  std::vector<double> wall(ticks), cpu(ticks);
  ToolInput input;
  input.num_tools = 1;
  input.tools[0].kind = ToolKind::kSphere;  // r = 1.5, k = 400, thesis law (ToolCommand defaults)
  int64_t active_sum = 0;
  for (int64_t i = 0; i < ticks; ++i) {
    const ScriptSample sample = SampleScript(Script::kPalpate, geometry, static_cast<double>(i) * options.dt_s);
    std::copy(sample.pos, sample.pos + 3, input.tools[0].pos);
    const double c0 = ThreadCpuNs();
    const auto w0 = std::chrono::steady_clock::now();
    const StepReport report = Step(model, state, ws, input);
    const auto w1 = std::chrono::steady_clock::now();
    const double c1 = ThreadCpuNs();
    wall[i] = std::chrono::duration<double, std::micro>(w1 - w0).count();
    cpu[i] = 1e-3 * (c1 - c0);
    active_sum += report.active_atoms;
    if (cpu[i] > cpu[r.slowest_tick]) r.slowest_tick = i, r.slowest = report;
    r.max_active = std::max(r.max_active, report.active_atoms);
    r.peak_fz = std::max(r.peak_fz, report.tools[0].force[2]);
  }
  r.ticks = ticks;
  r.mean_active = static_cast<double>(active_sum) / static_cast<double>(ticks);
  r.warnings = TotalWarnings(state.warnings);
  r.wall = Summarize(wall);
  r.cpu = Summarize(cpu);
  return r;
}

// The stitch with a 100-segment thread: the ticks from the puncture on (the needle in the tissue,
// then the thread through it and tied).
struct StitchResult {
  int64_t ticks = 0, warnings = 0;
  int32_t punctures = 0, ties = 0, substeps = 0;
  Percentiles wall, cpu;
};

StitchResult RunStitch(int32_t segments) {
  StitchResult r;
  const Model model = GenerateSlab(SlabOptions{});
  ToolCommand tool = StitchNeedle();
  tool.suture.segments = segments;
  const ScriptGeometry geometry = MakeScriptGeometry(model, tool.radius);
  StepOptions options;
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, options);
  ResyncWorkspace(model, state, ws);
  ToolInput input;
  input.num_tools = 1;
  const int64_t ticks = static_cast<int64_t>(std::llround(ScriptDuration(Script::kStitch) / options.dt_s));
  std::vector<double> wall, cpu;
  wall.reserve(ticks), cpu.reserve(ticks);
  bool counting = false;
  for (int64_t i = 0; i < ticks; ++i) {
    const ScriptSample sample = SampleScript(Script::kStitch, geometry, static_cast<double>(i + 1) * options.dt_s);
    std::copy(sample.pos, sample.pos + 3, tool.pos);
    NeedleAxisOf(sample.orientation, tool.axis);
    tool.tie = sample.closed;
    input.tools[0] = tool;
    const double c0 = ThreadCpuNs();
    const auto w0 = std::chrono::steady_clock::now();
    const StepReport report = Step(model, state, ws, input);
    const auto w1 = std::chrono::steady_clock::now();
    const double c1 = ThreadCpuNs();
    counting = counting || report.tools[0].punctured;
    if (!counting) continue;
    wall.push_back(std::chrono::duration<double, std::micro>(w1 - w0).count());
    cpu.push_back(1e-3 * (c1 - c0));
    r.ties += report.suture.tied;
    r.substeps = std::max(r.substeps, report.suture.substeps);
  }
  r.ticks = static_cast<int64_t>(wall.size());
  r.punctures = state.suture.num_punctures;
  r.warnings = TotalWarnings(state.warnings);
  if (!wall.empty()) r.wall = Summarize(wall), r.cpu = Summarize(cpu);
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<long long> sizes = {1000, 10000, 100000, 1000000};
  double duration_s = ScriptDuration(Script::kPalpate);
  const char* csv_path = nullptr;
  double local_radius = StepOptions{}.local_radius;
  Integrator integrator = StepOptions{}.integrator;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--quick")) {
      sizes = {1000, 10000};
    } else if (!std::strcmp(argv[i], "--csv") && i + 1 < argc) {
      csv_path = argv[++i];
    } else if (!std::strcmp(argv[i], "--local-radius") && i + 1 < argc) {
      local_radius = std::atof(argv[++i]);  // a wider window: more atoms per tick, same flatness test
    } else if (!std::strcmp(argv[i], "--integrator") && i + 1 < argc) {
      const char* name = argv[++i];
      bool known = false;
      for (Integrator k :
           {Integrator::kExplicitEuler, Integrator::kSymplecticEuler, Integrator::kRk4, Integrator::kImplicitEuler}) {
        if (!std::strcmp(name, IntegratorName(k))) integrator = k, known = true;
      }
      if (!known) {
        std::fprintf(stderr, "--integrator: expected euler, symplectic, rk4 or implicit, got '%s'\n", name);
        return 2;
      }
    } else {
      std::fprintf(stderr, "usage: %s [--quick] [--local-radius R] [--integrator NAME] [--csv FILE]\n", argv[0]);
      return 2;
    }
  }
  std::printf("palpation (%.1f s at 1 kHz, sphere r 1.5 k 400, r_l %.2f, %s, default checks)\n\n", duration_s,
              local_radius, IntegratorName(integrator));
  std::printf("%8s %8s %6s %9s | %23s | %23s | %5s %7s %6s\n", "atoms", "elements", "ticks", "active",
              "wall us p50 / p99 / max", "cpu us p50 / p99 / max", "warn", "peak fz", "setup");
  std::FILE* csv = csv_path ? std::fopen(csv_path, "w") : nullptr;
  if (csv) {
    std::fprintf(csv,
                 "atoms,elements,ticks,mean_active,max_active,wall_p50_us,wall_p99_us,wall_max_us,cpu_p50_us,"
                 "cpu_p99_us,cpu_max_us,warnings,peak_fz\n");
  }
  std::vector<SizeResult> results;
  for (long long n : sizes) {
    const SizeResult r = RunSize(n, duration_s, local_radius, integrator);
    results.push_back(r);
    std::printf("%8d %8d %6lld %4.0f/%4d | %7.1f %7.1f %7.1f | %7.1f %7.1f %7.1f | %5lld %7.2f %5.1fs\n", r.atoms,
                r.elements, static_cast<long long>(r.ticks), r.mean_active, r.max_active, r.wall.p50, r.wall.p99,
                r.wall.max, r.cpu.p50, r.cpu.p99, r.cpu.max, static_cast<long long>(r.warnings), r.peak_fz, r.setup_s);
    if (csv) {
      std::fprintf(csv, "%d,%d,%lld,%.2f,%d,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%lld,%.4f\n", r.atoms, r.elements,
                   static_cast<long long>(r.ticks), r.mean_active, r.max_active, r.wall.p50, r.wall.p99, r.wall.max,
                   r.cpu.p50, r.cpu.p99, r.cpu.max, static_cast<long long>(r.warnings), r.peak_fz);
    }
    std::printf(
        "%8s slowest tick %lld (%.0f us cpu): tools %.1f, active set %.1f, forces %.1f, integrate %.1f, "
        "checks %.1f us, %d active, %d substeps, %d attempts\n",
        "", static_cast<long long>(r.slowest_tick), r.cpu.max, 1e-3 * r.slowest.tools_ns,
        1e-3 * r.slowest.active_set_ns, 1e-3 * r.slowest.forces_ns, 1e-3 * r.slowest.integrate_ns,
        1e-3 * r.slowest.checks_ns, r.slowest.active_atoms, r.slowest.substeps, r.slowest.attempts);
    std::fflush(stdout);
  }
  if (csv) std::fclose(csv);
  // The flatness figure: the largest model against the 10^4-atom one.
  const SizeResult* small = nullptr;
  for (const SizeResult& r : results) {
    if (small == nullptr || std::llabs(r.atoms - 10000) < std::llabs(small->atoms - 10000)) small = &r;
  }
  const SizeResult& large = results.back();
  if (small != nullptr && &large != small) {
    std::printf("\n%d vs %d atoms: p50 %.2fx, p99 %.2fx (wall); p50 %.2fx, p99 %.2fx (cpu)\n", large.atoms,
                small->atoms, large.wall.p50 / small->wall.p50, large.wall.p99 / small->wall.p99,
                large.cpu.p50 / small->cpu.p50, large.cpu.p99 / small->cpu.p99);
  }
  // The suture row.
  const StitchResult st = RunStitch(100);
  std::printf(
      "\nsuture: the stitch on the hex fragment, a 100-segment thread (%d substeps at most), %lld ticks from the "
      "puncture on:\n  wall us p50 %.1f p99 %.1f max %.1f | cpu us p50 %.1f p99 %.1f max %.1f | %d points drawn "
      "through, %d knots, %lld warnings\n",
      st.substeps, static_cast<long long>(st.ticks), st.wall.p50, st.wall.p99, st.wall.max, st.cpu.p50, st.cpu.p99,
      st.cpu.max, st.punctures, st.ties, static_cast<long long>(st.warnings));
  std::printf(
      "wall = steady clock around Step (what a 1 kHz loop sees, preemption included); cpu = this thread's\n"
      "CPU time in Step (the machine is shared); active = mean / max atoms in the window.\n");
  return 0;
}
