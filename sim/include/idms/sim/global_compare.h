// Two-rate mode against the truth (issue 33's numbers): a scripted interaction run three ways on
// one model, (a) the whole model at the local tick (the reference), (b) local simulation only
// (the thesis), (c) local simulation with the global pass at a slower rate, and their errors
// against (a). For `idms-global-bench` and the tests; allocates freely.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "idms/sim/interaction_script.h"
#include "idms/sim/model.h"
#include "idms/sim/state.h"

namespace idms {

enum class RunMode : uint8_t { kFull, kLocal, kTwoRate };

struct ScriptedRunOptions {
  Script script = Script::kPluck;
  RunMode mode = RunMode::kLocal;
  double global_rate_hz = 100;  // kTwoRate
  int32_t global_phase = 0;     // kTwoRate: GlobalOptions::phase
  int32_t sample_every = 10;    // surface positions every this many ticks
  int64_t max_ticks = -1;       // -1 = the whole script
};

struct ScriptedTrace {
  std::vector<std::array<double, 3>> force;  // device force per tick
  std::vector<Real> surface;                 // external atoms' xyz per sample, sample after sample
  std::vector<int64_t> update_ticks;         // kTwoRate: ticks at which a global result was taken
  double global_step_ms = 0;                 // kTwoRate: mean wall time of a global step
};

// The script with the tool `idms-sim run` gives it (tweezers for the pluck, else the 1.5-unit
// sphere) and the default preset's step.
ScriptedTrace RunScripted(const Model& model, const ScriptedRunOptions& options);

struct TraceError {
  double peak_force = 0;                    // the reference's largest |f|
  double force_rms = 0, force_max = 0;      // |f - f_ref| over every tick
  double surface_rms = 0, surface_max = 0;  // |p - p_ref| of the external atoms over every sample
  // |(f(t) - f(t-1)) - (f_ref(t) - f_ref(t-1))|, the force change beyond the reference's own, at
  // the ticks right after a global result was taken, and at every other tick.
  double jump_at_update_max = 0, jump_elsewhere_max = 0;
  std::vector<double> jumps_at_update;  // each one, for a histogram
};

// The update's own part of the force change: the same two-rate run with its exchanges shifted half
// a slow step (`shifted`, no update at `run`'s update ticks) meets the same contacts at nearly the
// same ticks, so |(f(t) - f(t-1)) - (f_s(t) - f_s(t-1))| at run's update ticks is what the update
// added there; `elsewhere` is the same at every other tick (how much the two runs differ anyway).
struct UpdateJump {
  double at_update_max = 0, elsewhere_max = 0;
};
UpdateJump CompareShifted(const ScriptedTrace& run, const ScriptedTrace& shifted);

TraceError CompareTraces(const ScriptedTrace& reference, const ScriptedTrace& run);

}  // namespace idms
