#include "idms/sim/global.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "idms/sim/check.h"
#include "idms/sim/spatial_hash.h"

namespace idms {
namespace {

// Hand-off states of GlobalDynamics::slot_.
constexpr int32_t kIdle = 0, kJob = 1, kResult = 2;

StepOptions GlobalStepOptions(const StepOptions& local, const GlobalOptions& o) {
  StepOptions g = local;
  g.full = true;
  g.threads = std::max(1, o.threads);
  // The local pass is what the device feels and keeps its own check; the global one keeps the
  // stable-step prediction (its substeps) and the finiteness checks.
  g.stability.energy_check = false;
  return g;
}

int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

GlobalDynamics::GlobalDynamics(const Model& model, const State& state, const StepOptions& local,
                               const GlobalOptions& options)
    : m_(model), options_(options), gs_(state), gws_(MakeWorkspace(model, GlobalStepOptions(local, options))) {
  IDMS_CHECK(options.rate_hz > 0 && local.dt_s > 0);
  k_ = std::max(1, static_cast<int32_t>(std::lround(1.0 / (options.rate_hz * local.dt_s))));
  const size_t rows = 3 * static_cast<size_t>(model.num_atoms);
  local_moved_.assign(model.num_atoms, 0);
  moved_.assign(model.num_atoms, 0);
  window_.assign(model.num_atoms, 0);
  window_pos_.assign(rows, Real(0)), window_vel_.assign(rows, Real(0));
  for (Result& r : results_) r.atoms.assign(model.num_atoms, 0), r.pos.assign(rows, Real(0));
  sent_ = state.atom_pos;
  blend_list_.assign(model.num_atoms, 0);
  from_.assign(rows, Real(0)), to_.assign(rows, Real(0));
  blend_.assign(model.num_atoms, 0);
  if (options.threaded) thread_ = std::thread([this] { ThreadMain(); });
}

GlobalDynamics::~GlobalDynamics() {
  if (!thread_.joinable()) return;
  quit_.store(true, std::memory_order_release);
  slot_.store(-1, std::memory_order_release);  // a changed value: wait() returns only on one
  slot_.notify_all();
  thread_.join();
}

GlobalStats GlobalDynamics::stats() const {
  GlobalStats st;
  st.steps = steps_.load(std::memory_order_relaxed);
  st.exchanges = exchanges_;
  st.late = late_;
  st.stopped = stopped_;
  st.last_step_ms = 1e-6 * static_cast<double>(last_step_ns_.load(std::memory_order_relaxed));
  const int64_t total = step_ns_total_.load(std::memory_order_relaxed);
  st.reachable_hz = total > 0 ? 1e9 * static_cast<double>(st.steps) / static_cast<double>(total) : 0.0;
  return st;
}

void GlobalDynamics::AfterTick(State& s, Workspace& ws) {
  // A cut (or any edit) changed the local model: the global pass's copy no longer describes it.
  if (!started_) started_ = true, topology_ = ws.topology_version;
  if (stopped_ || ws.topology_version != topology_) {
    stopped_ = true;
    return;
  }
  // The local pass owns what it moved: no blend moves it until the global pass has seen it.
  for (int32_t i = 0; i < s.num_active; ++i) {
    const int32_t a = s.active_atoms[i];
    if (!local_moved_[a]) local_moved_[a] = 1, moved_[moved_n_++] = a;
    blend_[a] = 0;
  }
  phase_ = std::min(phase_ + 1, span_);
  if (have_target_) {
    const Real alpha = static_cast<Real>(static_cast<double>(phase_) / span_);
    for (int32_t i = 0; i < blend_n_; ++i) {
      const int32_t a = blend_list_[i];
      if (!blend_[a]) continue;
      Real* p = &s.atom_pos[3 * a];
      for (int c = 0; c < 3; ++c) p[c] = from_[3 * a + c] + alpha * (to_[3 * a + c] - from_[3 * a + c]);
      UpdateSpatialHash(ws.hash, a, p);
    }
    if (phase_ >= span_) have_target_ = false;  // arrived: hold until the next result
  }
  if ((++ticks_ + options_.phase) % k_ == 0) Exchange(s);
}

void GlobalDynamics::Exchange(const State& s) {
  bool take = false, publish = false;
  if (options_.threaded) {
    const int32_t slot = slot_.load(std::memory_order_acquire);
    take = slot == kResult;
    publish = slot == kIdle || slot == kResult;
    late_ += slot == kJob;
  } else {
    take = jobs_ > 0;
    publish = true;
  }
  if (take) {
    // The atoms the result moved, except those the local pass has moved since the last exchange,
    // go from where they are to the result over the next K ticks.
    const Result& r = results_[(jobs_ - 1) % 2];
    blend_n_ = 0;
    for (int32_t i = 0; i < r.n; ++i) {
      const int32_t a = r.atoms[i];
      if (local_moved_[a]) continue;
      blend_[a] = 1;
      blend_list_[blend_n_++] = a;
      for (int c = 0; c < 3; ++c) from_[3 * a + c] = s.atom_pos[3 * a + c], to_[3 * a + c] = r.pos[3 * i + c];
    }
    // Over as many ticks as results came apart last time (K while the pass keeps up; more on a
    // model too large for the rate, so that its atoms keep moving instead of stepping and holding).
    span_ = last_take_ < 0 ? k_ : static_cast<int32_t>(std::clamp<int64_t>(ticks_ - last_take_, k_, int64_t{64} * k_));
    last_take_ = ticks_;
    phase_ = 0;
    have_target_ = true;
    ++exchanges_;
  }
  if (!publish) return;  // the global thread is still stepping: the window waits for the next exchange
  window_n_ = moved_n_;
  for (int32_t i = 0; i < moved_n_; ++i) {
    const int32_t a = moved_[i];
    window_[i] = a;
    for (int c = 0; c < 3; ++c) {
      window_pos_[3 * i + c] = s.atom_pos[3 * a + c], window_vel_[3 * i + c] = s.atom_vel[3 * a + c];
    }
    local_moved_[a] = 0;
  }
  moved_n_ = 0;
  ++jobs_;
  if (options_.threaded) {
    slot_.store(kJob, std::memory_order_release);
    slot_.notify_one();
  } else {
    RunJob();
  }
}

void GlobalDynamics::RunJob() {
  const int64_t start = NowNs();
  auto hold = [&] {
    for (int32_t i = 0; i < window_n_; ++i) {
      const int32_t a = window_[i];
      for (int c = 0; c < 3; ++c) {
        gs_.atom_pos[3 * a + c] = window_pos_[3 * i + c], gs_.atom_vel[3 * a + c] = window_vel_[3 * i + c];
      }
    }
  };
  hold();
  const ToolInput none;
  for (int32_t j = 0; j < k_; ++j) {
    Step(m_, gs_, gws_, none);
    hold();  // the window's atoms are boundary conditions: held at the local state
  }
  // The atoms that moved by more than kGlobalEpsilon from what was last handed over for them.
  Result& r = results_[(jobs_ - 1) % 2];
  r.n = 0;
  for (int32_t a = 0; a < m_.num_atoms; ++a) {
    if (m_.atom_fixed[a]) continue;
    const Real* p = &gs_.atom_pos[3 * a];
    Real* sent = &sent_[3 * a];
    if (!(std::fabs(p[0] - sent[0]) > kGlobalEpsilon || std::fabs(p[1] - sent[1]) > kGlobalEpsilon ||
          std::fabs(p[2] - sent[2]) > kGlobalEpsilon)) {
      continue;
    }
    r.atoms[r.n] = a;
    for (int c = 0; c < 3; ++c) r.pos[3 * r.n + c] = p[c], sent[c] = p[c];
    ++r.n;
  }
  const int64_t ns = NowNs() - start;
  last_step_ns_.store(ns, std::memory_order_relaxed);
  step_ns_total_.fetch_add(ns, std::memory_order_relaxed);
  steps_.fetch_add(1, std::memory_order_relaxed);
}

void GlobalDynamics::ThreadMain() {
  for (;;) {
    int32_t slot = slot_.load(std::memory_order_acquire);
    while (slot != kJob && !quit_.load(std::memory_order_acquire)) {
      slot_.wait(slot, std::memory_order_acquire);
      slot = slot_.load(std::memory_order_acquire);
    }
    if (quit_.load(std::memory_order_acquire)) return;
    RunJob();
    if (options_.extra_delay_us > 0) std::this_thread::sleep_for(std::chrono::microseconds(options_.extra_delay_us));
    slot_.store(kResult, std::memory_order_release);
  }
}

}  // namespace idms
