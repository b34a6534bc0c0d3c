// idms-sim drape: a slab draped onto a sphere and saved as a new model (thesis 5.6.1), with
// progress on stderr while the DSM runs to equilibrium and an optional JSON summary.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <sstream>

#include "command.h"
#include "idms/sim/drape.h"
#include "idms/sim/generate.h"
#include "idms/sim/model_io.h"
#include "idms/sim/summary.h"

namespace idms::tool {
namespace {

struct DrapeArgs {
  SlabOptions slab;
  std::string model;  // drape this model instead of generating a slab
  DrapeOptions drape;
  std::string integrator = "symplectic", center = "0,0,0", out, compare;
  double compare_tolerance = 1e-3;
  double dt = 0;                // 0 = automatic
  double progress_percent = 5;  // a line per this many % of --max-time, and at least every second
  bool json = false, quiet = false;
};

bool ParseCenter(const std::string& text, double out[3]) {
  std::stringstream in(text);
  char comma;
  for (int i = 0; i < 3; ++i) {
    if (!(in >> out[i]) || !std::isfinite(out[i]) || (i < 2 && !(in >> comma && comma == ','))) return false;
  }
  return in.peek() == EOF;
}

// Same topology, material and surface as `expected`, rest positions within `tolerance`:
// regeneration checks that survive last-bit changes in the step (the rounding of the saved
// positions absorbs most, not all). Sets *max_diff; *why names the first mismatch.
bool SameModel(const Model& got, const Model& expected, double tolerance, double* max_diff, std::string* why) {
  *max_diff = 0;
  if (got.num_atoms != expected.num_atoms || got.num_elems != expected.num_elems || got.num_tris != expected.num_tris) {
    *why = "counts differ: " + std::to_string(got.num_atoms) + " atoms, " + std::to_string(got.num_elems) +
           " elements, " + std::to_string(got.num_tris) + " triangles against " + std::to_string(expected.num_atoms) +
           ", " + std::to_string(expected.num_elems) + ", " + std::to_string(expected.num_tris);
    return false;
  }
  if (got.elem_atoms != expected.elem_atoms || got.tri_atoms != expected.tri_atoms ||
      got.atom_fixed != expected.atom_fixed || got.atom_external != expected.atom_external) {
    *why = "the topology differs (elements, triangles or atom conditions)";
    return false;
  }
  if (got.atom_mass != expected.atom_mass || got.elem_k != expected.elem_k || got.elem_b != expected.elem_b) {
    *why = "masses, stiffnesses or viscosities differ";
    return false;
  }
  for (int32_t i = 0; i < 3 * got.num_atoms; ++i) {
    *max_diff = std::max(*max_diff, std::fabs(got.atom_pos_eq[i] - expected.atom_pos_eq[i]));
  }
  if (!(*max_diff <= tolerance)) {
    *why = "rest positions differ by up to " + std::to_string(*max_diff) + " (tolerance " + std::to_string(tolerance) +
           ")";
    return false;
  }
  return true;
}

// CPU time of this thread, s (as idms-sim run and the benches measure).
double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// JSON has no infinity: a range that saw no atom is null.
nlohmann::json Range(double lo, double hi) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) return nullptr;
  return {lo, hi};
}

