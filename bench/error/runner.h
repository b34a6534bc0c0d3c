// Error against run time: one scripted interaction run with one step configuration, compared
// with a reference run sample by sample, and timed in thread CPU time.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "idms/sim/interaction_script.h"
#include "idms/sim/model.h"
#include "idms/sim/step.h"

namespace idms::bench {

inline constexpr double kSamplePeriodS = 1e-3;  // errors are sampled every simulated ms
inline constexpr double kMioRadius = 1.5;       // r of the thesis's fingertip (ToolCommand default)

// One scripted interaction over a window of the script: every run starts at rest at t0 (the
// tool is out of contact there, so a run from 0 would be at rest too) and ends at t1.
struct Case {
  std::string model_name, script_name;
  const Model* model = nullptr;
  Script script = Script::kPalpate;
  ScriptGeometry geometry;
  double t0_s = 0, t1_s = 0;
  // The tool's friction (issue 30): mu_s = 0 is none; friction_damping b_t fixed across the
  // configurations (its default, k_t dt, would change with the tick being compared).
  double mu_s = 0, mu_d = 0, friction_damping = -1;
  int32_t samples() const;  // sample k = 1..samples() is at t0 + k ms
};

struct Config {
  Integrator integrator = Integrator::kExplicitEuler;
  double dt_s = 1e-3;
  double radius_ratio = 1.5;  // local radius r_l / r; 0 = full model (local simulation off)
  bool operator==(const Config&) const = default;
};

// The step options of a configuration: StepOptions defaults (what a user gets) with the
// integrator, tick and haptic window replaced.
StepOptions OptionsFor(const Config& config);

// What the reference run recorded at each sample: the device force and, sparsely, the atoms that
// were off their rest position by more than kMovedThreshold (the rest are at rest to within it).
struct Reference {
  static constexpr double kMovedThreshold = 1e-12;  // model units
  std::vector<std::array<double, 3>> force;         // (samples)
  std::vector<std::array<double, 3>> friction;      // (samples) its tangential part, friction's
  std::vector<int64_t> moved_adr;                   // (samples + 1): sample k's atoms are [adr[k], adr[k+1])
  std::vector<int32_t> moved_atom;
  std::vector<double> moved_pos;  // (3 x moved atoms)
  double peak_force = 0;          // largest |force| over the samples
  int64_t bytes() const;
};

struct RunResult {
  Config config;
  double cpu_us_per_ms = 0;                   // thread CPU time of the steps per simulated ms (min over repeats)
  double force_rms = 0, force_max = 0;        // |f - f_ref| over the samples, force units
  double pos_max = 0;                         // max over samples and atoms of |p - p_ref|, model units
  double friction_rms = 0, friction_max = 0;  // |f_t - f_t_ref| of friction's force (0 without friction)
  int64_t ticks = 0;
  double substeps_mean = 0;  // substeps per tick of the accepted attempts
  int64_t fallbacks = 0;     // ticks that fell back to implicit Euler
  int64_t warnings = 0;      // all counted warnings
  int32_t max_active = 0;    // most atoms simulated in one tick
};

// Runs `config` over the case. With `reference` set, the errors are against it; with `record`
// set, the samples are recorded into it instead (errors stay 0). `repeats` > 1 reruns the whole
// thing and keeps the least CPU time (the errors are deterministic). Allocates outside the
// timed region only.
RunResult RunCase(const Case& c, const Config& config, const Reference* reference, Reference* record, int repeats = 1);

// The first time the scripted MIO touches an external atom at rest (scanned every 0.1 ms), or
// the script's duration when it never does.
double ContactOnset(const Case& c);

// "euler dt 1e-3 r_l 1.5r" / "... full".
std::string ConfigLabel(const Config& config);

}  // namespace idms::bench
