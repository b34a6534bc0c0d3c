// Registration transforms, rotation parsing and the device-force guard.
#include "idms/agent/registration.h"

#include <Eigen/Geometry>
#include <charconv>
#include <cmath>
#include <numbers>

#include "text_internal.h"

namespace idms::agent {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

void MulRot(const double r[9], const double v[3], double out[3]) {
  for (int i = 0; i < 3; ++i) out[i] = r[3 * i] * v[0] + r[3 * i + 1] * v[1] + r[3 * i + 2] * v[2];
}

void MulRotT(const double r[9], const double v[3], double out[3]) {
  for (int i = 0; i < 3; ++i) out[i] = r[i] * v[0] + r[3 + i] * v[1] + r[6 + i] * v[2];
}

// Comma-separated finite numbers; exactly `count` of them.
bool ParseNumbers(std::string_view text, size_t count, double* out, std::string* error) {
  size_t n = 0;
  while (true) {
    const size_t comma = text.find(',');
    const std::string_view item = text.substr(0, comma);
    double value = 0;
    const auto [ptr, ec] = std::from_chars(item.data(), item.data() + item.size(), value);
    if (ec != std::errc() || ptr != item.data() + item.size() || !std::isfinite(value)) {
      *error = Cat({"expected a number, got '", item}) + "'";
      return false;
    }
    if (n < count) out[n] = value;
    ++n;
    if (comma == std::string_view::npos) break;
    text.remove_prefix(comma + 1);
  }
  if (n != count) {
    *error = "expected " + std::to_string(count) + " comma-separated numbers, got " + std::to_string(n);
    return false;
  }
  return true;
}

}  // namespace

void Registration::DeviceToModel(const double p_device[3], double p_model[3]) const {
  double r[3];
  MulRot(rot, p_device, r);
  for (int i = 0; i < 3; ++i) p_model[i] = scale * r[i] + offset[i];
}

namespace {

// The registration's rotation as a quaternion, and a unit, finite quaternion from q (false when none).
Eigen::Quaterniond RotationQuat(const double rot[9]) {
  return Eigen::Quaterniond(Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(rot));
}
bool UnitQuat(const double q[4], Eigen::Quaterniond* out) {
  const Eigen::Quaterniond r(q[0], q[1], q[2], q[3]);
  const double n = r.norm();
  if (!std::isfinite(n) || n < 1e-12) return false;
  *out = r;
  out->normalize();
  return true;
}
void Store(const Eigen::Quaterniond& q, double out[4]) {
  // The same rotation either sign; w >= 0 so that a recording reads the same for the same pose.
  const double sign = q.w() < 0 ? -1.0 : 1.0;
  out[0] = sign * q.w(), out[1] = sign * q.x(), out[2] = sign * q.y(), out[3] = sign * q.z();
}

}  // namespace

bool Registration::OrientationToModel(const double q_device[4], double q_model[4]) const {
  Eigen::Quaterniond q;
  if (!UnitQuat(q_device, &q)) return false;
  Store((RotationQuat(rot) * q).normalized(), q_model);
  return true;
}

bool Registration::OrientationToDevice(const double q_model[4], double q_device[4]) const {
  Eigen::Quaterniond q;
  if (!UnitQuat(q_model, &q)) return false;
  Store((RotationQuat(rot).conjugate() * q).normalized(), q_device);
  return true;
}

void Registration::ModelToDevice(const double p_model[3], double p_device[3]) const {
  const double d[3] = {(p_model[0] - offset[0]) / scale, (p_model[1] - offset[1]) / scale,
                       (p_model[2] - offset[2]) / scale};
  MulRotT(rot, d, p_device);
}

void Registration::ForceToDevice(const double f_model[3], double f_device[3]) const {
  MulRotT(rot, f_model, f_device);
  for (int i = 0; i < 3; ++i) f_device[i] *= force_scale;
}

void Registration::ForceToModel(const double f_device[3], double f_model[3]) const {
  MulRot(rot, f_device, f_model);
  for (int i = 0; i < 3; ++i) f_model[i] /= force_scale;
}

