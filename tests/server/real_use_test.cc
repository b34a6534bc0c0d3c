// The server under real use (issue 27): each probe that once broke it, kept as a test against the
// real idms-server on loopback. Viewers coming and going release their sockets; an agent that
// resumes while its old connection lingers (open, or silenced by a dead link) loses no tick; an
// ended session cannot be resumed; what a hostile agent or viewer sends is refused at the door
// and costs the server nothing it keeps.
#include <gtest/gtest.h>
#include <zstd.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "server_process.h"
#include "session_checks.h"
#include "test_clients.h"

namespace idms::test {
namespace {

using json = nlohmann::json;
using std::chrono::milliseconds;
using std::chrono::seconds;

bool IsWelcome(const std::optional<v1::Envelope>& e) { return e && e->has_welcome(); }

std::vector<uint64_t> Range(uint64_t first, uint64_t end) {
  std::vector<uint64_t> v;
  for (uint64_t t = first; t < end; ++t) v.push_back(t);
  return v;
}

std::optional<v1::Envelope> ErrorAfter(FakeAgent& agent) {
  return agent.ReadUntil([](const v1::Envelope& e) {
    return e.has_session_event() && e.session_event().kind() == v1::SessionEvent::KIND_ERROR;
  });
}

TEST(RealUse, ViewersComingAndGoingReleaseTheirSocketsAndGauges) {
  const std::string dir = TempDir("real-use-viewers");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string admin = server.Token("admin");
  FakeAgent agent(server.port(), server.Token("agent"));
  const auto welcome = agent.Hello();
  ASSERT_TRUE(IsWelcome(welcome));
  const std::string id = welcome->welcome().session_id();
  ASSERT_TRUE(agent.SendSamples(0, 20));
  // Baselines once the session is up, before any viewer.
  ASSERT_TRUE(Eventually([&] { return MetricValue(server.port(), admin, "idms_open_websockets") == 1; }));
  const int pid = server.process().pid();
  const int fds = OpenFds(pid);
  // Three waves of 20 viewers: half close cleanly, half drop without a close frame.
  uint64_t tick = 20;
  for (int wave = 0; wave < 3; ++wave) {
    std::vector<std::unique_ptr<TestViewer>> clean;
    for (int i = 0; i < 10; ++i) clean.push_back(std::make_unique<TestViewer>(server.port(), id, admin));
    std::vector<std::unique_ptr<FakeAgent>> dropped;  // raw clients on /ws/session: read one frame, drop
    for (int i = 0; i < 10; ++i) {
      WsResult r = WsConnect(server.port(), "/ws/session/" + id, {{"Authorization", "Bearer " + admin}});
      ASSERT_EQ(r.status, 101) << r.error;  // WsConnect returns with its socket closed, no close frame
    }
    ASSERT_TRUE(agent.SendSamples(tick, 20));
    tick += 20;
    clean.clear();  // clean closes
  }
  // Everything the viewers held comes back: descriptors, the WebSocket gauge, the viewer gauge.
  EXPECT_TRUE(Eventually([&] { return MetricValue(server.port(), admin, "idms_open_websockets") == 1; }, seconds(20)))
      << MetricValue(server.port(), admin, "idms_open_websockets");
  EXPECT_TRUE(Eventually([&] { return MetricValue(server.port(), admin, "idms_viewers") == 0; }, seconds(20)));
  EXPECT_TRUE(Eventually([&] { return OpenFds(pid) <= fds + 1; }, seconds(20)))
      << "descriptors: " << fds << " before, " << OpenFds(pid) << " after";
}

TEST(RealUse, AResumeWhileTheOldConnectionIsOpenLosesNoTick) {
  const std::string dir = TempDir("real-use-resume-open");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string token = server.Token("agent"), observer = server.Token("observer");
  FakeAgent first(server.port(), token);
  const auto welcome = first.Hello();
  ASSERT_TRUE(IsWelcome(welcome));
  const std::string id = welcome->welcome().session_id(), resume = welcome->welcome().resume_token();
  ASSERT_TRUE(first.SendSamples(0, 100));
  // The server has them (its two connections' frames are not ordered between each other).
  ASSERT_TRUE(Eventually([&] {
    const HttpReply r = Get(server.port(), "/api/sessions/" + id, observer);
    return r.status == 200 && json::parse(r.body)["samples"] == 100;
  }));
  // The resume arrives while the first connection is still open: its Welcome says where to go on.
  FakeAgent second(server.port(), token);
  const auto resumed = second.Hello(id, resume);
  ASSERT_TRUE(IsWelcome(resumed));
  EXPECT_EQ(resumed->welcome().next_tick(), 100u);
  ASSERT_TRUE(second.SendSamples(100, 100));
  // The old connection goes away (as a lingering one finally does): the new one stays the agent.
  first.Close();
  ASSERT_TRUE(second.SendSamples(200, 100));
  const auto ack = second.End(299);
  ASSERT_TRUE(ack) << server.Log();
  EXPECT_EQ(ack->ack().next_tick(), 300u);
  ASSERT_TRUE(DownloadRecording(server.port(), id, observer, dir + "/rec.mcap"));
  EXPECT_EQ(RecordedTicks(dir + "/rec.mcap"), Range(0, 300));
}

TEST(RealUse, AnEndedSessionCannotBeResumedAndATickCannotWrap) {
  const std::string dir = TempDir("real-use-ended");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string token = server.Token("agent");
  FakeAgent agent(server.port(), token);
  const auto welcome = agent.Hello();
  ASSERT_TRUE(IsWelcome(welcome));
  ASSERT_TRUE(agent.SendSamples(0, 10));
  ASSERT_TRUE(agent.End(9));
  // At once, and again later: the answer is that the session has ended.
  for (int i = 0; i < 3; ++i) {
    FakeAgent again(server.port(), token);
    const auto answer = again.Hello(welcome->welcome().session_id(), welcome->welcome().resume_token());
    ASSERT_TRUE(answer);
    EXPECT_FALSE(answer->has_welcome()) << "resume " << i << " of an ended session accepted";
    EXPECT_EQ(answer->session_event().kind(), v1::SessionEvent::KIND_ENDED) << answer->DebugString();
  }
  // A replay's controls are checked at the door: a NaN seek time or speed is refused, by name.
  {
    FakeAgent replay(server.port(), server.Token("observer"), "/ws/replay/" + welcome->welcome().session_id());
    ASSERT_TRUE(replay.connected());
    v1::Envelope seek;
    seek.mutable_playback_control()->set_action(v1::PlaybackControl::ACTION_SEEK);
    seek.mutable_playback_control()->set_seek_time_s(std::nan(""));
    ASSERT_TRUE(replay.Send(seek));
    const auto error = ErrorAfter(replay);
    ASSERT_TRUE(error);
    EXPECT_NE(error->session_event().message().find("seek_time_s must be finite"), std::string::npos);
  }
  // A tick at 2^64 - 1 is refused at the door (tick + 1 would wrap to 0).
  FakeAgent wrap(server.port(), token);
  ASSERT_TRUE(IsWelcome(wrap.Hello()));
  ASSERT_TRUE(wrap.SendSamples(UINT64_MAX, 1));
  const auto error = ErrorAfter(wrap);
  ASSERT_TRUE(error);
  EXPECT_NE(error->session_event().message().find("2^63"), std::string::npos) << error->DebugString();
}

TEST(RealUse, AnAgentSilencedByADeadLinkResumesThroughTheProxyWithEveryTickRecordedOnce) {
  const std::string dir = TempDir("real-use-silence");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string observer = server.Token("observer");
  SilenceProxy proxy(server.port());
  ChildProcess agent(IDMS_AGENT_BIN,
                     {"--server", "ws://127.0.0.1:" + std::to_string(proxy.port()), "--token", server.Token("agent"),
                      "--model", "hex_4x5_home", "--cache-dir", dir + "/cache", "--device", "scripted:palpate",
                      "--duration", "6", "--flush-timeout", "15", "--summary-json", dir + "/summary.json"},
                     dir + "/agent.log");
  const std::string id = WaitForLiveSession(server.port(), observer, 1500);
  ASSERT_FALSE(id.empty()) << server.Log() << agent.Log();
  // The link goes silent without a close, both ways: the agent must notice and resume on a new
  // connection while the server still holds the silent one.
  proxy.Silence();
  ASSERT_EQ(agent.Wait(seconds(60)), 0) << agent.Log();
  EXPECT_GE(proxy.connections(), 2) << agent.Log();
  const json summary = json::parse(ReadText(dir + "/summary.json"));
  EXPECT_EQ(summary["session_id"], id);
  EXPECT_EQ(summary["samples_dropped"], 0);
  EXPECT_EQ(summary["ended_cleanly"], true) << agent.Log();
  ASSERT_TRUE(Eventually([&] { return Sessions(server.port(), observer)[0]["state"] == "ended"; })) << server.Log();
  ASSERT_TRUE(DownloadRecording(server.port(), id, observer, dir + "/rec.mcap"));
  const uint64_t ticks = summary["ticks"];
  EXPECT_EQ(ticks, 6000u);
  EXPECT_EQ(RecordedTicks(dir + "/rec.mcap"), Range(0, ticks)) << agent.Log();
}

TEST(RealUse, LiveSessionsAreBoundedAndResumesStillPass) {
  const std::string dir = TempDir("real-use-max-live");
  ServerProcess server(dir + "/data", {"--max-live-sessions", "2"});
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string token = server.Token("agent");
  FakeAgent a(server.port(), token), b(server.port(), token), c(server.port(), token);
  const auto first = a.Hello();
  ASSERT_TRUE(IsWelcome(first));
  ASSERT_TRUE(IsWelcome(b.Hello()));
  const auto third = c.Hello();
  ASSERT_TRUE(third);
  EXPECT_FALSE(third->has_welcome());
  EXPECT_NE(third->session_event().message().find("--max-live-sessions"), std::string::npos);
  // A resume of a session live here is not a new one.
  FakeAgent again(server.port(), token);
  EXPECT_TRUE(IsWelcome(again.Hello(first->welcome().session_id(), first->welcome().resume_token())));
}

TEST(RealUse, ASilentAgentIsNoticedWithinItsIdleTimeout) {
  const std::string dir = TempDir("real-use-silent-agent");
  ServerProcess server(dir + "/data", {"--agent-idle-timeout-ms", "1000"});
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string observer = server.Token("observer");
  FakeAgent agent(server.port(), server.Token("agent"));
  const auto welcome = agent.Hello();
  ASSERT_TRUE(IsWelcome(welcome));
  ASSERT_TRUE(agent.SendSamples(0, 10));
  // From here the agent neither sends nor reads (so answers no ping): the server drops it.
  const std::string id = welcome->welcome().session_id();
  EXPECT_TRUE(Eventually(
      [&] {
        const HttpReply r = Get(server.port(), "/api/sessions/" + id, observer);
        return r.body.find("KIND_AGENT_DISCONNECTED") != std::string::npos;
      },
      seconds(10)));
}

TEST(RealUse, HostileAgentFramesAreRefusedAtTheDoorAndKeepNothing) {
  const std::string dir = TempDir("real-use-hostile");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string token = server.Token("agent"), observer = server.Token("observer");
  const int pid = server.process().pid();
  // A 4 MiB identity is refused, and not listed.
  {
    FakeAgent agent(server.port(), token);
    const auto answer = agent.Hello("", "", std::string(4 << 20, 'x'));
    ASSERT_TRUE(answer);
    EXPECT_FALSE(answer->has_welcome());
    EXPECT_NE(answer->session_event().message().find("Hello.identity"), std::string::npos);
    EXPECT_LT(Get(server.port(), "/api/sessions", observer).body.size(), 1000u);
  }
  // Times that are not session times: NaN, 1e300, negative.
  for (double t : {std::nan(""), 1e300, -1.0}) {
    FakeAgent agent(server.port(), token);
    ASSERT_TRUE(IsWelcome(agent.Hello()));
    v1::Envelope e;
    v1::DeviceSample* s = e.mutable_device_samples()->add_samples();
    s->set_tick(0);
    s->set_time_s(t);
    ASSERT_TRUE(agent.Send(e));
    const auto error = ErrorAfter(agent);
    ASSERT_TRUE(error) << t;
    EXPECT_NE(error->session_event().message().find("time_s"), std::string::npos) << error->DebugString();
  }
  // A 1 MiB event text.
  {
    FakeAgent agent(server.port(), token);
    ASSERT_TRUE(IsWelcome(agent.Hello()));
    v1::Envelope e;
    e.mutable_session_event()->set_kind(v1::SessionEvent::KIND_WARNING);
    e.mutable_session_event()->set_message(std::string(1 << 20, 'w'));
    ASSERT_TRUE(agent.Send(e));
    const auto error = ErrorAfter(agent);
    ASSERT_TRUE(error);
    EXPECT_NE(error->session_event().message().find("SessionEvent.message"), std::string::npos);
  }
  // A decompression bomb: an 8 KB keyframe that declares 200 MiB of zeros, for a model of 58
  // atoms. Refused by what the model can need, and the server keeps no buffer for it.
  // (Made before the agent says Hello: an agent that neither sends nor reads for its idle timeout
  // is dropped, and a sanitized build takes seconds to compress 200 MiB.)
  std::string bomb;
  {
    const std::string zeros(size_t{200} << 20, '\0');
    bomb.resize(ZSTD_compressBound(zeros.size()));
    bomb.resize(ZSTD_compress(bomb.data(), bomb.size(), zeros.data(), zeros.size(), 19));
  }
  ASSERT_LT(bomb.size(), 64u << 10);
  const int64_t rss_before = RssKiB(pid);
  {
    FakeAgent agent(server.port(), token);
    ASSERT_TRUE(IsWelcome(agent.Hello()));
    v1::Envelope e;
    v1::MeshKeyframe* k = e.mutable_mesh_keyframe();
    k->set_num_vertices(4 << 20);
    k->set_num_triangles(0);
    k->set_quant_step(1e-4);
    k->set_compression(v1::COMPRESSION_ZSTD);
    k->set_payload(bomb);
    ASSERT_TRUE(agent.Send(e));
    const auto error = ErrorAfter(agent);
    ASSERT_TRUE(error);
    EXPECT_NE(error->session_event().message().find("vertices exceed"), std::string::npos) << error->DebugString();
  }
  EXPECT_LT(RssKiB(pid) - rss_before, 64 << 10) << "KiB held after a refused bomb";
  // A viewer's annotation as a text frame, or at a time that is no session time.
  FakeAgent agent(server.port(), token);
  const auto welcome = agent.Hello();
  ASSERT_TRUE(IsWelcome(welcome));
  TestViewer viewer(server.port(), welcome->welcome().session_id(), observer);
  v1::Envelope note;
  note.mutable_annotation()->set_text("late");
  note.mutable_annotation()->set_time_s(std::nan(""));
  viewer.Send(note);
  ASSERT_TRUE(Eventually([&] {
    for (const v1::Envelope& f : viewer.Frames()) {
      if (f.has_session_event() && f.session_event().message().find("Annotation.time_s") != std::string::npos)
        return true;
    }
    return false;
  }));
}

// Issue 28: /metrics is what Prometheus expects, checked by its own promtool (names in base units:
// idms_session_tick_p99_us failed it), with a live session's own series present.
TEST(RealUse, MetricsPassPromtoolsCheck) {
  const std::string dir = TempDir("real-use-promtool");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string admin = server.Token("admin");
  FakeAgent agent(server.port(), server.Token("agent"));
  ASSERT_TRUE(IsWelcome(agent.Hello()));
  v1::Envelope batch;
  v1::DeviceSample* s = batch.mutable_device_samples()->add_samples();
  s->set_time_s(0.001);
  batch.mutable_device_samples()->mutable_stats()->set_compute_p99_us(120);
  ASSERT_TRUE(agent.Send(batch));
  std::string metrics;
  ASSERT_TRUE(Eventually([&] {
    const HttpReply r = Get(server.port(), "/metrics", admin);
    metrics = r.body;
    return r.status == 200 && metrics.find("idms_session_tick_p99_seconds{") != std::string::npos;
  })) << metrics;
  EXPECT_NE(metrics.find("} 0.00012\n"), std::string::npos) << "120 us as seconds:\n" << metrics;
  std::ofstream(dir + "/metrics.txt") << metrics;
  ChildProcess promtool("/bin/sh", {"-c", "promtool check metrics < " + dir + "/metrics.txt"}, dir + "/promtool.log");
  EXPECT_EQ(promtool.Wait(seconds(60)), 0) << promtool.Log();
  EXPECT_EQ(promtool.Log(), "") << "promtool's findings";
}

}  // namespace
}  // namespace idms::test
