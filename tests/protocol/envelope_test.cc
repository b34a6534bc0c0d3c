// Envelope framing: round trip, and oversize, malformed and empty frames rejected with a message.
#include "idms/protocol/envelope.h"

#include <gtest/gtest.h>

#include <string>

namespace idms {
namespace {

TEST(Envelope, RoundTrips) {
  v1::Envelope env;
  v1::Hello* hello = env.mutable_hello();
  hello->set_protocol_version(kProtocolVersion);
  hello->set_role(v1::ROLE_AGENT);
  hello->set_identity("test agent");
  hello->mutable_scene()->set_model("hex_4x5_home");
  std::string bytes;
  SerializeEnvelope(env, &bytes);
  v1::Envelope back;
  std::string error;
  ASSERT_TRUE(ParseEnvelope(bytes, &back, &error)) << error;
  EXPECT_EQ(back.hello().identity(), "test agent");
  EXPECT_EQ(back.hello().scene().model(), "hex_4x5_home");
  EXPECT_STREQ(EnvelopeBodyName(back), "hello");
}

TEST(Envelope, DeviceSamplesBatch) {
  v1::Envelope env;
  v1::DeviceSamples* batch = env.mutable_device_samples();
  for (int i = 0; i < 20; ++i) {
    v1::DeviceSample* s = batch->add_samples();
    s->set_tick(static_cast<uint64_t>(1000 + i));
    s->set_time_s((1000 + i) * 0.001);
    s->mutable_tool_pos()->set_z(1.5 - 0.001 * i);
    s->mutable_force()->set_z(0.1 * i);
    s->set_compute_us(40);
    s->set_period_us(1000);
    s->set_contact(i > 5);
    s->set_substeps(1);
  }
  batch->mutable_stats()->set_ticks(1020);
  std::string bytes;
  SerializeEnvelope(env, &bytes);
  // ~20 samples of a 1 kHz loop: a few kB/s per agent.
  EXPECT_LT(bytes.size(), 20u * 80);
  v1::Envelope back;
  std::string error;
  ASSERT_TRUE(ParseEnvelope(bytes, &back, &error)) << error;
  EXPECT_EQ(back.device_samples().samples(19).tick(), 1019u);
}

TEST(Envelope, RejectsOversize) {
  v1::Envelope env;
  env.mutable_session_event()->set_message(std::string(5000, 'x'));
  std::string bytes;
  SerializeEnvelope(env, &bytes);
  v1::Envelope back;
  std::string error;
  EXPECT_FALSE(ParseEnvelope(bytes, &back, &error, 4096));
  EXPECT_NE(error.find("exceeds the limit of 4096"), std::string::npos) << error;
}

TEST(Envelope, RejectsGarbage) {
  v1::Envelope back;
  std::string error;
  // Field 1 (hello), length-delimited, claiming 100 bytes that are not there.
  EXPECT_FALSE(ParseEnvelope(std::string("\x0a\x64\x01\x02", 4), &back, &error));
  EXPECT_NE(error.find("not a valid idms.v1.Envelope"), std::string::npos) << error;
  // A truncated varint tag.
  EXPECT_FALSE(ParseEnvelope(std::string("\xff\xff", 2), &back, &error));
  // Wire type 7 does not exist.
  EXPECT_FALSE(ParseEnvelope(std::string("\x0f", 1), &back, &error));
}

TEST(Envelope, RejectsEmptyBody) {
  v1::Envelope back;
  std::string error;
  EXPECT_FALSE(ParseEnvelope("", &back, &error));
  EXPECT_NE(error.find("no body"), std::string::npos) << error;
  // Only a field from the future: kept as unknown, but there is no body we know.
  EXPECT_FALSE(ParseEnvelope(std::string("\xa0\x06\x01", 3), &back, &error));
  EXPECT_NE(error.find("no body"), std::string::npos) << error;
}

TEST(Envelope, ParseFramesUnpacksAFramesMessageInOrderAndPassesALoneEnvelope) {
  v1::Envelope samples, delta, outer;
  samples.mutable_device_samples()->add_samples()->set_tick(41);
  delta.mutable_mesh_delta()->set_sequence(9);
  std::string a, b, bytes;
  SerializeEnvelope(samples, &a);
  SerializeEnvelope(delta, &b);
  outer.mutable_frames()->add_envelopes(a);
  outer.mutable_frames()->add_envelopes(b);
  SerializeEnvelope(outer, &bytes);
  std::vector<v1::Envelope> out;
  std::string error;
  ASSERT_TRUE(ParseFrames(bytes, &out, &error)) << error;
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].device_samples().samples(0).tick(), 41u);
  EXPECT_EQ(out[1].mesh_delta().sequence(), 9u);
  out.clear();
  ASSERT_TRUE(ParseFrames(a, &out, &error)) << error;
  ASSERT_EQ(out.size(), 1u);
  EXPECT_TRUE(out[0].has_device_samples());
  // A malformed inner envelope, or a Frames inside a Frames, is refused with its index.
  v1::Envelope bad;
  bad.mutable_frames()->add_envelopes(a);
  bad.mutable_frames()->add_envelopes("\xff\xff garbage");
  SerializeEnvelope(bad, &bytes);
  out.clear();
  EXPECT_FALSE(ParseFrames(bytes, &out, &error));
  EXPECT_NE(error.find("frames[1]"), std::string::npos) << error;
  v1::Envelope nested;
  std::string inner;
  SerializeEnvelope(outer, &inner);
  nested.mutable_frames()->add_envelopes(inner);
  SerializeEnvelope(nested, &bytes);
  out.clear();
  EXPECT_FALSE(ParseFrames(bytes, &out, &error));
  EXPECT_NE(error.find("frames[0]: a Frames inside a Frames"), std::string::npos) << error;
  EXPECT_TRUE(out.empty());
  v1::Envelope empty;
  empty.mutable_frames();
  SerializeEnvelope(empty, &bytes);
  EXPECT_FALSE(ParseFrames(bytes, &out, &error));
  EXPECT_EQ(error, "a Frames with no envelope");
}

}  // namespace
}  // namespace idms
