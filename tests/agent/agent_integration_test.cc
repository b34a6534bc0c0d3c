// The real idms-agent binary against a fault-injecting stand-in endpoint on loopback, for the one
// fault the real server does not produce: a connection dropped without a close frame while the
// server stays up. Samples arrive exactly once and in order across it, and the mirror equals the
// simulated surface. Everything else the agent does with a server is tested against the real
// idms-server (tests/server/agent_server_integration_test.cc, sessions_integration_test.cc).
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "agent_process.h"
#include "idms/protocol/mesh_mirror.h"
#include "test_endpoint.h"

namespace idms::test {
namespace {

using std::chrono::seconds;

const std::string kModel = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";

nlohmann::json ReadJson(const std::string& path) { return nlohmann::json::parse(ReadText(path)); }

// All device samples' ticks over all connections, in arrival order.
std::vector<uint64_t> Ticks(const std::vector<ConnectionRecord>& connections) {
  std::vector<uint64_t> ticks;
  for (const ConnectionRecord& c : connections) {
    for (const v1::Envelope& e : c.frames) {
      if (!e.has_device_samples()) continue;
      for (const v1::DeviceSample& s : e.device_samples().samples()) ticks.push_back(s.tick());
    }
  }
  return ticks;
}

bool LastIsEnded(const ConnectionRecord& c) {
  return !c.frames.empty() && c.frames.back().has_session_event() &&
         c.frames.back().session_event().kind() == v1::SessionEvent::KIND_ENDED;
}

TEST(AgentIntegration, EverySampleOnceInOrderAcrossDisconnectAndMirrorMatches) {
  EndpointOptions options;
  options.drop_after_samples = 1200;  // mid-palpation
  TestEndpoint endpoint(options);
  const std::string dir = TempDir("resume");
  AgentProcess agent(
      {"--server", endpoint.url(), "--token", options.token, "--model-file", kModel, "--device", "scripted:palpate",
       "--duration", "3", "--no-realtime", "--summary-json", dir + "/summary.json", "--dump-final", dir + "/final.txt"},
      dir + "/agent.log");
  ASSERT_TRUE(agent.started());
  const std::optional<int> status = agent.Wait(seconds(60));
  ASSERT_TRUE(status.has_value()) << agent.Log();
  ASSERT_EQ(*status, 0) << agent.Log();
  const nlohmann::json summary = ReadJson(dir + "/summary.json");
  const std::vector<ConnectionRecord> connections = endpoint.Connections();

  // Two connections: the dropped one, then the resumed session with the token from Welcome.
  ASSERT_EQ(connections.size(), 2u) << agent.Log();
  EXPECT_TRUE(connections[0].dropped_by_endpoint);
  EXPECT_TRUE(connections[0].hello.session_id().empty());
  EXPECT_EQ(connections[1].hello.session_id(), "session-1");
  EXPECT_EQ(connections[1].hello.resume_token(), "resume-7f3a");
  EXPECT_EQ(summary["reconnects"], 1);

  // Every tick exactly once, in order, and as many as the loop ran.
  const std::vector<uint64_t> ticks = Ticks(connections);
  const uint64_t num_ticks = summary["ticks"];
  ASSERT_EQ(ticks.size(), num_ticks) << agent.Log();
  for (size_t i = 0; i < ticks.size(); ++i) ASSERT_EQ(ticks[i], i) << "sample " << i;
  EXPECT_EQ(summary["samples_sent"], num_ticks);
  EXPECT_EQ(summary["samples_dropped"], 0);
  // The resume asked for the first tick the endpoint lacked, and the agent started there.
  EXPECT_EQ(connections[1].welcome.next_tick(), Ticks({connections[0]}).size());

  // The mirror from every mesh frame, in order; each connection starts with a keyframe.
  MeshMirror mirror;
  int frames = 0;
  for (const ConnectionRecord& c : connections) {
    bool first_mesh = true;
    for (const v1::Envelope& e : c.frames) {
      if (!e.has_mesh_keyframe() && !e.has_mesh_delta()) continue;
      if (first_mesh) {
        EXPECT_TRUE(e.has_mesh_keyframe()) << "a connection's first mesh frame is a keyframe";
      }
      first_mesh = false;
      std::string error;
      ASSERT_EQ(mirror.Apply(e, &error), MirrorStatus::kOk) << error;
      ++frames;
    }
  }
  EXPECT_GT(frames, 150);  // ~60 Hz for 3 s
  const std::vector<double> truth = ReadNumbersAfterFirstLine(dir + "/final.txt");
  ASSERT_EQ(truth.size(), 3 * static_cast<size_t>(mirror.num_vertices()));
  double max_error = 0, max_dent = 0;
  for (size_t i = 0; i < truth.size(); ++i) {
    max_error = std::max(max_error, std::abs(static_cast<double>(mirror.positions()[i]) - truth[i]));
    if (i % 3 == 2) max_dent = std::max(max_dent, std::abs(truth[i]));
  }
  EXPECT_LE(max_error, mirror.quant_step()) << "mirror vs simulated surface";
  EXPECT_GT(max_dent, 1e-3) << "the palpation should leave the surface dented at t = 3 s";

  // A clean end: ENDED, then a WebSocket close frame.
  EXPECT_TRUE(LastIsEnded(connections[1]));
  EXPECT_TRUE(connections[1].close_frame);
  EXPECT_EQ(summary["ended_cleanly"], true);
}

}  // namespace
}  // namespace idms::test
