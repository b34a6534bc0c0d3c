// The agent's 1 kHz loop: device read, DSM step, device write, one sample per tick into a
// lock-free ring, and every 1/60 s the surface positions into a pool of preallocated buffers.
// It never allocates, locks, logs or touches the network; the I/O thread (uplink.h) drains it.
#pragma once

#include <array>
#include <atomic>
#include <boost/lockfree/spsc_queue.hpp>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "idms/agent/device.h"
#include "idms/agent/histogram.h"
#include "idms/agent/realtime.h"
#include "idms/agent/registration.h"
#include "idms/agent/thread_owner.h"
#include "idms/sim/global.h"
#include "idms/sim/model.h"
#include "idms/sim/passivity.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"
#include "idms/sim/tool.h"
#include "idms/sim/workspace.h"

namespace idms::agent {

// One tick, loop -> I/O thread. Plain data: the ring copies it.
struct TickSample {
  uint64_t tick = 0;
  double time_s = 0;               // simulation time at the end of the tick, s
  double tool_pos[3] = {0, 0, 0};  // MIO centre, model frame and units
  double force[3] = {0, 0, 0};     // force commanded on the device, model frame, after the guard
  uint32_t compute_us = 0;         // read + step + write, µs
  uint32_t period_us = 0;          // since the previous tick's wake-up, µs; 0 on the first tick
  uint32_t substeps = 0;
  uint32_t warnings = 0;  // warnings raised this tick (the step's, plus a zeroed device force)
  uint32_t num_contacts = 0;
  bool contact = false, grasp = false;
  bool overrun = false;        // the work ended after the next deadline
  bool force_limited = false;  // the device force was clamped at its limit this tick
  bool reset = false;          // the model was put back to rest at the start of this tick (a command)
  // Friction (ToolReport): the tangential part of `force` (scaled as it was clamped), the normal
  // force, the state.
  double friction_force[3] = {0, 0, 0};
  double normal_force = 0;
  FrictionState friction = FrictionState::kNone;
  // The passivity controller (LoopOptions::passivity), when on: the port energy since the start and
  // its windowed part (force units * model units), the damping it added (force units * s / model
  // unit). All 0 when off.
  double port_energy = 0;
  double port_energy_window = 0;
  double passivity_damping = 0;
  // The tool's orientation, model frame, unit quaternion (w, x, y, z), when the device gave one
  // (`oriented`); a needle's punctured state and inserted length (model units).
  double orientation[4] = {1, 0, 0, 0};
  bool oriented = false;
  bool needle_punctured = false;
  double needle_inserted = 0;
  // The needle through the far side, and its suture (SutureReport): this tick's new points drawn
  // through, a knot tied or refused, a break; the thread's points and knots so far.
  bool needle_exited = false;
  bool tie = false;        // the needle's tie command (its button) this tick
  uint8_t tool_index = 0;  // the scene tool the device held (DeviceSample.tool_index)
  // The incision's gap now and open (DeviceSample.incision_gap, incision_open); 0 before a cut.
  double incision_gap = 0, incision_open = 0;
  uint8_t suture_new_punctures = 0;
  bool suture_tied = false, suture_tie_refused = false, suture_broke = false;
  uint16_t suture_punctures = 0, suture_ties = 0;
};

// A surface snapshot in a preallocated pool slot, loop -> I/O thread and back.
struct MeshSlot {
  uint64_t tick = 0;
  double time_s = 0;
  uint64_t topology_version = 0;
  bool final_frame = false;        // the last frame, published after the last tick
  std::vector<double> pos;         // (num_external x 3), model units; sized once
  int32_t num_tris = -1;           // triangles in tri_verts when the topology changed, else -1
  std::vector<int32_t> tri_verts;  // (num_tris x 3) vertex ids; capacity of the initial surface
  // The suture thread (State::suture) when there is one: its nodes and punctures (model frame,
  // float), its knots, the parted segment + 1 (0: whole). Fixed arrays: publishing allocates nothing.
  int32_t suture_nodes = 0;
  std::array<float, 3 * (kSutureSegments + 1)> suture_pos{};
  int32_t suture_punctures = 0;
  std::array<float, 3 * kSuturePunctures> suture_puncture_pos{};
  int32_t suture_ties = 0;
  int32_t suture_broken = 0;
};

// A command from the server, I/O thread -> loop. Tweezers close/open hold until the device's own
// button changes (or kTweezersDevice hands control back); kReset returns the model to rest (its
// rest copy is prepared by Loop::PushCommand, off the loop).
struct LoopCommand {
  enum Kind : uint8_t { kTweezersClose, kTweezersOpen, kTweezersDevice, kReset };
  Kind kind = kReset;
  int32_t tool = 0;
};

// A model with its state and workspace: what the loop steps, and what a reset swaps in whole.
// With LoopOptions::global_rate_hz, the set's global pass too (its own thread, started where the
// set is made and stopped where it is freed: both off the loop).
struct SimSet {
  Model model;
  State state;
  Workspace workspace;
  std::unique_ptr<GlobalDynamics> global;
};

struct LoopOptions {
  double rate_hz = 1000;           // wake-ups per second
  double mesh_rate_hz = 60;        // surface snapshots per simulated second
  int64_t max_ticks = 0;           // stop after this many ticks; 0 = until RequestStop
  uint32_t sample_ring = 1 << 14;  // samples the I/O thread may fall behind before some are lost
  uint32_t mesh_pool = 8;          // surface buffers in flight
  bool realtime = true;            // try SCHED_FIFO, mlockall, 1 ns timer slack, cpu_dma_latency 0
  int fifo_priority = 80;
  int cpu = -1;         // pin the loop thread to this CPU before the first tick; -1 = not pinned
  int64_t spin_ns = 0;  // sleep to deadline - spin_ns, then poll the clock to the deadline; 0 = off
  // The passivity observer and controller between the step's device force and the guard, in the
  // model frame and units (PassivityFromScene); off (the default): not run at all.
  PassivityOptions passivity;
  // Global dynamics at a slower rate beside the local pass (thesis 7.2.2; sim/global.h): the
  // whole model at this rate on a thread of its own; 0 = off (the thesis's local-only mode).
  double global_rate_hz = 0;
  int32_t global_threads = 1;   // StepOptions::threads of the global pass
  bool global_threaded = true;  // false: each global step inside the tick (tests: reproducible)
  // The scene's tools (SceneTools): the device holds the first, the loop's `tool`, until it picks
  // another (DeviceReading::tool). Without them (num_tools 0) it holds `tool` only.
  std::array<ToolCommand, kMaxTools> tools{};
  int32_t num_tools = 0;
};

// Counters the loop publishes (relaxed atomics: any thread may read them).
struct LoopCounters {
  std::atomic<uint64_t> ticks{0};
  std::atomic<uint64_t> overruns{0};
  std::atomic<uint64_t> samples_lost{0};  // the sample ring was full (the I/O thread stalled)
  std::atomic<uint64_t> mesh_skipped{0};  // no free surface buffer at a snapshot time
  std::atomic<uint64_t> force_faults{0};  // non-finite device force zeroed at the write
  std::atomic<uint64_t> pose_faults{0};   // non-finite device positions, treated as no pose
  std::atomic<uint64_t> commands{0};
  // Wake-ups one full period or more after their scheduled time (the tick's deadline passed
  // before it started): the loop's count of what cyclictest reports as latency >= the period.
  std::atomic<uint64_t> late_wakeups{0};
  std::atomic<uint64_t> resets{0};              // prepared rest states swapped in
  std::atomic<uint64_t> passivity_ticks{0};     // ticks the passivity controller added damping
  std::atomic<double> passivity_dissipated{0};  // the work its damping took out, force * model units
  // The global pass (LoopOptions::global_rate_hz): its steps, the exchanges that found it still
  // stepping, and the rate it can reach on this model (GlobalStats).
  std::atomic<int64_t> global_steps{0};
  std::atomic<int64_t> global_late{0};
  std::atomic<double> global_reachable_hz{0};
};

class Loop {
 public:
  // tool: tool slot 0 as the scene configures it (kind, radius, stiffness, law); the device
  // drives its position and, for tweezers, its closing. The model, step options and registration
  // are fixed for the loop's life. Allocates every buffer here.
  Loop(Model model, const StepOptions& step_options, const ToolCommand& tool, const Registration& registration,
       Device& device, const LoopOptions& options);
  Loop(const Loop&) = delete;
  Loop& operator=(const Loop&) = delete;
  ~Loop();  // lets go of /dev/cpu_dma_latency