void Run(DrapeArgs& a) {
  // The slab: generated (home elements are stripped by Drape) or loaded.
  Model slab;
  if (!a.model.empty()) {
    std::string fem, plg;
    ModelPaths(a.model, &fem, &plg);
    LoadError error;
    if (!LoadModel(fem, plg, {}, &slab, &error)) Fail("drape", error.ToString());
  } else {
    if (a.slab.rows < 2 || a.slab.cols < 1) Fail("drape", "expected --rows >= 2 and --cols >= 1, or --model PREFIX");
    a.slab.name = a.drape.name;
    slab = GenerateSlab(a.slab);
  }

  // Form and step; the tick defaults to 90% of what the form and the elements allow, at most 1 ms.
  DrapeOptions& o = a.drape;
  if (!ParseCenter(a.center, o.form.center)) Fail("drape", "--center '" + a.center + "': expected X,Y,Z");
  if (!ParseIntegratorName(a.integrator, &o.step.integrator)) {
    Fail("drape", "--integrator '" + a.integrator + "': expected euler, symplectic, rk4 or implicit");
  }
  const Model stripped = StripHomeElements(slab);
  const double stable = DrapeStableDt(stripped, o.form, o.step);
  if (!(stable > 0)) {
    Fail("drape",
         "no stable step: an undamped atom under explicit Euler (give the elements or --b-form viscosity, or "
         "use --integrator symplectic)");
  }
  o.step.dt_s = a.dt > 0 ? a.dt : std::min(1e-3, 0.9 * stable);
  o.huge_pages = true;  // a command-line generation run: large slabs pay back the system calls
  if (o.step.dt_s > stable) {
    Fail("drape", "--dt " + std::to_string(a.dt) + " s exceeds the stable step " + std::to_string(stable) +
                      " s for this slab, form and integrator (omit --dt to use 90% of it)");
  }

  // Stage 2 with a progress line per N% of --max-time or per wall-clock second.
  const auto start = std::chrono::steady_clock::now();
  auto last_print = start;
  double next_fraction = 0;
  // Stage 2's CPU time per tick, from its first progress report after tick 0 to its last (the
  // first ticks build full mode's lists), or from tick 0 when there is no
  // such report in between.
  struct Mark {
    int64_t tick = 0;
    double cpu_s = 0;
    double wall_s = 0;
  };
  Mark marks[3];  // the first two reports and the last
  int64_t reports = 0;
  auto progress = [&](const DrapeProgress& p) {
    const Mark mark{p.tick, ThreadCpuSeconds(),
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()};
    marks[std::min<int64_t>(reports++, 2)] = mark;
    marks[2] = mark;
    const auto now = std::chrono::steady_clock::now();
    const bool due = p.fraction >= next_fraction || now - last_print >= std::chrono::seconds(1) || p.settled;
    if (a.quiet || !due) return;
    std::fprintf(stderr, "drape: t %7.3f s  kinetic %.3e  max speed %.3e  energy %.6e  (%3.0f%% of --max-time)%s\n",
                 p.time_s, p.kinetic, p.max_speed, p.energy, 100 * p.fraction, p.settled ? "  settled" : "");
    last_print = now;
    while (next_fraction <= p.fraction) next_fraction += a.progress_percent / 100;
  };
  const DrapeResult r = Drape(slab, o, progress);
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // Per tick of stage 2 (form forces, the step, progress), CPU time; element updates per second
  // counts one substep per tick (the default tick is 90% of the predicted stable one).
  const Mark& from = marks[2].tick > marks[1].tick && reports > 2 ? marks[1] : marks[0];
  const double tick_cpu_s =
      marks[2].tick > from.tick ? (marks[2].cpu_s - from.cpu_s) / static_cast<double>(marks[2].tick - from.tick) : 0.0;
  // On several threads, element updates per wall-clock second (this thread's CPU time leaves the
  // others' out).
  const double tick_wall_s = marks[2].tick > from.tick
                                 ? (marks[2].wall_s - from.wall_s) / static_cast<double>(marks[2].tick - from.tick)
                                 : 0.0;
  const double tick_rate_s = o.step.threads > 1 ? tick_wall_s : tick_cpu_s;

  // Stage 3 output and summary.
  std::string error;
  if (!SaveModel(r.model, a.out, &error)) Fail("drape", error);
  const ModelSummary s = Summarize(r.model);
  bool matches = true;
  double max_diff = 0;
  std::string mismatch;
  if (!a.compare.empty()) {
    Model expected;
    std::string fem, plg;
    ModelPaths(a.compare, &fem, &plg);
    LoadError load_error;
    if (!LoadModel(fem, plg, {}, &expected, &load_error)) Fail("drape", "--compare: " + load_error.ToString());
    matches = SameModel(r.model, expected, a.compare_tolerance, &max_diff, &mismatch);
  }
  if (a.json) {
    PrintJson({{"atoms", s.atoms},
               {"elements", s.elements},
               {"external_atoms", s.external_atoms},
               {"home_elements", s.home_elements},
               {"triangles", s.triangles},
               {"settled", r.settled},
               {"sim_time_s", r.time_s},
               {"ticks", r.ticks},
               {"dt", o.step.dt_s},
               {"integrator", IntegratorName(o.step.integrator)},
               {"wall_s", wall_s},
               {"tick_cpu_ms", 1e3 * tick_cpu_s},
               {"tick_wall_ms", 1e3 * tick_wall_s},
               {"threads", o.step.threads},
               {"element_updates_per_s", tick_rate_s > 0 ? stripped.num_elems / tick_rate_s : 0.0},
               {"kinetic", r.kinetic},
               {"max_speed", r.max_speed},
               {"energy_start", r.energy_start},
               {"energy_end", r.energy_end},
               {"energy_max", r.energy_max},
               {"external_gap", Range(r.external_min, r.external_max)},
               {"internal_gap", Range(r.internal_min, r.internal_max)},
               {"folded_triangles", r.folded_triangles},
               {"warnings", r.warnings},
               {"bbox_min", {s.bbox_min[0], s.bbox_min[1], s.bbox_min[2]}},
               {"bbox_max", {s.bbox_max[0], s.bbox_max[1], s.bbox_max[2]}},
               {"fem", a.out + ".fem"},
               {"plg", a.out + ".plg"},
               {"matches", a.compare.empty() ? nlohmann::json(nullptr) : nlohmann::json(matches)},
               {"compare_max_diff", a.compare.empty() ? nlohmann::json(nullptr) : nlohmann::json(max_diff)}});
  } else {
    std::printf("%s after %.3f s simulated (%lld ticks of %g s, %s) in %.1f s: energy %.4g -> %.4g, %lld warnings\n",
                r.settled ? "settled" : "NOT settled (hit --max-time)", r.time_s, static_cast<long long>(r.ticks),
                o.step.dt_s, IntegratorName(o.step.integrator), wall_s, r.energy_start, r.energy_end,
                static_cast<long long>(r.warnings));
    std::printf("surface atoms lie %.4f .. %.4f from the sphere, the lower layer %.4f .. %.4f\n", r.external_min,
                r.external_max, r.internal_min, r.internal_max);
    if (r.folded_triangles > 0) {
      std::printf(
          "%d surface triangles face the sphere: the slab folded or wrinkled (try a lower --k-out or a larger "
          "--radius)\n",
          r.folded_triangles);
    }
    std::printf("wrote %s.fem (%d atoms, %d elements, %d home) and %s.plg (%d vertices, %d triangles)\n", a.out.c_str(),
                s.atoms, s.elements, s.home_elements, a.out.c_str(), s.external_atoms, s.triangles);
  }
  if (!a.compare.empty()) {
    if (!matches) Fail("drape", "--compare " + a.compare + ": " + mismatch);
    if (!a.json) std::printf("matches %s (rest positions within %g)\n", a.compare.c_str(), max_diff);
  }
  if (!r.settled) throw CLI::RuntimeError(3);  // the model is written, but it is not an equilibrium
}

