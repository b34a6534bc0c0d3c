// CheckAgentFrame: what the server refuses at the agent's door, naming the field.
#include "../../server/src/frame_checks.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

namespace idms::server {
namespace {

v1::Envelope OneSample() {
  v1::Envelope e;
  v1::DeviceSample* s = e.mutable_device_samples()->add_samples();
  s->set_tick(7);
  s->set_time_s(0.007);
  s->mutable_tool_pos()->set_z(1);
  return e;
}

TEST(FrameChecks, AnOrientedSampleIsTakenWhenItsQuaternionIsUnit) {
  v1::Envelope e = OneSample();
  v1::Quat* q = e.mutable_device_samples()->mutable_samples(0)->mutable_tool_orientation();
  q->set_w(std::cos(0.3));
  q->set_y(std::sin(0.3));
  std::string error;
  EXPECT_TRUE(CheckAgentFrame(e, &error)) << error;
  e.mutable_device_samples()->mutable_samples(0)->set_needle_punctured(true);
  e.mutable_device_samples()->mutable_samples(0)->set_needle_inserted(2.5);
  EXPECT_TRUE(CheckAgentFrame(e, &error)) << error;
}

TEST(FrameChecks, ANonUnitOrNonFiniteOrientationIsRefusedNamingTheField) {
  for (const double w : {0.0, 2.0, std::numeric_limits<double>::quiet_NaN()}) {
    v1::Envelope e = OneSample();
    e.mutable_device_samples()->mutable_samples(0)->mutable_tool_orientation()->set_w(w);
    std::string error;
    EXPECT_FALSE(CheckAgentFrame(e, &error)) << w;
    EXPECT_NE(error.find("samples[0].tool_orientation"), std::string::npos) << error;
  }
}

TEST(FrameChecks, ANonFiniteNeedleDepthIsRefused) {
  v1::Envelope e = OneSample();
  e.mutable_device_samples()->mutable_samples(0)->set_needle_inserted(std::numeric_limits<double>::infinity());
  std::string error;
  EXPECT_FALSE(CheckAgentFrame(e, &error));
  EXPECT_NE(error.find("needle_inserted"), std::string::npos) << error;
}

}  // namespace
}  // namespace idms::server