  // The thread body: real-time setup (reported on stderr before the first tick), ticks on
  // absolute deadlines until RequestStop or max_ticks, then the device released, and the final
  // surface published. Run once, on the loop thread.
  void Run();

  // One tick's work at wall time wake_ns (CLOCK_MONOTONIC) for the deadline deadline_ns; the tick
  // was scheduled to wake at deadline_ns - one period. Public for tests, which drive it without
  // sleeping. Loop thread; does not allocate.
  void Tick(int64_t wake_ns, int64_t deadline_ns);

  // Two threads use a Loop: the loop thread (Run, Tick) and one I/O thread (the ring ends, commands
  // and resets below). Each side belongs to the first thread that calls it; a call from another
  // thread is a bug, caught by ThreadOwner (debug builds abort; release builds count it in
  // wrong_thread_calls and the destructor says so on stderr).

  // Any thread, async-signal-safe: finish the current tick and stop.
  void RequestStop() { stop_.store(true, std::memory_order_relaxed); }
  // True once Run has returned its device released and its final frame published (acquire).
  bool finished() const { return finished_.load(std::memory_order_acquire); }

  // I/O thread side of the rings (single consumer / single producer for commands).
  boost::lockfree::spsc_queue<TickSample>& samples() {
    io_thread_.Check("Loop::samples");
    return samples_;
  }
  // Indices into slot(): full ones to read, then hand back with ReleaseMeshSlot.
  bool PopMeshSlot(int32_t* index) {
    io_thread_.Check("Loop::PopMeshSlot");
    return mesh_full_.pop(*index);
  }
  void ReleaseMeshSlot(int32_t index) {
    io_thread_.Check("Loop::ReleaseMeshSlot");
    mesh_free_.push(index);
  }
  const MeshSlot& slot(int32_t index) const { return slots_[static_cast<size_t>(index)]; }
  // I/O thread (the single producer). A kReset first copies the rest model, state and workspace
  // on the calling thread (allocates, O(model)) and queues the copy ahead of the command; the tick
  // that applies it swaps the copy in (O(1), no allocation, no copy) and hands the set it
  // replaced back for CollectResets. At most kResetsInFlight copies exist outside the loop at a
  // time. False, with nothing queued, when the command ring or the reset handoff is full.
  bool PushCommand(const LoopCommand& command);
  // I/O thread: frees the sets replaced by resets (O(model) each, off the loop; their global
  // passes stop there, waiting for a global step in progress); how many.
  int CollectResets();
  // The current set's global pass (zeros without one). Loop thread, or any thread once the loop
  // has stopped (the set is the loop's to swap).
  GlobalStats global_stats() const;
  static constexpr int kResetsInFlight = 2;