void Setup(CLI::App& app) {
  auto* cmd =
      app.add_subcommand("drape", "Drape a slab onto a sphere and save the equilibrium as a model (thesis 5.6.1)");
  static DrapeArgs a;
  SlabOptions& slab = a.slab;
  SphereForm& form = a.drape.form;
  a.slab.rows = a.slab.cols = 0;
  auto* rows = cmd->add_option("--rows", slab.rows, "Rows of the slab's top hex grid")->check(CLI::Range(2, 100000));
  auto* cols =
      cmd->add_option("--cols", slab.cols, "Atoms in even rows (odd rows have one more)")->check(CLI::Range(1, 100000));
  cmd->add_option("--model", a.model, "Drape this model (its home elements are removed) instead of a new slab")
      ->excludes(rows)
      ->excludes(cols);
  cmd->add_option("--radius", form.radius, "Sphere radius R_f")->required()->check(CLI::PositiveNumber);
  cmd->add_option("--center", a.center, "Sphere centre X,Y,Z")->capture_default_str();
  cmd->add_option("--k-out", form.k_out, "Attraction stiffness k_f^o outside the sphere")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--k-in", form.k_in, "Surface stiffness k_f^i inside the sphere")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--b-form", form.b, "Viscosity b_f inside the sphere")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--air-damping", a.drape.step.air_damping,
                  "Air resistance on every atom, 1/s (0 = thesis; settles large slabs faster, same equilibrium)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--gap", a.drape.gap, "Start with the slab's lowest atom this far above the sphere")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--spacing", slab.spacing, "Slab element length")->check(CLI::PositiveNumber)->capture_default_str();
  cmd->add_option("--k", slab.k, "Slab element stiffness")->check(CLI::NonNegativeNumber)->capture_default_str();
  cmd->add_option("--b", slab.b, "Slab element viscosity")->check(CLI::NonNegativeNumber)->capture_default_str();
  cmd->add_option("--mass", slab.mass, "Slab atom mass")->check(CLI::PositiveNumber)->capture_default_str();
  cmd->add_option("--home-k", a.drape.home_k, "Stiffness of the home elements added at the end")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--home-b", a.drape.home_b, "Viscosity of the home elements added at the end")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--integrator", a.integrator, "euler | symplectic | rk4 | implicit")->capture_default_str();
  cmd->add_option("--threads", a.drape.step.threads,
                  "Threads for stage 2's pass (more than one: the slab is renumbered for it, and the result "
                  "mapped back)")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  cmd->add_option("--dt", a.dt, "Time step, s (default: 90% of the predicted stable step, at most 1 ms)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--max-time", a.drape.max_time_s, "Give up after this much simulated time, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--settle-kinetic", a.drape.settle_kinetic, "Equilibrium: total kinetic energy below this")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--settle-speed", a.drape.settle_speed, "Equilibrium: every atom slower than this")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--settle-hold", a.drape.settle_hold_s, "Equilibrium: both for this long, s")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--decimals", a.drape.decimals, "Round rest positions to this many decimals (-1: exact)")
      ->capture_default_str();
  cmd->add_option("--name", a.drape.name, "Model name written in the headers")->capture_default_str();
  cmd->add_option("--progress", a.progress_percent, "A progress line per this many % of --max-time (and each second)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_flag("--quiet", a.quiet, "No progress lines");
  cmd->add_option("--out", a.out, "Output prefix: writes PREFIX.fem and PREFIX.plg")->required();
  cmd->add_option("--compare", a.compare,
                  "Then check the result against this model: same topology and material, "
                  "rest positions within --compare-tolerance (exit 1 if not)");
  cmd->add_option("--compare-tolerance", a.compare_tolerance, "Largest rest-position difference --compare accepts")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_flag("--json", a.json, "Print the summary as one JSON object");
  cmd->callback([] { Run(a); });
}

IDMS_SIM_COMMAND(15, Setup);

}  // namespace
}  // namespace idms::tool