bool RotationFromRpyDeg(const double rpy_deg[3], double rot[9], std::string* error) {
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(rpy_deg[i])) {
      *error = "roll, pitch and yaw must be finite";
      return false;
    }
  }
  const double cr = std::cos(rpy_deg[0] * kDegToRad), sr = std::sin(rpy_deg[0] * kDegToRad);
  const double cp = std::cos(rpy_deg[1] * kDegToRad), sp = std::sin(rpy_deg[1] * kDegToRad);
  const double cy = std::cos(rpy_deg[2] * kDegToRad), sy = std::sin(rpy_deg[2] * kDegToRad);
  // R = Rz(yaw) Ry(pitch) Rx(roll), written out.
  const double r[9] = {cy * cp,
                       cy * sp * sr - sy * cr,
                       cy * sp * cr + sy * sr,
                       sy * cp,
                       sy * sp * sr + cy * cr,
                       sy * sp * cr - cy * sr,
                       -sp,
                       cp * sr,
                       cp * cr};
  for (int i = 0; i < 9; ++i) rot[i] = r[i];
  return true;
}

bool RotationFromQuaternion(double w, double x, double y, double z, double rot[9], std::string* error) {
  const double norm = std::sqrt(w * w + x * x + y * y + z * z);
  if (!std::isfinite(norm) || norm < 1e-12) {
    *error = "a rotation quaternion must be finite and nonzero";
    return false;
  }
  w /= norm, x /= norm, y /= norm, z /= norm;
  const double r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                       2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                       2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
  for (int i = 0; i < 9; ++i) rot[i] = r[i];
  return true;
}

bool RotationFromAxisAngle(const double axis[3], double angle_deg, double rot[9], std::string* error) {
  const double norm = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
  if (!std::isfinite(norm) || norm < 1e-12 || !std::isfinite(angle_deg)) {
    *error = "a rotation axis must be finite and nonzero, the angle finite";
    return false;
  }
  // The quaternion of a turn by a about unit axis u is (cos a/2, sin a/2 u).
  const double half = 0.5 * angle_deg * kDegToRad;
  const double s = std::sin(half) / norm;
  return RotationFromQuaternion(std::cos(half), s * axis[0], s * axis[1], s * axis[2], rot, error);
}

bool ParseRotation(std::string_view spec, double rot[9], std::string* error) {
  const size_t colon = spec.find(':');
  const std::string_view kind = spec.substr(0, colon);
  const std::string_view args = colon == std::string_view::npos ? std::string_view() : spec.substr(colon + 1);
  std::string why;
  double v[4];
  bool ok = false;
  if (kind == "quat") {
    ok = ParseNumbers(args, 4, v, &why) && RotationFromQuaternion(v[0], v[1], v[2], v[3], rot, &why);
  } else if (kind == "axis-angle") {
    ok = ParseNumbers(args, 4, v, &why) && RotationFromAxisAngle(v, v[3], rot, &why);
  } else if (kind == "rpy") {
    ok = ParseNumbers(args, 3, v, &why) && RotationFromRpyDeg(v, rot, &why);
  } else {
    why = "expected quat:W,X,Y,Z, axis-angle:X,Y,Z,DEG or rpy:ROLL,PITCH,YAW";
  }
  if (!ok) *error = Cat({"rotation '", spec}) + "': " + why;
  return ok;
}

bool ParseVec3(std::string_view text, double out[3], std::string* error) {
  std::string why;
  if (ParseNumbers(text, 3, out, &why)) return true;
  *error = Cat({"'", text}) + "': " + why;
  return false;
}

int SanitizeDeviceForce(double force[3], double max_force) {
  // Any non-finite component: the whole force is untrustworthy.
  if (!std::isfinite(force[0]) || !std::isfinite(force[1]) || !std::isfinite(force[2])) {
    force[0] = force[1] = force[2] = 0;
    return 1;
  }
  // Clamp the magnitude, keeping the direction.
  const double mag = std::sqrt(force[0] * force[0] + force[1] * force[1] + force[2] * force[2]);
  if (mag > max_force && mag > 0) {
    const double s = max_force / mag;
    for (int i = 0; i < 3; ++i) force[i] *= s;
  }
  return 0;
}

}  // namespace idms::agent