  const LoopOptions& options() const { return options_; }
  const LoopCounters& counters() const { return counters_; }
  // Calls from a thread that does not own their side (0 unless there is a bug; any thread).
  uint64_t wrong_thread_calls() const { return tick_thread_.violations() + io_thread_.violations(); }
  bool realtime() const { return realtime_.load(std::memory_order_relaxed); }

  // Loop-thread data: read only after finished() (or from the loop thread), or before Run. The
  // model and state references are invalidated by a reset.
  const Model& model() const { return sim_->model; }
  const State& state() const { return sim_->state; }
  const LatencyHistogram& period_histogram() const { return period_hist_; }
  const LatencyHistogram& compute_histogram() const { return compute_hist_; }
  // Wake-up minus scheduled wake-up, µs: cyclictest's latency, measured the same way.
  const LatencyHistogram& wake_histogram() const { return wake_hist_; }
  RealtimeReport realtime_report() const { return rt_report_; }

 private:
  // The set's global pass, when the options ask for one (allocates, starts its thread).
  void StartGlobal(SimSet& set) const;
  void SetUpThread();  // real-time setup and pinning of the calling thread, said on stderr
  void ApplyCommands();
  bool PublishMesh(bool final_frame);  // false when no buffer was free
  // The incision's gap over its lips now (at the stream rate, or once a cut added lips).
  void MeasureIncision(const State& state);
  void Reset();

