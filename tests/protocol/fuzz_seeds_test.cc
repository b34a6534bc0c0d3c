// The seeds of tests/fuzz/corpus/envelope_fuzz: real frames and sessions from the current codec.
// This test checks that every seed still parses and applies; run it with IDMS_WRITE_FUZZ_SEEDS=1
// to rewrite them after a format change. A session seed is records of
// [uint16 little-endian length][Envelope bytes], the form tests/fuzz/envelope_fuzz.cc reads.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "idms/protocol/envelope.h"
#include "idms/protocol/mesh_mirror.h"
#include "idms/sim/generate.h"

namespace idms {
namespace {

namespace fs = std::filesystem;

void AddRecord(const v1::Envelope& env, std::string* session) {
  std::string bytes;
  SerializeEnvelope(env, &bytes);
  session->push_back(static_cast<char>(bytes.size() & 0xFF));
  session->push_back(static_cast<char>(bytes.size() >> 8));
  *session += bytes;
}

// A dent pressed into a slab over `frames` frames; every frame as a record, optionally one lost.
std::string Session(int32_t rows, int32_t cols, int frames, int lost_frame, double keyframe_interval_s = 5) {
  SlabOptions options;
  options.rows = rows;
  options.cols = cols;
  const Model model = GenerateSlab(options);
  std::vector<double> rest(3 * model.external_atoms.size());
  GatherSurface(model, model.atom_pos_eq, rest);
  EncoderOptions encoder_options;
  encoder_options.keyframe_interval_s = keyframe_interval_s;
  MeshEncoder encoder(encoder_options);
  encoder.SetTopology(1, SurfaceTriangles(model));
  std::string session;
  for (int f = 0; f < frames; ++f) {
    std::vector<double> p = rest;
    const double cx = 0.5 * cols * (0.5 + 0.5 * f / frames), cy = 0.43 * rows;
    for (size_t i = 0; i < p.size(); i += 3) {
      const double dx = p[i] - cx, dy = p[i + 1] - cy;
      p[i + 2] -= 0.3 * std::exp(-(dx * dx + dy * dy) / 1.2);
    }
    v1::Envelope env;
    std::string error;
    EXPECT_TRUE(encoder.Encode(f / 60.0, p, &env, &error)) << error;
    if (f != lost_frame) AddRecord(env, &session);
  }
  return session;
}

std::string Frame(const v1::Envelope& env) {
  std::string bytes;
  SerializeEnvelope(env, &bytes);
  return bytes;
}

std::map<std::string, std::string> Seeds() {
  std::map<std::string, std::string> seeds;
  seeds["session_hex"] = Session(5, 4, 8, -1);
  seeds["session_hex_gap"] = Session(5, 4, 6, 3);
  seeds["session_slab_12x10"] = Session(12, 10, 12, -1, 0.1);
  {
    // One keyframe alone (applied as a whole input).
    const std::string s = Session(10, 10, 1, -1);
    seeds["keyframe_10x10"] = s.substr(2);
  }
  v1::Envelope samples;
  for (int i = 0; i < 3; ++i) {
    v1::DeviceSample* s = samples.mutable_device_samples()->add_samples();
    s->set_tick(static_cast<uint64_t>(i));
    s->set_time_s(i * 0.001);
    s->mutable_tool_pos()->set_z(1.4);
    s->mutable_force()->set_z(0.2);
    s->set_contact(true);
  }
  seeds["device_samples"] = Frame(samples);
  v1::Envelope hello;
  hello.mutable_hello()->set_protocol_version(kProtocolVersion);
  hello.mutable_hello()->set_role(v1::ROLE_AGENT);
  hello.mutable_hello()->mutable_scene()->set_model("hex_4x5_home");
  seeds["hello"] = Frame(hello);
  v1::Envelope command;
  command.mutable_command()->set_kind(v1::Command::KIND_KEYFRAME_REQUEST);
  seeds["command"] = Frame(command);
  return seeds;
}

// Applies a session seed to a mirror: how many frames applied and how many were gaps.
std::pair<int, int> Replay(const std::string& session) {
  MeshMirror mirror;
  int ok = 0, gaps = 0;
  size_t at = 0;
  while (at + 2 <= session.size()) {
    const size_t len =
        static_cast<uint8_t>(session[at]) | (static_cast<size_t>(static_cast<uint8_t>(session[at + 1])) << 8);
    at += 2;
    v1::Envelope env;
    std::string error;
    EXPECT_TRUE(ParseEnvelope(std::string_view(session).substr(at, len), &env, &error)) << error;
    const MirrorStatus status = mirror.Apply(env, &error);
    EXPECT_NE(status, MirrorStatus::kInvalid) << error;
    ok += status == MirrorStatus::kOk;
    gaps += status == MirrorStatus::kGap;
    at += len;
  }
  EXPECT_EQ(at, session.size());
  return {ok, gaps};
}

TEST(FuzzSeeds, MatchTheCurrentFormat) {
  const fs::path dir = fs::path(IDMS_SOURCE_DIR) / "tests/fuzz/corpus/envelope_fuzz";
  const std::map<std::string, std::string> seeds = Seeds();
  if (std::getenv("IDMS_WRITE_FUZZ_SEEDS") != nullptr) {
    fs::create_directories(dir);
    for (const auto& [name, bytes] : seeds) {
      std::ofstream(dir / (name + ".bin"), std::ios::binary) << bytes;
    }
  }
  for (const auto& [name, bytes] : seeds) {
    ASSERT_LT(bytes.size(), 65536u) << name << ": beyond the fuzzer's -max_len";
    std::ifstream in(dir / (name + ".bin"), std::ios::binary);
    ASSERT_TRUE(in) << name << ".bin missing; run with IDMS_WRITE_FUZZ_SEEDS=1";
    std::string stored;
    char buffer[4096];
    while (in.read(buffer, sizeof buffer) || in.gcount() > 0) {
      stored.append(buffer, static_cast<size_t>(in.gcount()));
    }
    v1::Envelope env;
    std::string error;
    if (name.rfind("session_", 0) == 0) {
      const auto [ok, gaps] = Replay(stored);
      EXPECT_GT(ok, 0) << name;
      EXPECT_EQ(gaps > 0, name.find("gap") != std::string::npos) << name;
    } else {
      EXPECT_TRUE(ParseEnvelope(stored, &env, &error)) << name << ": " << error;
    }
  }
}

}  // namespace
}  // namespace idms
