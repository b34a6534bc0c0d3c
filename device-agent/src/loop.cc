// The loop thread: absolute-deadline ticks of device read, DSM step and device write, with
// samples and surface snapshots handed to the I/O thread through lock-free rings.
#include "idms/agent/loop.h"

#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "idms/sim/edit.h"
#include "idms/sim/surface.h"

namespace idms::agent {
namespace {

uint32_t ToMicros(int64_t ns) { return ns <= 0 ? 0u : static_cast<uint32_t>(std::min<int64_t>(ns / 1000, UINT32_MAX)); }

// Touches a stack region once so page faults happen before the first tick, not during one.
[[gnu::noinline]] void PrefaultStack() {
  volatile unsigned char buf[256 * 1024];
  for (size_t i = 0; i < sizeof(buf); i += 4096) buf[i] = 0;
}

}  // namespace

Loop::Loop(Model model, const StepOptions& step_options, const ToolCommand& tool, const Registration& registration,
           Device& device, const LoopOptions& options)
    : sim_(std::make_unique<SimSet>()),
      step_options_(step_options),
      registration_(registration),
      device_(device),
      options_(options),
      samples_(options.sample_ring),
      mesh_full_(options.mesh_pool + 1),
      mesh_free_(options.mesh_pool + 1),
      commands_(64),
      reset_ready_(kResetsInFlight),
      reset_spent_(kResetsInFlight) {
  // Simulation buffers, and their rest copy for PushCommand's resets.
  SimSet& sim = *sim_;
  sim.model = std::move(model);
  sim.state = MakeState(sim.model);
  sim.workspace = MakeWorkspace(sim.model, step_options_);
  // No madvise from the loop's first full-mode tick: huge pages pay only past the caches, far
  // beyond what a 1 kHz full-mode scene can step.
  // Filed now, so the first tick does not refile every atom (O(atoms): ~1 ms at 10^5). The rest
  // copy is filed too, so a reset swaps in a workspace that needs no refiling either.
  ResyncWorkspace(sim.model, sim.state, sim.workspace);
  rest_ = std::make_unique<const SimSet>(SimSet{sim.model, sim.state, sim.workspace, nullptr});
  StartGlobal(sim);
  rest_topology_ = sim.model.topology_version;
  input_.tools[0] = tool;
  input_.num_tools = 0;
  if (options_.passivity.enabled) passivity_ = PassivityController(options_.passivity);
  // Timing.
  period_ns_ = std::max<int64_t>(1, std::llround(1e9 / options_.rate_hz));
  mesh_interval_s_ = 1.0 / options_.mesh_rate_hz;
  // The surface pool: every buffer sized for the whole surface and topology.
  slots_.resize(options_.mesh_pool);
  for (size_t i = 0; i < slots_.size(); ++i) {
    slots_[i].pos.assign(3 * static_cast<size_t>(sim.model.num_external), 0.0);
    slots_[i].tri_verts.assign(3 * static_cast<size_t>(sim.model.num_tris), 0);
    mesh_free_.push(static_cast<int32_t>(i));
  }
}

Loop::~Loop() {
  if (dma_latency_fd_ >= 0) close(dma_latency_fd_);
  if (wrong_thread_calls() > 0) {
    std::fprintf(stderr, "idms-agent: BUG: %llu calls to the loop from a thread that does not own them\n",
                 static_cast<unsigned long long>(wrong_thread_calls()));
  }
  // Rest sets never applied, and replaced ones never collected.
  reset_ready_.consume_all([](SimSet* set) { delete set; });
  reset_spent_.consume_all([](SimSet* set) { delete set; });
}

bool Loop::PushCommand(const LoopCommand& command) {
  io_thread_.Check("Loop::PushCommand");
  if (command.kind != LoopCommand::kReset) return commands_.push(command);
  // Room for both first: this thread is the only producer, so the room cannot shrink meanwhile,
  // and no prepared set is left behind without its command.
  if (commands_.write_available() == 0 || resets_in_flight_ >= kResetsInFlight) return false;
  // The copy of the rest set: the O(model) work a reset used to do inside one tick; its global
  // pass starts here too (the spent set's stops in CollectResets, on this thread as well).
  auto set = std::make_unique<SimSet>(SimSet{rest_->model, rest_->state, rest_->workspace, nullptr});
  StartGlobal(*set);
  reset_ready_.push(set.release());
  ++resets_in_flight_;
  return commands_.push(command);
}

void Loop::StartGlobal(SimSet& set) const {
  if (!(options_.global_rate_hz > 0)) return;
  set.global = std::make_unique<GlobalDynamics>(set.model, set.state, step_options_,
                                                GlobalOptions{.rate_hz = options_.global_rate_hz,
                                                              .threaded = options_.global_threaded,
                                                              .threads = options_.global_threads});
}

GlobalStats Loop::global_stats() const {
  const SimSet* set = sim_.get();
  return set != nullptr && set->global ? set->global->stats() : GlobalStats{};
}

int Loop::CollectResets() {
  io_thread_.Check("Loop::CollectResets");
  return static_cast<int>(reset_spent_.consume_all([this](SimSet* set) {
    delete set;
    --resets_in_flight_;
  }));
}

void Loop::SetUpThread() {
  // Real-time setup, said plainly when refused.
  if (options_.realtime) {
    rt_report_ = SetUpRealtime(options_.fifo_priority, &dma_latency_fd_);
    realtime_.store(rt_report_.fifo && rt_report_.mlock, std::memory_order_relaxed);
    if (!rt_report_.fifo) {
      std::fprintf(stderr, "idms-agent: NOT real-time: SCHED_FIFO refused (%s); the loop runs at normal priority\n",
                   std::strerror(rt_report_.fifo_errno));
    }
    if (!rt_report_.mlock) {
      std::fprintf(stderr, "idms-agent: NOT real-time: mlockall refused (%s); page faults may delay ticks\n",
                   std::strerror(rt_report_.mlock_errno));
    }
    if (rt_report_.fifo && rt_report_.mlock) {
      std::fprintf(stderr, "idms-agent: real-time: SCHED_FIFO priority %d, memory locked\n", options_.fifo_priority);
    }
    if (rt_report_.dma_latency) {
      std::fprintf(stderr, "idms-agent: CPU idle exit latency held at 0 us (/dev/cpu_dma_latency)\n");
    } else {
      std::fprintf(stderr,
                   "idms-agent: note: /dev/cpu_dma_latency refused (%s); waking from a deep CPU idle state may "
                   "delay ticks\n",
                   std::strerror(rt_report_.dma_latency_errno));
    }
  } else {
    SetMinimalTimerSlack();
    std::fprintf(stderr, "idms-agent: NOT real-time: disabled by --no-realtime\n");
  }
  // CPU pinning, before the first tick; refused = the loop runs wherever the scheduler puts it.
  if (options_.cpu >= 0) {
    rt_report_.pin_errno = PinThisThread(options_.cpu);
    rt_report_.pinned = rt_report_.pin_errno == 0;
    if (rt_report_.pinned) {
      std::fprintf(stderr, "idms-agent: loop pinned to CPU %d\n", options_.cpu);
    } else {
      std::fprintf(stderr, "idms-agent: NOT pinned: CPU %d refused (%s); the loop runs on any CPU\n", options_.cpu,
                   std::strerror(rt_report_.pin_errno));
    }
  }
  if (options_.spin_ns > 0) {
    std::fprintf(stderr, "idms-agent: spinning the last %lld us before each deadline\n",
                 static_cast<long long>(options_.spin_ns / 1000));
  }
}

void Loop::Run() {
  tick_thread_.Check("Loop::Run");
  SetUpThread();
  PrefaultStack();

  // Ticks on absolute deadlines.
  int64_t next_ns = MonotonicNs();
  while (!stop_.load(std::memory_order_relaxed) && !device_.finished() &&
         (options_.max_ticks == 0 || sim_->state.tick < options_.max_ticks)) {
    Tick(WaitUntil(next_ns, options_.spin_ns), next_ns + period_ns_);
    next_ns += period_ns_;
    // Behind schedule: skip the missed wake-ups rather than run them back to back.
    const int64_t now_ns = MonotonicNs();
    if (now_ns >= next_ns) next_ns += ((now_ns - next_ns) / period_ns_ + 1) * period_ns_;
  }

  // Let the device go, then publish the final surface (waiting for a buffer is fine now).
  device_.Release();
  const int64_t give_up_ns = MonotonicNs() + 2000000000;
  while (!PublishMesh(true) && MonotonicNs() < give_up_ns) {
    const timespec pause{.tv_sec = 0, .tv_nsec = 1000000};
    nanosleep(&pause, nullptr);
  }
  finished_.store(true, std::memory_order_release);
}

void Loop::Tick(int64_t wake_ns, int64_t deadline_ns) {
  tick_thread_.Check("Loop::Tick");
  // Commands first: a reset replaces the set stepped below.
  ApplyCommands();
  Model& model = sim_->model;
  State& state = sim_->state;
  Workspace& workspace = sim_->workspace;
  const int64_t tick = state.tick;

  // Device read, mapped into the model frame; a device without a pose leaves the tool out.
  DeviceReading reading;
  device_.Read(tick, state.time_s, &reading);
  // A non-finite position is no pose: the tool holds where it was, and no NaN reaches the model,
  // a sample, a recording or a viewer.
  int pose_fault = 0;
  if (reading.valid &&
      !(std::isfinite(reading.pos[0]) && std::isfinite(reading.pos[1]) && std::isfinite(reading.pos[2]))) {
    reading.valid = false;
    pose_fault = 1;
    counters_.pose_faults.fetch_add(1, std::memory_order_relaxed);
  }
  // A change of tool (the suture's scalpel, then its needle): the scene's other tool from now on.
  if (reading.valid && reading.tool >= 0 && reading.tool < options_.num_tools && reading.tool != tool_index_) {
    input_.tools[0] = options_.tools[reading.tool];
    tool_index_ = reading.tool;
  }
  ToolCommand& tool = input_.tools[0];
  if (reading.valid) {
    registration_.DeviceToModel(reading.pos, tool.pos);
    has_pose_ = true;
    // An orientation that is no rotation (zero, non-finite) is a fault too: the tool keeps the last.
    if (reading.oriented) {
      if (registration_.OrientationToModel(reading.orientation, orientation_)) {
        oriented_ = true;
        NeedleAxisOf(orientation_, tool.axis);
      } else {
        pose_fault = 1;
        counters_.pose_faults.fetch_add(1, std::memory_order_relaxed);
      }
    }
  }
  // A tweezers command holds until the device's own button changes.
  if (tweezers_override_ >= 0 && reading.closed != override_button_) tweezers_override_ = -1;
  last_button_ = reading.closed;
  tool.closed = tweezers_override_ < 0 ? reading.closed : tweezers_override_ == 1;
  tool.tie = tool.kind == ToolKind::kNeedle && reading.closed;  // a needle's button ties its thread
  input_.num_tools = has_pose_ ? 1 : 0;

  // The DSM step; cuts found by a scalpel are applied between steps.
  const int64_t clamped_before = state.warnings.device_force_clamped;
  const StepReport report = Step(model, state, workspace, input_);
  if (report.pending_cuts > 0) {
    // The incision's lips: each cut surface element's two atoms (ids stay; elements move).
    for (int32_t i = 0; i < workspace.num_pending_cuts && num_incision_pairs_ < kMaxIncisionPairs; ++i) {
      const int32_t e = workspace.pending_cuts[i];
      const int32_t a = model.elem_atoms[2 * e], b = model.elem_atoms[2 * e + 1];
      if (model.elem_home[e] || !model.atom_external[a] || !model.atom_external[b]) continue;
      incision_pairs_[num_incision_pairs_++] = {a, b};
      incision_open_sum_ += model.elem_leq[e];
      incision_due_ = true;
    }
    ApplyPendingEdits(model, state, workspace);
  }

  // Device write: zero without a fresh pose; the guard is the last line of defence.
  const ToolReport& out = report.tools[0];
  double f_model[3] = {0, 0, 0};
  if (reading.valid && input_.num_tools > 0)
    f_model[0] = out.force[0], f_model[1] = out.force[1], f_model[2] = out.force[2];
  // The passivity controller: the port's energy from the position read and the force the device
  // held last tick; damping added to this tick's force when the port would turn active.
  PassivityTick passive;
  const bool passivity = options_.passivity.enabled;
  if (passivity) passive = passivity_.Update(tool.pos, reading.valid, f_model, report.energy_after, f_model);
  double f_device[3];
  registration_.ForceToDevice(f_model, f_device);
  const double asked = std::sqrt(f_device[0] * f_device[0] + f_device[1] * f_device[1] + f_device[2] * f_device[2]);
  const int fault = SanitizeDeviceForce(f_device, registration_.max_force);
  device_.Write(tick, f_device);
  const int64_t written_ns = MonotonicNs();
  registration_.ForceToModel(f_device, f_model);  // what the device was actually told
  if (fault != 0) counters_.force_faults.fetch_add(1, std::memory_order_relaxed);
  if (passivity) {
    passivity_.Commanded(f_model);
    if (passive.acted) counters_.passivity_ticks.fetch_add(1, std::memory_order_relaxed);
    counters_.passivity_dissipated.store(passivity_.dissipated(), std::memory_order_relaxed);
  }

  // The atoms outside the haptic window from the global pass (its window hand-off too): after the
  // device write, which it does not change, and before the snapshot, which shows it.
  if (sim_->global) {
    sim_->global->AfterTick(state, workspace);
    const GlobalStats g = sim_->global->stats();
    counters_.global_steps.store(g.steps, std::memory_order_relaxed);
    counters_.global_late.store(g.late, std::memory_order_relaxed);
    counters_.global_reachable_hz.store(g.reachable_hz, std::memory_order_relaxed);
  }

  // Surface snapshot at the stream rate, and the incision's gap with it (up to 1,024 pairs: not
  // every tick) or as soon as a cut adds lips.
  if (incision_due_ || state.time_s >= next_mesh_time_s_ - 1e-9) MeasureIncision(state);
  if (state.time_s >= next_mesh_time_s_ - 1e-9) {
    if (!PublishMesh(false)) counters_.mesh_skipped.fetch_add(1, std::memory_order_relaxed);
    while (next_mesh_time_s_ <= state.time_s + 1e-9) next_mesh_time_s_ += mesh_interval_s_;
  }

  // Timing, histograms and the sample.
  TickSample s;
  s.tick = static_cast<uint64_t>(tick);
  s.time_s = state.time_s;
  for (int i = 0; i < 3; ++i) s.tool_pos[i] = tool.pos[i], s.force[i] = f_model[i];
  s.compute_us = ToMicros(written_ns - wake_ns);
  s.period_us = prev_wake_ns_ < 0 ? 0 : ToMicros(wake_ns - prev_wake_ns_);
  s.substeps = static_cast<uint32_t>(std::max(report.substeps, 0));
  s.warnings = static_cast<uint32_t>(std::max<int64_t>(report.new_warnings, 0) + fault + pose_fault);
  s.num_contacts = static_cast<uint32_t>(std::max(out.contacts, 0));
  s.contact = out.contacts > 0;
  // Clamped at the limit by the step (the scene's max_force) or by the guard (the device's).
  s.force_limited = state.warnings.device_force_clamped != clamped_before || asked > registration_.max_force;
  s.grasp = out.grasp_atom >= 0;
  s.reset = reset_this_tick_;
  reset_this_tick_ = false;
  if (out.friction != FrictionState::kNone) {
    // The tangential part as the device got it: scaled by what the clamps and the guard kept.
    const double raw = std::sqrt(out.force_raw[0] * out.force_raw[0] + out.force_raw[1] * out.force_raw[1] +
                                 out.force_raw[2] * out.force_raw[2]);
    const double sent = std::sqrt(f_model[0] * f_model[0] + f_model[1] * f_model[1] + f_model[2] * f_model[2]);
    const double keep = raw > sent && raw > 0 ? sent / raw : 1.0;
    for (int i = 0; i < 3; ++i) s.friction_force[i] = std::isfinite(keep) ? keep * out.friction_force[i] : 0.0;
    s.normal_force = std::isfinite(out.normal_force) ? out.normal_force : 0.0;
    s.friction = out.friction;
  }
  for (int i = 0; i < 4; ++i) s.orientation[i] = orientation_[i];
  s.oriented = oriented_;
  s.needle_punctured = out.punctured;
  s.needle_inserted = out.inserted;
  s.needle_exited = out.exited;
  s.tie = tool.tie;
  s.tool_index = static_cast<uint8_t>(tool_index_);
  s.incision_gap = incision_gap_;
  s.incision_open = num_incision_pairs_ > 0 ? incision_open_sum_ / num_incision_pairs_ : 0.0;
  s.suture_new_punctures = static_cast<uint8_t>(report.suture.new_punctures);
  s.suture_tied = report.suture.tied;
  s.suture_tie_refused = report.suture.tie_refused;
  s.suture_broke = report.suture.broke;
  s.suture_punctures = static_cast<uint16_t>(report.suture.punctures);
  s.suture_ties = static_cast<uint16_t>(report.suture.ties);
  s.port_energy = passive.energy;
  s.port_energy_window = passive.window;
  s.passivity_damping = passive.damping;
  s.overrun = MonotonicNs() > deadline_ns;
  compute_hist_.Add(s.compute_us);
  if (prev_wake_ns_ >= 0) period_hist_.Add(s.period_us);
  // Wake-up against its schedule (deadline_ns - one period): one period late = deadline gone.
  wake_hist_.Add(ToMicros(wake_ns - (deadline_ns - period_ns_)));
  if (wake_ns >= deadline_ns) counters_.late_wakeups.fetch_add(1, std::memory_order_relaxed);
  prev_wake_ns_ = wake_ns;
  if (s.overrun) counters_.overruns.fetch_add(1, std::memory_order_relaxed);
  if (!samples_.push(s)) counters_.samples_lost.fetch_add(1, std::memory_order_relaxed);
  counters_.ticks.store(static_cast<uint64_t>(state.tick), std::memory_order_relaxed);
}

void Loop::ApplyCommands() {
  LoopCommand command;
  while (commands_.pop(command)) {
    counters_.commands.fetch_add(1, std::memory_order_relaxed);
    if (command.tool != 0) continue;  // one device drives tool 0; other slots are not simulated
    switch (command.kind) {
      case LoopCommand::kTweezersClose:
        tweezers_override_ = 1, override_button_ = last_button_;
        break;
      case LoopCommand::kTweezersOpen:
        tweezers_override_ = 0, override_button_ = last_button_;
        break;
      case LoopCommand::kTweezersDevice:
        tweezers_override_ = -1;
        break;
      case LoopCommand::kReset:
        Reset();
        break;
    }
  }
}

bool Loop::PublishMesh(bool final_frame) {
  int32_t index = -1;
  if (!mesh_free_.pop(index)) return false;
  MeshSlot& slot = slots_[static_cast<size_t>(index)];
  const Model& model = sim_->model;
  const State& state = sim_->state;
  // Positions of the external atoms, in plg vertex order.
  GatherSurface(model, state.atom_pos, slot.pos);
  // Triangles only when the topology changed since the last published frame.
  slot.num_tris = -1;
  if (model.topology_version != published_topology_) {
    slot.num_tris = model.num_tris;
    for (size_t i = 0; i < 3 * static_cast<size_t>(model.num_tris); ++i) {
      slot.tri_verts[i] = model.atom_external_id[static_cast<size_t>(model.tri_atoms[i])];
    }
    published_topology_ = model.topology_version;
  }
  // The suture thread: its nodes and the points it passes through.
  const SutureState& ss = state.suture;
  slot.suture_nodes = ss.num_nodes;
  for (int32_t i = 0; i < 3 * ss.num_nodes; ++i) slot.suture_pos[i] = static_cast<float>(ss.pos[i]);
  slot.suture_punctures = 0;
  for (int32_t j = 0; j < ss.num_punctures; ++j) {
    double p[3] = {0, 0, 0};
    for (int i = 0; i < kAnchorAtoms && ss.punctures[j].atoms[i] >= 0; ++i) {
      for (int c = 0; c < 3; ++c) p[c] += ss.punctures[j].w[i] * state.atom_pos[3 * ss.punctures[j].atoms[i] + c];
    }
    for (int c = 0; c < 3; ++c) slot.suture_puncture_pos[3 * slot.suture_punctures + c] = static_cast<float>(p[c]);
    ++slot.suture_punctures;
  }
  slot.suture_ties = ss.num_ties;
  slot.suture_broken = ss.broken + 1;
  slot.tick = static_cast<uint64_t>(state.tick);
  slot.time_s = state.time_s;
  slot.topology_version = model.topology_version;
  slot.final_frame = final_frame;
  mesh_full_.push(index);
  return true;
}

void Loop::MeasureIncision(const State& state) {
  incision_due_ = false;
  if (num_incision_pairs_ == 0) return;
  double sum = 0;
  for (int32_t i = 0; i < num_incision_pairs_; ++i) {
    const Real* p = &state.atom_pos[3 * incision_pairs_[i][0]];
    const Real* q = &state.atom_pos[3 * incision_pairs_[i][1]];
    sum += std::hypot(static_cast<double>(q[0] - p[0]), static_cast<double>(q[1] - p[1]),
                      static_cast<double>(q[2] - p[2]));
  }
  incision_gap_ = std::isfinite(sum) ? sum / num_incision_pairs_ : 0.0;
}

void Loop::Reset() {
  // The rest set PushCommand queued ahead of this command; none means a broken handoff, and the
  // loop does not abort: the command is ignored.
  SimSet* rest = nullptr;
  if (!reset_ready_.pop(rest)) return;
  // Keep the tick count and time (samples stay consecutive).
  rest->state.tick = sim_->state.tick;
  rest->state.time_s = sim_->state.time_s;
  rest->workspace.synced_tick = rest->state.tick;
  // Cuts since the last rest: the restored model is a new topology for the viewers.
  if (sim_->model.topology_version != rest_topology_) rest_topology_ = sim_->model.topology_version + 1;
  rest->model.topology_version = rest_topology_;
  rest->workspace.topology_version = rest_topology_;
  // The hand feels no jump: the device force carries on from where it was and eases towards the
  // new contact force instead of leaping to it (the tissue springs back around a pressing tool).
  BeginForceTransition(sim_->state, rest->state, rest->workspace.options);
  // Swap pointers; the replaced set goes back to the I/O thread to be freed there. It cannot find
  // the ring full: PushCommand keeps at most its capacity of sets away from the loop.
  reset_spent_.push(sim_.release());
  sim_.reset(rest);
  tweezers_override_ = -1;
  num_incision_pairs_ = 0;  // the rest model is whole again
  incision_open_sum_ = incision_gap_ = 0;
  reset_this_tick_ = true;
  counters_.resets.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace idms::agent
