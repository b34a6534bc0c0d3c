// The drag interaction (issue 30): press a fingertip to a depth, then push it sideways through a
// simulated hand with a constant force, a given fraction of mu_s f_n, so that anyone can see a
// contact with friction hold below the limit and slip above it. Closed loop: the tool's x is the
// hand's, which the device force pushes back. Used by `idms-sim run --script drag:...`, the
// agent's scripted devices and the friction tests and bench.
#pragma once

#include <string>
#include <string_view>

#include "idms/sim/interaction_script.h"

namespace idms {

struct DragOptions {
  double fraction = 0.5;  // sideways force / (mu_s f_n), >= 0
  double mu_s = 0;        // the tool's static coefficient, the push's reference (> 0 to push)
  double depth = 0.063;   // how far below first contact the tool presses, model units (palpation's)
  // The hand along x: a mass pushed by the constant force and the device force, with its own
  // damping (critical against the MIO stiffness k: 2 sqrt(k m)).
  double hand_mass = 0.05;   // mass units
  double hand_damping = -1;  // force / (length / s); < 0 = 2 sqrt(400 hand_mass)
  double press_s = 1.0;      // coming down from 1 unit above first contact
  double settle_s = 1.0;     // held at depth; f_n is measured over its last 0.2 s
  double ramp_s = 0.5;       // the push rises with a half-cosine over this
  // Ramp included. The constant push lasts 12.5 s: the hand and the tissue settle under it within
  // ~2.5 s (0.3 s time constant on the hex fragment), so the script's last 10 s show the hold itself.
  double push_s = 13.0;
};

// "fraction=0.5,depth=0.063,mass=0.05,damping=3,push=12" (any subset, after "drag:" or alone).
// False with *error naming the item on a bad one.
bool ParseDragSpec(std::string_view spec, DragOptions* options, std::string* error);

class DragHand {
 public:
  DragHand(const ScriptGeometry& geometry, const DragOptions& options);

  // The tool's pose for the tick ending at t_s (> the last call's), given the device force
  // (model frame) the last tick sent. Allocates nothing.
  ScriptSample Next(double t_s, const double device_force[3]);

  double Duration() const { return o_.press_s + o_.settle_s + o_.push_s; }
  double PushStart() const { return o_.press_s + o_.settle_s; }
  double HoldStart() const { return PushStart() + o_.ramp_s; }  // the push is constant from here
  double normal_force() const { return fn_; }                   // f_n measured at the end of the settle
  double push_force() const { return push_; }                   // the sideways force this tick
  double hand_x() const { return x_; }

 private:
  ScriptGeometry g_;
  DragOptions o_;
  double x_ = 0, v_ = 0;  // hand along x
  double t_ = 0;          // last call's time
  double fn_sum_ = 0;
  int fn_n_ = 0;
  double fn_ = 0, push_ = 0;
};

}  // namespace idms
