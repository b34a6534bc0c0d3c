// Device-to-model registration (thesis 5.3): p_model = scale * R * p_device + offset, forces back
// through the rotation, and the last line of defence before a force reaches the device.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace idms::agent {

struct Registration {
  double scale = 1;                             // model units per device unit, > 0
  double rot[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // R, row-major, orthonormal
  double offset[3] = {0, 0, 0};                 // model units
  double force_scale = 1;                       // device force units per model force unit, > 0
  double max_force = 10;                        // device force clamp, device force units, > 0

  // p_model = scale * R * p_device + offset. Does not allocate.
  void DeviceToModel(const double p_device[3], double p_model[3]) const;
  // The inverse: p_device = R^T (p_model - offset) / scale.
  void ModelToDevice(const double p_model[3], double p_device[3]) const;
  // f_device = force_scale * R^T f_model (a force turns with the frame; scale does not apply).
  void ForceToDevice(const double f_model[3], double f_device[3]) const;
  // f_model = R f_device / force_scale (for a device force acting back on a simulated hand).
  void ForceToModel(const double f_device[3], double f_model[3]) const;
  // Orientations as unit quaternions (w, x, y, z): q_model = R q_device, and back. The input is
  // normalised; false (out untouched) when it is not finite or is zero. Does not allocate.
  bool OrientationToModel(const double q_device[4], double q_model[4]) const;
  bool OrientationToDevice(const double q_model[4], double q_device[4]) const;
};

// Rotation matrices (row-major) from the usual descriptions. Each returns false with a message
// when the input cannot describe a rotation (non-finite, zero quaternion or axis).
// Roll about x, pitch about y, yaw about z, degrees: R = Rz(yaw) Ry(pitch) Rx(roll) (idms.proto).
bool RotationFromRpyDeg(const double rpy_deg[3], double rot[9], std::string* error);
// Unit quaternion w + xi + yj + zk (normalised here).
bool RotationFromQuaternion(double w, double x, double y, double z, double rot[9], std::string* error);
// A right-handed turn of angle_deg about axis (normalised here).
bool RotationFromAxisAngle(const double axis[3], double angle_deg, double rot[9], std::string* error);

// Parses a --rotation value: "quat:W,X,Y,Z", "axis-angle:X,Y,Z,DEG" or "rpy:ROLL,PITCH,YAW" (degrees).
bool ParseRotation(std::string_view spec, double rot[9], std::string* error);
// Parses "X,Y,Z" (finite numbers).
bool ParseVec3(std::string_view text, double out[3], std::string* error);

// The last line of defence at the device write: a non-finite component zeroes the whole force,
// and a magnitude above max_force is scaled down to it. Returns 1 when it zeroed (a fault to
// count), else 0. Loop thread; does not allocate.
int SanitizeDeviceForce(double force[3], double max_force);

}  // namespace idms::agent
