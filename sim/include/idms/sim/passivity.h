// A passivity observer and controller at the device port (Hannaford & Ryu 2002, with a window that
// forgets only dissipated energy): what the agent's loop and the Z-width bench put between the
// step's device force and the device. Pure; no allocation after construction.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace idms {

// Units: lengths and forces in one consistent frame (the agent uses the model frame and units).
struct PassivityOptions {
  bool enabled = false;  // the controller acts; the observer runs either way
  double dt_s = 1e-3;    // T, the loop period: the force is held (ZOH) for T
  // Credit older than this that the environment no longer stores is forgotten (see below); 0 =
  // nothing is forgotten (the whole-session observer alone, Hannaford & Ryu's original).
  double window_s = 0.1;
  // The largest damping the controller adds (force * s / length): what the device can render
  // without its own sampled damping going active (a discrete damper is stable below m/T).
  double max_damping = 1.0;
  // The encoder's resolution (length): |v|^2 is floored at (quantum / T)^2, the smallest nonzero
  // velocity a backward difference of quantized positions can show. 0 = 1e-9 / T.
  double quantum = 0;
};

// One tick's verdict.
struct PassivityTick {
  double damping = 0;  // alpha added this tick, force * s / length (0 = the controller did nothing)
  double energy = 0;   // whole-session observed port energy after this tick, force * length
  double window = 0;   // the windowed energy the controller keeps >= 0
  bool acted = false;  // alpha > 0 and the tool moved
};

// E(n) = sum_k -F(k-1) . (x(k) - x(k-1)) = T sum f(k) . v(k): the energy the hand has put into the
// environment through the port, with F the force commanded on the device (held over the interval
// that ends at sample k, so the work of a zero-order-held force over a measured displacement is
// exact, up to the encoder) and v the backward difference of the positions read.
//
// The controller keeps the windowed energy W >= 0: W follows E, but is capped at the energy
// deposited (positive increments) within the last window plus the energy the environment stores
// now (its elastic, contact and kinetic energy, when the caller knows it). Credit that has left the
// window and is not stored any more was dissipated (by the tissue's viscosity, the tool's friction
// or the controller); it cannot come back, so it is forgotten, and a session's large dissipated
// total cannot hide a new instability. Energy the environment generates (negative increments) is
// never forgotten: it stays owed until paid back.
//
// Each tick it predicts the next interval's work with the force about to be sent, -F_env . v T, and
// when W plus it would go below zero adds a damping F = F_env - alpha v with
// alpha = (F_env . v T - W) / (max(|v|^2, v_floor^2) T), capped at max_damping. The weaknesses the
// literature reports, and what is done about each:
//   - delayed action: the prediction acts in the tick the excess would arise, not one later;
//   - bursts (a teleport, a reset, a clamp): alpha is capped, so the deficit is paid over the next
//     ticks at the device's damping limit instead of in one jolt; what the cap leaves stays owed;
//   - division near zero velocity: |v|^2 is floored at the encoder's velocity resolution, and the
//     force alpha v vanishes with v anyway;
//   - saturation: the observer reads the force the device was actually given (Commanded, after the
//     clamp and the NaN guard), so what a clamp took away is not counted as dissipated.
// A non-finite position is no observation (the tick's increment is 0, nothing NaN enters the sums)
// and the controller adds nothing that tick; a non-finite force_env is sent as zero.
class PassivityController {
 public:
  PassivityController() = default;  // observer only, no window; allocates nothing
  // Allocates the window's ring (window_s / dt_s ticks). Options are taken as given: validate first.
  explicit PassivityController(const PassivityOptions& options);

  // One tick, after the step: pos is the position read this tick (valid = false: none), force_env
  // the force the environment asks for, stored_energy what the environment holds now (>= 0; 0 when
  // unknown). Writes the force to command to force_out (force_env when the controller does nothing;
  // may alias force_env). Does not allocate.
  PassivityTick Update(const double pos[3], bool valid, const double force_env[3], double stored_energy,
                       double force_out[3]);
  // The force the device was given this tick (after the clamp and the guard): what the next
  // tick's observation multiplies with its displacement.
  void Commanded(const double force[3]);

  const PassivityOptions& options() const { return options_; }
  double energy() const { return energy_; }                 // E, force * length
  double window_energy() const { return window_; }          // W
  double dissipated() const { return dissipated_; }         // work of the controller's force so far
  double work_in() const { return work_in_; }               // sum of positive increments of E
  double min_energy() const { return min_energy_; }         // lowest E so far
  double min_window_energy() const { return min_window_; }  // lowest W so far
  uint64_t acted_ticks() const { return acted_ticks_; }

 private:
  PassivityOptions options_;
  double v_floor2_ = 1e-12;
  // Observer.
  bool has_prev_ = false;
  double prev_pos_[3] = {0, 0, 0};
  double commanded_[3] = {0, 0, 0};      // held over the interval now running
  double damping_force_[3] = {0, 0, 0};  // the controller's part of commanded_
  double asked_[3] = {0, 0, 0};          // what Update returned, to scale the damping part by the clamp
  double energy_ = 0, window_ = 0;
  double dissipated_ = 0, work_in_ = 0;
  double min_energy_ = 0, min_window_ = 0;
  uint64_t acted_ticks_ = 0;
  // Window: deposits of the last ring_.size() ticks and their sum.
  std::vector<double> ring_;
  size_t ring_next_ = 0;
  double deposits_ = 0;
};

}  // namespace idms
