// Global dynamics at a slower rate beside local simulation (thesis 7.2.2). Local simulation moves
// only the haptic window, so a pluck that should lift a membrane lifts a dimple. Here a second
// pass steps the whole model every K local ticks (global_rate_hz = 1 / (K T)): it takes the
// atoms the local pass moved as boundary conditions (held at their latest local state through
// its step), steps the rest in full mode with the local tick as its substep (the fused pass, on
// its own threads if asked), and hands its result back; the local pass then moves every atom
// outside its window from where it is to that result, linearly over the next K ticks, so nothing
// jumps. A result lags the local state by one slow step (the step it took to compute), in both
// modes below, so an offline run shows what a device sees. When results come further apart (a
// model too large for the rate), each blend spans the interval the last two came apart.
//
// Two modes. Synchronous: the global step runs inside AfterTick at the exchange (offline runs,
// `idms-sim run --global-rate`, reproducible to the bit). Threaded: it runs on a thread of its
// own; AfterTick never waits for it (no lock, no allocation: it publishes the window through an
// atomic hand-off and takes a result only when one is ready), and a global step that takes longer
// than K ticks is counted (`late`) and its rate reported (`reachable_hz`), instead of the local
// pass falling behind.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

#include "idms/sim/model.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"

namespace idms {

struct GlobalOptions {
  double rate_hz = 0;     // 0 = off (the thesis's local-only mode); else rounded to K = 1 / (rate T) ticks
  bool threaded = false;  // the global step on its own thread (else inside AfterTick)
  int32_t threads = 1;    // StepOptions::threads of the global pass (full mode, renumbered models)
  // Tests only: the global thread sleeps this long after each step (a pass made artificially slow).
  int32_t extra_delay_us = 0;
  // Benches: the exchanges come this many ticks earlier in each period (0 = at multiples of K).
  int32_t phase = 0;
};

// Model units: a result moves an atom only when it differs by more than this from the position
// last handed over for it (a tenth of the viewer stream's quantization step).
inline constexpr double kGlobalEpsilon = 1e-5;

struct GlobalStats {
  int64_t steps = 0;        // global steps taken
  int64_t exchanges = 0;    // exchanges at which a result was taken
  int64_t late = 0;         // exchanges at which the threaded step had not finished (nothing taken)
  double last_step_ms = 0;  // wall time of the last global step
  double reachable_hz = 0;  // 1 / (its mean step time): the rate this model can run at
  bool stopped = false;     // a cut changed the local model: the global pass stopped (its copy is the old one)
};

class GlobalDynamics {
 public:
  // Copies of `model` and `state` become the global pass's own (the local model may change under
  // the loop: a cut stops the global pass, see GlobalStats::stopped); `local` are the local pass's options (its tick
  // T, integrator and damping; the global pass runs them in full mode, energy check off: the
  // local pass is what the device feels and keeps its own). Allocates; starts the thread.
  GlobalDynamics(const Model& model, const State& state, const StepOptions& local, const GlobalOptions& options);
  ~GlobalDynamics();
  GlobalDynamics(const GlobalDynamics&) = delete;
  GlobalDynamics& operator=(const GlobalDynamics&) = delete;

  // After each local Step(model, s, ws, ...): the atoms outside the local window move toward the
  // last global result (refiled in ws's spatial hash); every K ticks the window goes to the
  // global pass and its latest result becomes the target. O(window + atoms the result moved) per
  // tick: the global pass lists the atoms whose result differs by more than kGlobalEpsilon from
  // what it last handed over (so no atom drifts further than that from the global state). No
  // allocation, no lock, no wait.
  void AfterTick(State& s, Workspace& ws);

  int32_t ticks_per_step() const { return k_; }
  GlobalStats stats() const;

 private:
  void Exchange(const State& s);
  void RunJob();  // one global step from the published window (either mode)
  void ThreadMain();

  const Model m_;          // the global pass's copy
  uint64_t topology_ = 0;  // the local workspace's topology at the first AfterTick
  bool started_ = false, stopped_ = false;
  const GlobalOptions options_;
  int32_t k_ = 1;
  int64_t ticks_ = 0;
  // The global pass's own state (only RunJob touches it once the thread runs).
  State gs_;
  Workspace gws_;
  // The atoms the local pass moved since the last exchange (AfterTick's alone).
  std::vector<uint8_t> local_moved_;  // (atoms)
  std::vector<int32_t> moved_;
  int32_t moved_n_ = 0;
  // The window hand-off: those atoms with their state at the exchange (written by AfterTick,
  // read by RunJob after the hand-off).
  std::vector<int32_t> window_;
  int32_t window_n_ = 0;
  std::vector<Real> window_pos_, window_vel_;  // by index in window_
  // Results, two so that the loop blends from one while the thread writes the other: the atoms
  // whose position changed by more than kGlobalEpsilon and their new positions (by index).
  struct Result {
    std::vector<int32_t> atoms;
    std::vector<Real> pos;
    int32_t n = 0;
  };
  Result results_[2];
  std::vector<Real> sent_;  // (atoms x 3) the position last handed over per atom (RunJob's)
  // Jobs published; job j (from 1) writes results_[(j - 1) % 2]. Changed by AfterTick only while
  // no job runs, read by the job after the hand-off.
  int64_t jobs_ = 0;
  // The blend: these atoms go from `from_` to `to_` over K ticks (blend_[a] = 0 once the local
  // pass takes one).
  std::vector<int32_t> blend_list_;
  int32_t blend_n_ = 0;
  std::vector<Real> from_, to_;  // (atoms x 3)
  std::vector<uint8_t> blend_;   // (atoms)
  int32_t phase_ = 0;            // ticks into the blend period
  int32_t span_ = 1;             // its length: the ticks between the last two results taken, at least K
  int64_t last_take_ = -1;       // ticks_ when the last result was taken; -1 = none yet
  bool have_target_ = false;
  // Threaded mode's hand-offs: 0 idle, 1 job published, 2 result ready.
  std::atomic<int32_t> slot_{0};
  std::atomic<bool> quit_{false};
  std::atomic<int64_t> steps_{0};
  std::atomic<int64_t> step_ns_total_{0};
  std::atomic<int64_t> last_step_ns_{0};
  int64_t exchanges_ = 0, late_ = 0;
  std::thread thread_;
};

}  // namespace idms
