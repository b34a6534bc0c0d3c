// The bench's sampled-data device and simulated hand (port_model.h).
#include "idms/sim/port_model.h"

#include <cmath>

namespace idms {

PortModel::PortModel(const PortModelOptions& options, const double start[3]) : options_(options) {
  for (int i = 0; i < 3; ++i) x_[i] = start[i];
}

void PortModel::Advance(const double force[3], const double target[3]) {
  const double m = options_.device_mass + options_.hand_mass;
  const double b = options_.device_damping + options_.hand_damping;
  const double h = options_.dt_s / options_.substeps;
  // 1-DOF: only z is free; x and y are where the hand wants them.
  const int first = options_.dof == 1 ? 2 : 0;
  for (int i = 0; i < first; ++i) x_[i] = target[i], v_[i] = 0;
  for (int s = 0; s < options_.substeps; ++s) {
    for (int i = first; i < 3; ++i) {
      const double a = (force[i] - b * v_[i] + options_.hand_stiffness * (target[i] - x_[i])) / m;
      v_[i] += h * a;
      x_[i] += h * v_[i];
    }
  }
}

void PortModel::Read(double pos[3]) const {
  const double q = options_.quantum;
  for (int i = 0; i < 3; ++i) pos[i] = q > 0 ? q * std::round(x_[i] / q) : x_[i];
}

}  // namespace idms
