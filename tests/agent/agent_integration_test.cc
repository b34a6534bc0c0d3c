// The real idms-agent binary against the test endpoint on loopback: samples exactly once and in
// order across a forced disconnect, the mirror equal to the simulated surface, clean shutdown on
// SIGTERM, a bad token refused clearly, the model library download and cache.
#include <gtest/gtest.h>
#include <signal.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "agent_process.h"
#include "idms/agent/model_source.h"
#include "idms/protocol/mesh_mirror.h"
#include "test_endpoint.h"

namespace idms::test {
namespace {

using std::chrono::milliseconds;
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

TEST(AgentIntegration, BacklogOverflowDropsOldestCountsAndTellsTheServer) {
  // The server goes away for 1.5 s; the agent keeps only 300 samples meanwhile.
  EndpointOptions options;
  options.drop_after_samples = 500;
  options.down_after_drop = milliseconds(1500);
  TestEndpoint endpoint(options);
  const std::string dir = TempDir("overflow");
  AgentProcess agent(
      {"--server", endpoint.url(), "--token", options.token, "--model-file", kModel, "--device", "scripted:stroke-slow",
       "--duration", "3", "--no-realtime", "--backlog", "300", "--summary-json", dir + "/summary.json"},
      dir + "/agent.log");
  ASSERT_EQ(agent.Wait(seconds(60)), std::optional<int>(0)) << agent.Log();
  EXPECT_GE(endpoint.UpgradesRefused(), 2) << "the agent retried with backoff while the server was down";
  const nlohmann::json summary = ReadJson(dir + "/summary.json");
  const std::vector<ConnectionRecord> connections = endpoint.Connections();
  ASSERT_EQ(connections.size(), 2u);
  // Strictly increasing ticks; each tick either arrived once or was dropped and counted.
  const std::vector<uint64_t> ticks = Ticks(connections);
  for (size_t i = 1; i < ticks.size(); ++i) ASSERT_LT(ticks[i - 1], ticks[i]);
  const uint64_t dropped = summary["samples_dropped"];
  EXPECT_GT(dropped, 500u);
  EXPECT_EQ(ticks.size() + dropped, summary["ticks"].get<uint64_t>());
  EXPECT_EQ(ticks.back() + 1, summary["ticks"].get<uint64_t>());
  // The server was told: a SessionEvent with the count, and the cumulative field in the batches.
  uint64_t told = 0, field = 0;
  for (const v1::Envelope& e : connections[1].frames) {
    if (e.has_session_event() && e.session_event().kind() == v1::SessionEvent::KIND_SAMPLES_DROPPED) {
      told += e.session_event().count();
    }
    if (e.has_device_samples()) field = std::max(field, e.device_samples().samples_dropped());
  }
  EXPECT_EQ(told, dropped);
  EXPECT_EQ(field, dropped);
}

TEST(AgentIntegration, SigtermFinishesFlushesAndClosesCleanly) {
  TestEndpoint endpoint(EndpointOptions{});
  const std::string dir = TempDir("sigterm");
  AgentProcess agent({"--server", endpoint.url(), "--token", "agent-secret", "--model-file", kModel, "--device",
                      "human:stroke-slow", "--summary-json", dir + "/summary.json"},
                     dir + "/agent.log");
  ASSERT_TRUE(agent.started());
  // Running and streaming: half a second of samples arrived.
  ASSERT_TRUE(endpoint.WaitFor(
      [](const std::vector<ConnectionRecord>& cs) { return !cs.empty() && Ticks(cs).size() >= 500; }, seconds(30)))
      << agent.Log();
  agent.Signal(SIGTERM);
  const std::optional<int> status = agent.Wait(seconds(30));
  ASSERT_TRUE(status.has_value()) << agent.Log();
  EXPECT_EQ(*status, 0) << agent.Log();
  // Everything the loop ran was delivered before the close.
  const nlohmann::json summary = ReadJson(dir + "/summary.json");
  const std::vector<ConnectionRecord> connections = endpoint.Connections();
  ASSERT_EQ(connections.size(), 1u);
  const std::vector<uint64_t> ticks = Ticks(connections);
  EXPECT_EQ(ticks.size(), summary["ticks"].get<uint64_t>());
  for (size_t i = 0; i < ticks.size(); ++i) ASSERT_EQ(ticks[i], i);
  EXPECT_TRUE(LastIsEnded(connections[0]));
  EXPECT_TRUE(connections[0].close_frame);
  EXPECT_NE(agent.Log().find("SIGTERM"), std::string::npos) << agent.Log();
}

TEST(AgentIntegration, BadTokenExitsWithClearError) {
  TestEndpoint endpoint(EndpointOptions{});
  const std::string dir = TempDir("badtoken");
  AgentProcess agent({"--server", endpoint.url(), "--token", "wrong", "--model-file", kModel, "--device",
                      "scripted:palpate", "--no-realtime"},
                     dir + "/agent.log");
  ASSERT_TRUE(agent.started());
  const std::optional<int> status = agent.Wait(seconds(30));
  ASSERT_TRUE(status.has_value()) << agent.Log();
  EXPECT_EQ(*status, 2) << agent.Log();
  const std::string log = agent.Log();
  EXPECT_NE(log.find("refused the token (HTTP 401"), std::string::npos) << log;
  EXPECT_NE(log.find("--token"), std::string::npos) << log;
  EXPECT_TRUE(endpoint.Connections().empty());
}

TEST(AgentIntegration, CommandsReachTheLoop) {
  TestEndpoint endpoint(EndpointOptions{});
  const std::string dir = TempDir("commands");
  AgentProcess agent({"--server", endpoint.url(), "--token", "agent-secret", "--model-file", kModel, "--device",
                      "scripted:palpate", "--no-realtime", "--summary-json", dir + "/summary.json"},
                     dir + "/agent.log");
  ASSERT_TRUE(agent.started());
  ASSERT_TRUE(
      endpoint.WaitFor([](const std::vector<ConnectionRecord>& cs) { return Ticks(cs).size() >= 100; }, seconds(30)));
  // A reset and a keyframe request: the next mesh frame is a keyframe.
  v1::Command reset;
  reset.set_kind(v1::Command::KIND_RESET);
  endpoint.SendCommand(reset);
  v1::Command keyframe;
  keyframe.set_kind(v1::Command::KIND_KEYFRAME_REQUEST);
  endpoint.SendCommand(keyframe);
  const auto keyframes = [](const std::vector<ConnectionRecord>& cs) {
    int n = 0;
    for (const v1::Envelope& e : cs.at(0).frames) n += e.has_mesh_keyframe() ? 1 : 0;
    return n;
  };
  ASSERT_TRUE(
      endpoint.WaitFor([&](const std::vector<ConnectionRecord>& cs) { return keyframes(cs) >= 2; }, seconds(30)));
  agent.Signal(SIGTERM);
  ASSERT_EQ(agent.Wait(seconds(30)), std::optional<int>(0)) << agent.Log();
  EXPECT_EQ(ReadJson(dir + "/summary.json")["commands"], 2);
}

// The library's routes as model_source.h defines them, served by the endpoint.
EndpointOptions LibraryEndpoint(std::string* fem_sha) {
  const std::string fem = ReadText(kModel + ".fem");
  const std::string plg = ReadText(kModel + ".plg");
  *fem_sha = agent::Sha256Hex(fem);
  EndpointOptions o;
  const nlohmann::json meta = {
      {"name", "hex_4x5_home"}, {"version", 3}, {"fem_sha256", *fem_sha}, {"plg_sha256", agent::Sha256Hex(plg)}};
  o.files["/api/models/hex_4x5_home?version=3"] = meta.dump();
  o.files["/api/models/hex_4x5_home/fem?version=3"] = fem;
  o.files["/api/models/hex_4x5_home/plg?version=3"] = plg;
  return o;
}

TEST(AgentIntegration, ModelByNameIsDownloadedOnceThenCached) {
  std::string fem_sha;
  const std::string dir = TempDir("library");
  const std::string cache = dir + "/cache";
  {
    TestEndpoint endpoint(LibraryEndpoint(&fem_sha));
    for (int run = 0; run < 2; ++run) {
      AgentProcess agent({"--server", endpoint.url(), "--token", "agent-secret", "--model", "hex_4x5_home@3",
                          "--cache-dir", cache, "--device", "scripted:palpate", "--duration", "0.2", "--no-realtime"},
                         dir + "/agent.log");
      ASSERT_EQ(agent.Wait(seconds(30)), std::optional<int>(0)) << agent.Log();
    }
    // Metadata twice, the files once: the second run found them by hash.
    EXPECT_EQ(endpoint.HttpRequests("/api/models/hex_4x5_home?version=3"), 2);
    EXPECT_EQ(endpoint.HttpRequests("/api/models/hex_4x5_home/fem?version=3"), 1);
    EXPECT_EQ(endpoint.HttpRequests("/api/models/hex_4x5_home/plg?version=3"), 1);
    EXPECT_TRUE(std::filesystem::exists(cache + "/blobs/" + fem_sha));
  }
  // Server gone: the model comes from the cache, the loop runs anyway, the agent gives up
  // delivering after its flush timeout and exits normally.
  AgentProcess agent({"--server", "ws://127.0.0.1:1", "--token", "agent-secret", "--model", "hex_4x5_home@3",
                      "--cache-dir", cache, "--device", "scripted:palpate", "--duration", "0.5", "--no-realtime",
                      "--flush-timeout", "0.5", "--summary-json", dir + "/summary.json"},
                     dir + "/offline.log");
  ASSERT_EQ(agent.Wait(seconds(30)), std::optional<int>(0)) << agent.Log();
  EXPECT_NE(agent.Log().find("using the cached"), std::string::npos) << agent.Log();
  EXPECT_EQ(ReadJson(dir + "/summary.json")["ticks"], 500);
}

TEST(AgentIntegration, UnknownModelIsAClearError) {
  std::string fem_sha;
  TestEndpoint endpoint(LibraryEndpoint(&fem_sha));
  const std::string dir = TempDir("unknown-model");
  AgentProcess agent({"--server", endpoint.url(), "--token", "agent-secret", "--model", "liver@1", "--cache-dir",
                      dir + "/cache", "--device", "scripted:palpate", "--duration", "0.2"},
                     dir + "/agent.log");
  ASSERT_EQ(agent.Wait(seconds(30)), std::optional<int>(1)) << agent.Log();
  EXPECT_NE(agent.Log().find("model 'liver@1': GET /api/models/liver?version=1"), std::string::npos) << agent.Log();
  EXPECT_NE(agent.Log().find("HTTP 404"), std::string::npos) << agent.Log();
}

}  // namespace
}  // namespace idms::test
