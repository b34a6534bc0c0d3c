// The agent's 1 kHz loop: device read, DSM step, device write, one sample per tick into a
// lock-free ring, and every 1/60 s the surface positions into a pool of preallocated buffers.
// It never allocates, locks, logs or touches the network; the I/O thread (uplink.h) drains it.
#pragma once

#include <atomic>
#include <boost/lockfree/spsc_queue.hpp>
#include <cstdint>
#include <vector>

#include "idms/agent/device.h"
#include "idms/agent/histogram.h"
#include "idms/agent/registration.h"
#include "idms/sim/model.h"
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
  bool overrun = false;  // the work ended after the next deadline
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
};

// A command from the server, I/O thread -> loop. Tweezers close/open hold until the device's own
// button changes (or kTweezersDevice hands control back); kReset returns the model to rest.
struct LoopCommand {
  enum Kind : uint8_t { kTweezersClose, kTweezersOpen, kTweezersDevice, kReset };
  Kind kind = kReset;
  int32_t tool = 0;
};

struct LoopOptions {
  double rate_hz = 1000;           // wake-ups per second
  double mesh_rate_hz = 60;        // surface snapshots per simulated second
  int64_t max_ticks = 0;           // stop after this many ticks; 0 = until RequestStop
  uint32_t sample_ring = 1 << 14;  // samples the I/O thread may fall behind before some are lost
  uint32_t mesh_pool = 8;          // surface buffers in flight
  bool realtime = true;            // try SCHED_FIFO, mlockall and zero timer slack
  int fifo_priority = 80;
};

// What the real-time setup achieved, reported before the first tick.
struct RealtimeReport {
  bool fifo = false, mlock = false, timer_slack = false;
  int fifo_errno = 0, mlock_errno = 0;
};

// Counters the loop publishes (relaxed atomics: any thread may read them).
struct LoopCounters {
  std::atomic<uint64_t> ticks{0};
  std::atomic<uint64_t> overruns{0};
  std::atomic<uint64_t> samples_lost{0};  // the sample ring was full (the I/O thread stalled)
  std::atomic<uint64_t> mesh_skipped{0};  // no free surface buffer at a snapshot time
  std::atomic<uint64_t> force_faults{0};  // non-finite device force zeroed at the write
  std::atomic<uint64_t> commands{0};
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

  // The thread body: real-time setup (reported on stderr before the first tick), ticks on
  // absolute deadlines until RequestStop or max_ticks, then the device released, and the final
  // surface published. Run once, on the loop thread.
  void Run();

  // One tick's work at wall time wake_ns (CLOCK_MONOTONIC) for the deadline deadline_ns. Public
  // for tests, which drive it without sleeping. Loop thread; does not allocate.
  void Tick(int64_t wake_ns, int64_t deadline_ns);

  // Any thread, async-signal-safe: finish the current tick and stop.
  void RequestStop() { stop_.store(true, std::memory_order_relaxed); }
  // True once Run has returned its device released and its final frame published (acquire).
  bool finished() const { return finished_.load(std::memory_order_acquire); }

  // I/O thread side of the rings (single consumer / single producer for commands).
  boost::lockfree::spsc_queue<TickSample>& samples() { return samples_; }
  // Indices into slot(): full ones to read, then hand back with ReleaseMeshSlot.
  bool PopMeshSlot(int32_t* index) { return mesh_full_.pop(*index); }
  void ReleaseMeshSlot(int32_t index) { mesh_free_.push(index); }
  const MeshSlot& slot(int32_t index) const { return slots_[static_cast<size_t>(index)]; }
  bool PushCommand(const LoopCommand& command) { return commands_.push(command); }

  // Set before Run; read-only while it runs.
  const Model& model() const { return model_; }
  const LoopOptions& options() const { return options_; }
  const LoopCounters& counters() const { return counters_; }
  bool realtime() const { return realtime_.load(std::memory_order_relaxed); }

  // Loop-thread data: read only after finished() (or from the loop thread).
  const LatencyHistogram& period_histogram() const { return period_hist_; }
  const LatencyHistogram& compute_histogram() const { return compute_hist_; }
  const State& state() const { return state_; }
  RealtimeReport realtime_report() const { return rt_report_; }

 private:
  void ApplyCommands();
  bool PublishMesh(bool final_frame);  // false when no buffer was free
  void Reset();

  // Simulation (loop thread).
  Model model_;
  StepOptions step_options_;
  State state_;
  Workspace workspace_;
  Model rest_model_;  // for Reset: plain copies into buffers of the same capacity, no allocation
  State rest_state_;
  Workspace rest_workspace_;
  ToolInput input_;
  Registration registration_;
  Device& device_;
  LoopOptions options_;

  // Tick bookkeeping (loop thread).
  int64_t period_ns_ = 1000000;
  int64_t prev_wake_ns_ = -1;
  double next_mesh_time_s_ = 0;
  double mesh_interval_s_ = 1.0 / 60;
  uint64_t published_topology_ = UINT64_MAX;
  bool has_pose_ = false;
  int8_t tweezers_override_ = -1;  // -1 = the device decides, 0 = held open, 1 = held closed
  bool override_button_ = false;   // the device's button when the override was commanded
  bool last_button_ = false;       // the device's button last tick
  LatencyHistogram period_hist_;
  LatencyHistogram compute_hist_;
  RealtimeReport rt_report_;

  // Rings: samples out, surface slots out and back, commands in.
  boost::lockfree::spsc_queue<TickSample> samples_;
  std::vector<MeshSlot> slots_;
  boost::lockfree::spsc_queue<int32_t> mesh_full_;
  boost::lockfree::spsc_queue<int32_t> mesh_free_;
  boost::lockfree::spsc_queue<LoopCommand> commands_;

  LoopCounters counters_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> finished_{false};
  std::atomic<bool> realtime_{false};
};

// CLOCK_MONOTONIC now, ns.
int64_t MonotonicNs();

// Tries SCHED_FIFO at `priority` for the calling thread, mlockall(MCL_CURRENT | MCL_FUTURE) and
// a 1 ns timer slack; reports what worked. Not for the tick itself (it makes system calls).
RealtimeReport SetUpRealtime(int priority);

}  // namespace idms::agent
