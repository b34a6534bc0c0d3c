// The port's passivity observer and controller (passivity.h).
#include "idms/sim/passivity.h"

#include <algorithm>
#include <cmath>

namespace idms {
namespace {

bool Finite3(const double a[3]) { return std::isfinite(a[0]) && std::isfinite(a[1]) && std::isfinite(a[2]); }
double Dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

}  // namespace

PassivityController::PassivityController(const PassivityOptions& options) : options_(options) {
  // The smallest velocity an encoder of this resolution shows: one count per tick.
  const double q = options_.quantum > 0 ? options_.quantum : 1e-9;
  v_floor2_ = (q / options_.dt_s) * (q / options_.dt_s);
  const double ticks = std::round(options_.window_s / options_.dt_s);
  if (ticks >= 1) ring_.assign(static_cast<size_t>(std::min(ticks, 1e7)), 0.0);
}

PassivityTick PassivityController::Update(const double pos[3], bool valid, const double force_env[3],
                                          double stored_energy, double force_out[3]) {
  // Observe: the work of the force held over the interval that just ended, from the measured
  // displacement (backward difference of what the encoder read).
  double v[3] = {0, 0, 0};
  double increment = 0;
  const bool observed = valid && Finite3(pos);
  if (observed) {
    if (has_prev_) {
      const double dx[3] = {pos[0] - prev_pos_[0], pos[1] - prev_pos_[1], pos[2] - prev_pos_[2]};
      const double work = -Dot3(commanded_, dx);
      const double controller_work = -Dot3(damping_force_, dx);
      if (std::isfinite(work) && std::isfinite(controller_work)) {
        increment = work;
        dissipated_ += controller_work;
        for (int i = 0; i < 3; ++i) v[i] = dx[i] / options_.dt_s;
      }
    }
    for (int i = 0; i < 3; ++i) prev_pos_[i] = pos[i];
    has_prev_ = true;
  }
  energy_ += increment;
  if (increment > 0) work_in_ += increment;

  // The window: credit is capped at the last window's deposits plus what the environment stores.
  if (!ring_.empty()) {
    const double deposit = std::max(increment, 0.0);
    deposits_ += deposit - ring_[ring_next_];
    ring_[ring_next_] = deposit;
    ring_next_ = ring_next_ + 1 == ring_.size() ? 0 : ring_next_ + 1;
    deposits_ = std::max(deposits_, 0.0);  // rounding of the running sum
    const double stored = std::isfinite(stored_energy) && stored_energy > 0 ? stored_energy : 0.0;
    window_ = std::min(window_ + increment, deposits_ + stored);
  } else {
    window_ = energy_;
  }
  min_energy_ = std::min(min_energy_, energy_);
  min_window_ = std::min(min_window_, window_);

  // Control: the next interval's work predicted with the force about to be sent; damp the excess.
  // A non-finite force becomes zero here (the step zeroes its own; this is for other callers).
  double f[3] = {force_env[0], force_env[1], force_env[2]};
  if (!Finite3(f)) f[0] = f[1] = f[2] = 0;
  const double v2 = Dot3(v, v);
  double alpha = 0;
  if (options_.enabled && v2 > 0) {
    const double owed = Dot3(f, v) * options_.dt_s - window_;
    if (owed > 0) alpha = std::min(owed / (std::max(v2, v_floor2_) * options_.dt_s), options_.max_damping);
    if (!(alpha > 0)) alpha = 0;  // NaN or a non-positive cap
  }
  for (int i = 0; i < 3; ++i) {
    damping_force_[i] = -alpha * v[i];
    force_out[i] = f[i] + damping_force_[i];
    asked_[i] = force_out[i];
  }
  PassivityTick tick;
  tick.damping = alpha;
  tick.energy = energy_;
  tick.window = window_;
  tick.acted = alpha > 0;
  if (tick.acted) ++acted_ticks_;
  return tick;
}

void PassivityController::Commanded(const double force[3]) {
  // What the device got: the guard zeroes a non-finite force, the clamp scales the vector.
  if (!Finite3(force)) {
    for (int i = 0; i < 3; ++i) commanded_[i] = damping_force_[i] = 0;
    return;
  }
  const double asked = std::sqrt(Dot3(asked_, asked_));
  const double got = std::sqrt(Dot3(force, force));
  const double keep = asked > got && asked > 0 ? got / asked : 1.0;
  for (int i = 0; i < 3; ++i) {
    commanded_[i] = force[i];
    damping_force_[i] *= keep;
  }
}

}  // namespace idms
