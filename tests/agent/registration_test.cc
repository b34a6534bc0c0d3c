// Registration: the three ways of writing a rotation agree, the transform inverts, forces turn.
#include "idms/agent/registration.h"

#include <gtest/gtest.h>

#include <cmath>

#include "idms/sim/tool.h"

namespace idms::test {
namespace {

using agent::Registration;

void ExpectRotEq(const double a[9], const double b[9]) {
  for (int i = 0; i < 9; ++i) EXPECT_NEAR(a[i], b[i], 1e-12) << "entry " << i;
}

TEST(Registration, QuaternionAxisAngleAndRpyAgree) {
  // 90 degrees about z, three ways.
  double q[9], aa[9], rpy[9], parsed[9];
  std::string error;
  const double s = std::sqrt(0.5);
  ASSERT_TRUE(agent::RotationFromQuaternion(s, 0, 0, s, q, &error));
  const double z[3] = {0, 0, 2};
  ASSERT_TRUE(agent::RotationFromAxisAngle(z, 90, aa, &error));
  const double angles[3] = {0, 0, 90};
  ASSERT_TRUE(agent::RotationFromRpyDeg(angles, rpy, &error));
  ExpectRotEq(q, aa);
  ExpectRotEq(q, rpy);
  ASSERT_TRUE(agent::ParseRotation("axis-angle:0,0,1,90", parsed, &error)) << error;
  ExpectRotEq(q, parsed);
  // x goes to y.
  EXPECT_NEAR(q[3], 1, 1e-12);
}

TEST(Registration, DeviceToModelInvertsAndForcesTurnWithTheFrame) {
  Registration r;
  std::string error;
  ASSERT_TRUE(agent::ParseRotation("quat:0.9,0.1,-0.3,0.2", r.rot, &error)) << error;
  r.scale = 25.4;  // device in inches, model in mm
  r.offset[0] = 1, r.offset[1] = -2, r.offset[2] = 3;
  r.force_scale = 0.5;
  const double p_device[3] = {0.3, -0.1, 0.7};
  double p_model[3], back[3];
  r.DeviceToModel(p_device, p_model);
  r.ModelToDevice(p_model, back);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(back[i], p_device[i], 1e-12);
  // A force keeps its magnitude (times force_scale) and turns with R^T.
  const double f_model[3] = {0, 0, 2};
  double f_device[3], f_back[3];
  r.ForceToDevice(f_model, f_device);
  EXPECT_NEAR(std::hypot(f_device[0], f_device[1], f_device[2]), 1.0, 1e-12);
  r.ForceToModel(f_device, f_back);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(f_back[i], f_model[i], 1e-12);
}

// An orientation turns with the frame as a direction does: a needle's axis (the local -z) mapped
// to the model is the device's axis turned by R; mapped back, the orientation is the device's.
TEST(Registration, AnOrientationTurnsWithTheFrameAndMapsBack) {
  Registration r;
  std::string error;
  ASSERT_TRUE(agent::ParseRotation("quat:0.9,0.1,-0.3,0.2", r.rot, &error)) << error;
  r.scale = 25.4;  // scale and offset do not turn anything
  r.offset[0] = 5;
  const double c = std::cos(0.35), s = std::sin(0.35);
  const double q_device[4] = {2 * c, 2 * s * 0.6, 0, 2 * s * 0.8};  // not unit: normalised
  double q_model[4], back[4];
  ASSERT_TRUE(r.OrientationToModel(q_device, q_model));
  EXPECT_NEAR(q_model[0] * q_model[0] + q_model[1] * q_model[1] + q_model[2] * q_model[2] + q_model[3] * q_model[3], 1,
              1e-12);
  EXPECT_GE(q_model[0], 0);
  const double unit[4] = {c, s * 0.6, 0, s * 0.8};
  double axis_device[3], axis_model[3], turned[3];
  NeedleAxisOf(unit, axis_device);
  NeedleAxisOf(q_model, axis_model);
  r.ForceToModel(axis_device, turned);  // R v (force_scale 1)
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(axis_model[i], turned[i], 1e-12) << i;
  ASSERT_TRUE(r.OrientationToDevice(q_model, back));
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(back[i], unit[i], 1e-12) << i;
  // No rotation: zero or non-finite.
  const double zero[4] = {0, 0, 0, 0}, nan[4] = {std::nan(""), 0, 0, 1};
  EXPECT_FALSE(r.OrientationToModel(zero, q_model));
  EXPECT_FALSE(r.OrientationToModel(nan, q_model));
}

TEST(Registration, BadRotationsAreExplained) {
  double rot[9];
  std::string error;
  EXPECT_FALSE(agent::ParseRotation("quat:0,0,0,0", rot, &error));
  EXPECT_NE(error.find("nonzero"), std::string::npos) << error;
  EXPECT_FALSE(agent::ParseRotation("euler:1,2,3", rot, &error));
  EXPECT_NE(error.find("axis-angle:X,Y,Z,DEG"), std::string::npos) << error;
  EXPECT_FALSE(agent::ParseRotation("rpy:1,2", rot, &error));
  EXPECT_NE(error.find("expected 3"), std::string::npos) << error;
  double v[3];
  EXPECT_FALSE(agent::ParseVec3("1,x,3", v, &error));
  EXPECT_NE(error.find("'x'"), std::string::npos) << error;
}

}  // namespace
}  // namespace idms::test
