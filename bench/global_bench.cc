// Global dynamics at a slower rate against the truth (issue 33, thesis 7.2.2): on models where
// motion propagates (a membrane on weak home springs, the draped sphere cap) and for a pluck and
// a stroke, the device force and the surface of (b) local simulation only and (c) local plus the
// global pass at 50 and 100 Hz, against (a) the whole model at 1 kHz. Prints the errors, the
// largest force change at a global update beside the largest elsewhere, and a histogram of the
// changes at updates. The global pass runs synchronously (each result applied one slow step
// late, as a thread that keeps up would): the figures are reproducible. Never fails on time.
#include <cstdio>
#include <string>
#include <vector>

#include "idms/sim/generate.h"
#include "idms/sim/global_compare.h"
#include "idms/sim/model_io.h"

using namespace idms;

namespace {

// A slab on weak home springs (the elements' k is 15): a pull spreads beyond the haptic window.
Model Membrane(double home_k) {
  SlabOptions so;
  so.rows = 20, so.cols = 20;
  so.home_k = home_k;
  so.name = "membrane";
  return GenerateSlab(so);
}

Model SphereCap() {
  Model m;
  LoadError error;
  const std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/sphere_cap";
  if (!LoadModel(prefix + ".fem", prefix + ".plg", {}, &m, &error)) {
    std::fprintf(stderr, "%s\n", error.ToString().c_str());
    std::exit(1);
  }
  return m;
}

}  // namespace

int main() {
  const std::pair<const char*, Model> models[] = {
      {"membrane 20x20", Membrane(1.5)}, {"membrane soft", Membrane(0.3)}, {"sphere_cap", SphereCap()}};
  const Script scripts[] = {Script::kPluck, Script::kStrokeSlow};
  std::printf("%-15s %-12s %-14s | %8s %8s | %9s %9s | %9s %9s | %8s\n", "model", "script", "mode", "f rms %",
              "f max %", "surf rms", "surf max", "jump@upd", "jump else", "step ms");
  for (const auto& [name, model] : models) {
    for (const Script script : scripts) {
      const ScriptedTrace ref = RunScripted(model, {.script = script, .mode = RunMode::kFull});
      struct Case {
        const char* label;
        RunMode mode;
        double hz;
      };
      for (const Case c : {Case{"local only", RunMode::kLocal, 0}, Case{"two-rate 50 Hz", RunMode::kTwoRate, 50},
                           Case{"two-rate 100 Hz", RunMode::kTwoRate, 100}}) {
        const ScriptedTrace run = RunScripted(model, {.script = script, .mode = c.mode, .global_rate_hz = c.hz});
        const TraceError e = CompareTraces(ref, run);
        std::printf("%-15s %-12s %-14s | %8.2f %8.2f | %9.2e %9.2e | %9.4f %9.4f | %8.3f\n", name, ScriptName(script),
                    c.label, 100 * e.force_rms / e.peak_force, 100 * e.force_max / e.peak_force, e.surface_rms,
                    e.surface_max, e.jump_at_update_max, e.jump_elsewhere_max, run.global_step_ms);
        if (c.mode == RunMode::kTwoRate) {
          // The update's own part: the same run with its exchanges half a slow step later.
          const int32_t k = static_cast<int32_t>(1000 / c.hz);
          const ScriptedTrace shifted =
              RunScripted(model, {.script = script, .mode = c.mode, .global_rate_hz = c.hz, .global_phase = k / 2});
          const UpdateJump u = CompareShifted(run, shifted);
          std::printf(
              "%-15s %-12s %-14s   against the run shifted half a slow step: largest change at its updates "
              "%.4f N, at other ticks %.4f N\n",
              "", "", "", u.at_update_max, u.elsewhere_max);
          const double edges[] = {1e-4, 1e-3, 5e-3, 1e-2, 5e-2};
          int bins[6] = {0, 0, 0, 0, 0, 0};
          for (const double j : e.jumps_at_update) {
            int b = 0;
            while (b < 5 && j >= edges[b]) ++b;
            ++bins[b];
          }
          std::printf(
              "%-15s %-12s %-14s   force changes at updates (N): <1e-4 %d, <1e-3 %d, <5e-3 %d, <1e-2 %d, "
              "<5e-2 %d, >=5e-2 %d\n",
              "", "", "", bins[0], bins[1], bins[2], bins[3], bins[4], bins[5]);
        }
        std::fflush(stdout);
      }
    }
  }
  std::printf(
      "\nf rms %% / f max %% = |f - f_ref| over every tick, RMS and largest, in %% of the reference's peak |f|;\n"
      "surf = |p - p_ref| of the external atoms every 10 ticks (model units); jump@upd = the largest change of f from\n"
      "one tick to the next beyond the reference's own change, at the tick after a global result was taken; jump\n"
      "else = the same at every other tick (N); membranes: home k 1.5 and 0.3 (elements 15); step ms = one\n"
      "global step's wall time (the whole model over 20 or 10 local ticks). Reference: the whole model at 1 kHz.\n");
  return 0;
}