  // Simulation (loop thread). sim_ is replaced whole by a reset; rest_ is immutable after the
  // constructor, so the I/O thread copies it while the loop runs.
  std::unique_ptr<SimSet> sim_;
  std::unique_ptr<const SimSet> rest_;
  uint64_t rest_topology_ = 0;  // the topology version of the model at rest (a cut changes the model's)
  StepOptions step_options_;
  ToolInput input_;
  Registration registration_;
  PassivityController passivity_;  // run only when options_.passivity.enabled
  Device& device_;
  LoopOptions options_;

  // Tick bookkeeping (loop thread).
  int64_t period_ns_ = 1000000;
  int64_t prev_wake_ns_ = -1;
  double next_mesh_time_s_ = 0;
  double mesh_interval_s_ = 1.0 / 60;
  uint64_t published_topology_ = UINT64_MAX;
  bool has_pose_ = false;
  double orientation_[4] = {1, 0, 0, 0};  // the tool's, model frame, once the device gave one
  bool oriented_ = false;
  int32_t tool_index_ = 0;  // the scene tool the device holds (LoopOptions::tools)
  // The incision's lips: the atom pairs of the surface elements the scalpel cut (up to
  // kMaxIncisionPairs, the first cut), and the sum of their rest lengths. A reset forgets them.
  static constexpr int32_t kMaxIncisionPairs = 1024;
  std::array<std::array<int32_t, 2>, kMaxIncisionPairs> incision_pairs_{};
  int32_t num_incision_pairs_ = 0;
  double incision_open_sum_ = 0;
  double incision_gap_ = 0;        // their mean distance when last measured (MeasureIncision)
  bool incision_due_ = false;      // a cut added pairs: measure at once
  int8_t tweezers_override_ = -1;  // -1 = the device decides, 0 = held open, 1 = held closed
  bool reset_this_tick_ = false;   // Reset() ran in this tick's commands: the sample says so
  bool override_button_ = false;   // the device's button when the override was commanded
  bool last_button_ = false;       // the device's button last tick
  LatencyHistogram period_hist_;
  LatencyHistogram compute_hist_;
  LatencyHistogram wake_hist_;
  RealtimeReport rt_report_;
  int dma_latency_fd_ = -1;  // open while the loop runs: the kernel drops the request on close

  // Rings: samples out, surface slots out and back, commands in.
  boost::lockfree::spsc_queue<TickSample> samples_;
  std::vector<MeshSlot> slots_;
  boost::lockfree::spsc_queue<int32_t> mesh_full_;
  boost::lockfree::spsc_queue<int32_t> mesh_free_;
  boost::lockfree::spsc_queue<LoopCommand> commands_;
  // Reset handoff: prepared rest sets in (pushed before their kReset), replaced sets out. Owned
  // raw pointers: spsc_queue needs trivially copyable items; the destructor frees what is left.
  boost::lockfree::spsc_queue<SimSet*> reset_ready_;
  boost::lockfree::spsc_queue<SimSet*> reset_spent_;
  int resets_in_flight_ = 0;  // I/O thread: sets pushed to reset_ready_ and not yet collected

  // Who may call what: Run, Tick and everything they call; the rings' other ends, PushCommand and
  // CollectResets. The default policy: a wrong call may come from the loop thread itself, which
  // must not abort in a release build.
  ThreadOwner tick_thread_{"the loop's tick side (Run, Tick)"};
  ThreadOwner io_thread_{"the loop's I/O side (sample and mesh rings, commands, resets)"};

  LoopCounters counters_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> finished_{false};
  std::atomic<bool> realtime_{false};
};

}  // namespace idms::agent
