// A sampled-data haptic device held by a simulated hand, for the Z-width bench and the passivity
// tests: a mass with viscous friction, an encoder of finite resolution and a force held for a whole
// loop period (zero-order hold), pulled by a hand (mass, spring, damper) towards a scripted target.
#pragma once

namespace idms {

struct PortModelOptions {
  int dof = 3;                   // 1: only z moves (x and y follow the target exactly), 3: all
  double device_mass = 0.002;    // force * s^2 / length (model units; 0.002 ~ 80 g with inches and N)
  double device_damping = 0.02;  // b, the device's viscous friction, force * s / length
  double quantum = 1e-4;         // encoder resolution, length; 0 = exact positions
  double hand_mass = 0.005;      // the fingers and hand that move with the stylus
  double hand_stiffness = 10;    // the arm's spring to the scripted target, force / length
  double hand_damping = 0.05;    // the grip's damping, force * s / length
  double dt_s = 1e-3;            // the loop period: the force is held this long
  int substeps = 32;             // the plant's own integration steps per period (continuous time)
};

// (m_d + m_h) x'' = F - (b + c) x' + k (target - x), F held over each period. Symplectic Euler at
// dt_s / substeps (the plant's fastest pole, (b + c) / (m_d + m_h), is far below that rate).
class PortModel {
 public:
  PortModel(const PortModelOptions& options, const double start[3]);
  // One loop period under the force `force` (held) towards `target` (taken as constant over it).
  void Advance(const double force[3], const double target[3]);
  // What the encoder reads now: positions rounded to the quantum.
  void Read(double pos[3]) const;
  const double* pos() const { return x_; }
  const double* vel() const { return v_; }
  const PortModelOptions& options() const { return options_; }

 private:
  PortModelOptions options_;
  double x_[3] = {0, 0, 0}, v_[3] = {0, 0, 0};
};

}  // namespace idms
