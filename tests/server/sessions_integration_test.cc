// Live sessions with the real idms-server and idms-agent on loopback: several viewers whose
// mirrors equal the agent's final surface, a late joiner served a keyframe at once, commands from
// an admin relayed and an observer's refused, the recording downloaded and read back, and an
// agent that resumes after the server is killed, with every tick in the recording exactly once.
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>
#include <cmath>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "idms/protocol/envelope.h"
#include "idms/protocol/mesh_mirror.h"
#include "idms/protocol/recording.h"
#include "server_process.h"
#include "session_checks.h"

namespace idms::test {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace websocket = beast::websocket;
using json = nlohmann::json;
using std::chrono::milliseconds;
using std::chrono::seconds;

std::vector<std::string> AgentArgs(const ServerProcess& server, const std::string& dir, double duration) {
  return {"--server",
          "ws://127.0.0.1:" + server.port_string(),
          "--token",
          server.Token("agent"),
          "--model",
          "hex_4x5_home",
          "--device",
          "scripted:palpate",
          "--duration",
          std::to_string(duration),
          "--no-realtime",
          "--cache-dir",
          dir + "/cache",
          "--dump-final",
          dir + "/final.txt",
          "--summary-json",
          dir + "/summary.json"};
}

TEST(Sessions, ViewersSeeTheAgentsSurfaceLateJoinersGetAKeyframeCommandsByRole) {
  const std::string dir = TempDir("sessions-live");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  const uint16_t port = server.port();
  const std::string observer = server.Token("observer"), admin = server.Token("admin");
  ChildProcess agent(IDMS_AGENT_BIN, AgentArgs(server, dir, 4), dir + "/agent.log");
  // The session appears, live.
  const std::string id = WaitForLiveSession(port, observer);
  ASSERT_FALSE(id.empty()) << server.Log();
  TestViewer a(port, id, observer), b(port, id, admin);
  // A late joiner: Welcome, then a keyframe from the server's mirror straight away.
  ASSERT_TRUE(Eventually([&] { return Sessions(port, observer)[0]["samples"].get<int>() > 1500; }));
  TestViewer late(port, id, observer);
  ASSERT_TRUE(Eventually([&] { return late.Frames().size() >= 2; }));
  const std::vector<v1::Envelope> first = late.Frames();
  ASSERT_TRUE(first[0].has_welcome());
  EXPECT_EQ(first[0].welcome().session_id(), id);
  EXPECT_EQ(first[0].welcome().scene().model(), "hex_4x5_home");
  EXPECT_TRUE(first[1].has_mesh_keyframe());
  // Commands: an observer's is refused, an admin's reaches the agent.
  v1::Envelope command;
  command.mutable_command()->set_kind(v1::Command::KIND_KEYFRAME_REQUEST);
  a.Send(command);
  b.Send(command);
  ASSERT_TRUE(Eventually([&] {
    for (const v1::Envelope& e : a.Frames()) {
      if (e.has_session_event() && e.session_event().kind() == v1::SessionEvent::KIND_ERROR &&
          e.session_event().message().find("only an admin") != std::string::npos)
        return true;
    }
    return false;
  }));
  // An annotation from the instructor reaches every viewer, stamped with its author and time.
  v1::Envelope note;
  note.mutable_annotation()->set_text("too much force here");
  b.Send(note);
  v1::Annotation noted;
  auto annotation_in = [](TestViewer& v, v1::Annotation* out) {
    for (const v1::Envelope& e : v.Frames()) {
      if (e.has_annotation()) return *out = e.annotation(), true;
    }
    return false;
  };
  ASSERT_TRUE(Eventually([&] {
    v1::Annotation ignored;
    return annotation_in(late, &ignored) && annotation_in(b, &ignored) && annotation_in(a, &noted);
  }));
  EXPECT_EQ(noted.text(), "too much force here");
  EXPECT_EQ(noted.id(), 1u);
  EXPECT_NE(noted.author().find("admin"), std::string::npos);
  EXPECT_GT(noted.time_s(), 1.0);
  // The agent ends: every viewer is closed, and its mirror equals the agent's final surface.
  ASSERT_EQ(agent.Wait(seconds(60)), 0) << agent.Log();
  for (TestViewer* v : {&a, &b, &late}) {
    ASSERT_TRUE(v->WaitClosed(seconds(20)));
    EXPECT_EQ(v->gaps(), 0);
    const std::vector<double> truth = ReadNumbersAfterFirstLine(dir + "/final.txt");
    EXPECT_LE(MaxMirrorError(*v, truth), v->quant_step()) << "max |mirror - agent| over the surface";
  }
  const json summary = json::parse(ReadText(dir + "/summary.json"));
  EXPECT_GE(summary["commands"].get<int>(), 1);
  // The session is listed as ended, with its figures, and its recording reads back whole.
  const json s = Sessions(port, observer)[0];
  EXPECT_EQ(s["state"], "ended");
  EXPECT_EQ(s["samples"], 4000);
  EXPECT_GT(s["summary"]["peak_force"].get<double>(), 1.0);
  EXPECT_GT(s["summary"]["contact_time_s"].get<double>(), 0.1);
  const HttpReply rec = Get(port, "/api/sessions/" + id + "/recording.mcap", observer);
  ASSERT_EQ(rec.status, 200);
  std::ofstream(dir + "/rec.mcap", std::ios::binary) << rec.body;
  std::vector<uint64_t> ticks = RecordedTicks(dir + "/rec.mcap");
  ASSERT_EQ(ticks.size(), 4000u);
  for (size_t i = 0; i < ticks.size(); ++i) ASSERT_EQ(ticks[i], i);
  IndependentReaderAccepts(dir + "/rec.mcap", 4000);
  // Ranges: the file resumes.
  const HttpReply part = Http(port, HttpCall{"GET",
                                             "/api/sessions/" + id + "/recording.mcap",
                                             {{"Authorization", "Bearer " + observer}, {"Range", "bytes=100-199"}},
                                             ""});
  EXPECT_EQ(part.status, 206);
  EXPECT_EQ(part.body, rec.body.substr(100, 100));
  const json detail = json::parse(Get(port, "/api/sessions/" + id, observer).body);
  bool saw_joined = false, saw_command = false;
  for (const json& e : detail["events"]) {
    saw_joined |= e["kind"] == "KIND_VIEWER_JOINED";
    // The admin's keyframe request, relayed and recorded with who sent it.
    saw_command |= e["kind"] == "KIND_COMMAND" &&
                   e["message"].get<std::string>().find("KIND_KEYFRAME_REQUEST") != std::string::npos;
  }
  EXPECT_TRUE(saw_joined);
  EXPECT_TRUE(saw_command) << detail["events"].dump();
  ASSERT_EQ(detail["annotations"].size(), 1u);
  EXPECT_EQ(detail["annotations"][0]["text"], "too much force here");
  EXPECT_NEAR(detail["annotations"][0]["time_s"].get<double>(), noted.time_s(), 1e-9);
  // A viewer of a session that is not live: 404.
  EXPECT_EQ(WsConnect(port, "/ws/session/" + id, {{"Authorization", "Bearer " + observer}}).status, 404);
  // Only an admin deletes a recording.
  EXPECT_EQ(Http(port, HttpCall{"DELETE", "/api/sessions/" + id, {{"Authorization", "Bearer " + observer}}, ""}).status,
            403);
  EXPECT_EQ(Http(port, HttpCall{"DELETE", "/api/sessions/" + id, {{"Authorization", "Bearer " + admin}}, ""}).status,
            200);
  EXPECT_EQ(Get(port, "/api/sessions/" + id + "/recording.mcap", observer).status, 404);
}

// A viewer that stops reading loses mesh deltas (never the others' frames), is put right with a
// keyframe when it reads again, and is closed when it stays stalled; the agent, the recording and
// the other viewers go on untouched.
TEST(Sessions, AStalledViewerIsResynchronisedOrClosedAndSlowsNobody) {
  const std::string dir = TempDir("sessions-stalled");
  ServerProcess server(dir + "/data", {"--viewer-stall-timeout", "2", "--ws-send-buffer-kb", "8"});
  ASSERT_TRUE(server.ready()) << server.Log();
  const uint16_t port = server.port();
  const std::string observer = server.Token("observer");
  std::vector<std::string> args = AgentArgs(server, dir, 14);
  args.erase(std::find(args.begin(), args.end(), "--no-realtime"));  // 14 s of wall time
  args[std::find(args.begin(), args.end(), "--device") - args.begin() + 1] = "scripted:stroke-slow";
  ChildProcess agent(IDMS_AGENT_BIN, args, dir + "/agent.log");
  const std::string id = WaitForLiveSession(port, observer);
  ASSERT_FALSE(id.empty()) << server.Log();
  const auto metric = [&](const std::string& name) { return MetricValue(port, observer, name); };
  // 4 KB of receive window and 8 KiB of send buffer: once a viewer stops reading, the server's
  // queue for it fills in a second or two.
  TestViewerOptions small;
  small.receive_buffer_bytes = 4096;
  TestViewer steady(port, id, observer), slow(port, id, observer, small), stuck(port, id, observer, small);
  ASSERT_TRUE(Eventually([&] { return slow.Keyframes() >= 1 && stuck.Keyframes() >= 1; }));
  slow.Pause();
  ASSERT_TRUE(Eventually([&] { return metric("idms_viewer_deltas_skipped_total") > 0; }, seconds(20)));
  const double resyncs = metric("idms_viewer_resyncs_total");
  slow.Resume();
  ASSERT_TRUE(Eventually([&] { return metric("idms_viewer_resyncs_total") > resyncs; }, seconds(20)));
  // The other stops reading for good: closed after the stall timeout (2 s) and the close grace.
  stuck.Pause();
  ASSERT_TRUE(Eventually([&] { return metric("idms_viewer_stalled_closed_total") >= 1; }, seconds(30)));
  EXPECT_FALSE(slow.closed());
  stuck.Resume();
  ASSERT_TRUE(stuck.WaitClosed(seconds(20))) << "the server dropped the stalled viewer's connection";
  ASSERT_EQ(agent.Wait(seconds(60)), 0) << agent.Log();
  // The steady viewer lost nothing (a skipped delta would be a gap in its mirror), and the slow one,
  // resynchronised, ends on the agent's surface as well.
  const std::vector<double> truth = ReadNumbersAfterFirstLine(dir + "/final.txt");
  for (TestViewer* v : {&steady, &slow}) {
    ASSERT_TRUE(v->WaitClosed(seconds(20)));
    EXPECT_EQ(v->gaps(), 0);
    EXPECT_LE(MaxMirrorError(*v, truth), v->quant_step());
  }
  // Nothing upstream was slowed: every tick recorded, no overruns from the stall.
  const json summary = json::parse(ReadText(dir + "/summary.json"));
  EXPECT_EQ(summary["samples_dropped"], 0);
  const std::string rec = dir + "/rec.mcap";
  ASSERT_TRUE(Eventually([&] { return Sessions(port, observer)[0]["state"] == "ended"; }));
  ASSERT_TRUE(DownloadRecording(port, id, observer, rec));
  EXPECT_EQ(RecordedTicks(rec).size(), 14000u);
  EXPECT_GT(metric("idms_recording_bytes_total"), 0);
}

TEST(Sessions, TheRealAgentIsRefusedAWrongTokenAndAnObserversOne) {
  const std::string dir = TempDir("sessions-refused");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string url = "ws://127.0.0.1:" + server.port_string();
  for (const auto& [token, status] : std::vector<std::pair<std::string, std::string>>{
           {"wrong-token-xxxxxxxxxxx", "HTTP 401"}, {server.Token("observer"), "HTTP 403"}}) {
    ChildProcess agent(
        IDMS_AGENT_BIN,
        {"--server", url, "--token", token, "--model-file", std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home",
         "--device", "scripted:palpate", "--no-realtime", "--duration", "2"},
        dir + "/agent.log");
    EXPECT_EQ(agent.Wait(seconds(30)), 2) << agent.Log();
    EXPECT_NE(agent.Log().find("refused the token (" + status), std::string::npos) << agent.Log();
  }
  EXPECT_TRUE(Sessions(server.port(), server.Token("observer")).empty());
}

TEST(Sessions, GarbageFromAnAgentClosesItWithAReason) {
  const std::string dir = TempDir("sessions-garbage");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  asio::io_context io;
  websocket::stream<beast::tcp_stream> ws(io);
  beast::get_lowest_layer(ws).connect(asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), server.port()));
  beast::get_lowest_layer(ws).expires_after(seconds(30));
  const std::string agent = server.Token("agent");
  ws.set_option(websocket::stream_base::decorator(
      [&](websocket::request_type& req) { req.set("Authorization", "Bearer " + agent); }));
  ws.handshake("127.0.0.1", "/ws/agent");
  ws.binary(true);
  ws.write(asio::buffer(std::string("\xff\xff\xff garbage", 12)));
  beast::flat_buffer buffer;
  ws.read(buffer);
  v1::Envelope e;
  std::string error;
  const auto data = buffer.data();
  ASSERT_TRUE(ParseEnvelope(std::string_view(static_cast<const char*>(data.data()), data.size()), &e, &error));
  ASSERT_TRUE(e.has_session_event());
  EXPECT_EQ(e.session_event().kind(), v1::SessionEvent::KIND_ERROR);
  EXPECT_NE(e.session_event().message().find("malformed frame"), std::string::npos);
  beast::error_code ec;
  buffer.consume(buffer.size());
  ws.read(buffer, ec);
  EXPECT_EQ(ec, websocket::error::closed);
  EXPECT_EQ(ws.reason().code, websocket::close_code::policy_error);
  // Observers may not publish.
  EXPECT_EQ(WsConnect(server.port(), "/ws/agent", {{"Authorization", "Bearer " + server.Token("observer")}}).status,
            403);
  EXPECT_EQ(Get(server.port(), "/api/health", "").status, 200);
}

TEST(Sessions, ReplayPlaysSeeksAndChangesSpeed) {
  const std::string dir = TempDir("sessions-replay");
  ServerProcess server(dir + "/data");
  ASSERT_TRUE(server.ready()) << server.Log();
  const uint16_t port = server.port();
  const std::string observer = server.Token("observer");
  // 7 s with a keyframe every second: a seek's catch-up reaches further back than its keyframe.
  const std::string scene = dir + "/palpate.scene";
  std::ofstream(scene) << ReadText(std::string(IDMS_SOURCE_DIR) + "/models/palpate.scene")
                       << "keyframe_interval_s: 1\n";
  std::vector<std::string> args = AgentArgs(server, dir, 7);
  args.insert(args.end(), {"--scene", scene});
  ChildProcess agent(IDMS_AGENT_BIN, args, dir + "/agent.log");
  ASSERT_EQ(agent.Wait(seconds(60)), 0) << agent.Log();
  std::string id;
  ASSERT_TRUE(Eventually([&] {
    const json s = Sessions(port, observer);
    if (s.empty() || s[0]["state"] != "ended") return false;
    id = s[0]["id"];
    return true;
  }));
  // Welcome, then the state: paused at 0 of about 7 s.
  asio::io_context io;
  websocket::stream<beast::tcp_stream> ws(io);
  beast::get_lowest_layer(ws).connect(asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
  beast::get_lowest_layer(ws).expires_after(seconds(60));
  ws.set_option(websocket::stream_base::decorator(
      [&](websocket::request_type& req) { req.set("Authorization", "Bearer " + observer); }));
  ws.handshake("127.0.0.1", "/ws/replay/" + id);
  auto read = [&] {
    beast::flat_buffer buffer;
    ws.read(buffer);
    v1::Envelope e;
    std::string error;
    const auto data = buffer.data();
    EXPECT_TRUE(ParseEnvelope(std::string_view(static_cast<const char*>(data.data()), data.size()), &e, &error));
    return e;
  };
  auto send = [&](v1::PlaybackControl::Action action, double value) {
    v1::Envelope e;
    e.mutable_playback_control()->set_action(action);
    if (action == v1::PlaybackControl::ACTION_SEEK) e.mutable_playback_control()->set_seek_time_s(value);
    if (action == v1::PlaybackControl::ACTION_SET_SPEED) e.mutable_playback_control()->set_speed(value);
    std::string bytes;
    SerializeEnvelope(e, &bytes);
    ws.binary(true);
    ws.write(asio::buffer(bytes));
  };
  v1::Envelope e = read();
  ASSERT_TRUE(e.has_welcome());
  EXPECT_EQ(e.welcome().scene().model(), "hex_4x5_home");
  e = read();
  ASSERT_TRUE(e.has_playback_state());
  EXPECT_FALSE(e.playback_state().playing());
  // On the session's clock: 7 s of simulation is 7 s of replay, however late frames arrived.
  EXPECT_NEAR(e.playback_state().duration_s(), 7.0, 0.01);
  // Paused at 0, before the agent's first frame: its first keyframe comes at once (the viewer once
  // had an empty view until Play).
  e = read();
  ASSERT_TRUE(e.has_mesh_keyframe()) << e.DebugString().substr(0, 300);
  EXPECT_GT(e.mesh_keyframe().num_vertices(), 0u);
  // At 10x the whole recording plays in about a tenth of its length, every tick in order.
  send(v1::PlaybackControl::ACTION_SET_SPEED, 10);
  send(v1::PlaybackControl::ACTION_PLAY, 0);
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<uint64_t> ticks;
  MeshMirror mirror;
  std::string error;
  int gaps = 0;
  while (true) {
    e = read();
    if (e.has_device_samples()) {
      for (const auto& s : e.device_samples().samples()) ticks.push_back(s.tick());
    }
    if ((e.has_mesh_keyframe() || e.has_mesh_delta()) && mirror.Apply(e, &error) != MirrorStatus::kOk) ++gaps;
    if (e.has_playback_state() && !e.playback_state().playing() && !ticks.empty()) break;
  }
  const double played_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_EQ(ticks.size(), 7000u);
  for (size_t i = 0; i < ticks.size(); ++i) ASSERT_EQ(ticks[i], i);
  EXPECT_EQ(gaps, 0);
  EXPECT_GT(played_s, 0.5);
  EXPECT_LT(played_s, 3.5);
  // A seek to 6.5 s: first the state there (a viewer restarts its plots), then the catch-up: the
  // device samples of the viewer's 5 s plot window, from 1.5 s, though the latest keyframe is
  // within the last second; the surface at 6.5 s as one keyframe (the server applied the deltas
  // since the recorded keyframe); then the state again.
  send(v1::PlaybackControl::ACTION_SEEK, 6.5);
  do {
    e = read();
    ASSERT_FALSE(e.has_device_samples() || e.has_mesh_keyframe() || e.has_mesh_delta()) << EnvelopeBodyName(e);
  } while (!e.has_playback_state() || std::abs(e.playback_state().time_s() - 6.5) > 0.01);
  std::vector<uint64_t> caught;
  MeshMirror seeked;
  double keyframe_s = -1;
  int mesh_frames = 0;
  int device_messages = 0;
  for (e = read(); !e.has_playback_state(); e = read()) {
    if (e.has_device_samples()) {
      for (const auto& s : e.device_samples().samples()) caught.push_back(s.tick());
      ++device_messages;
    }
    if (e.has_mesh_keyframe() || e.has_mesh_delta()) {
      ++mesh_frames;
      EXPECT_TRUE(e.has_mesh_keyframe()) << EnvelopeBodyName(e);
      EXPECT_EQ(seeked.Apply(e, &error), MirrorStatus::kOk) << error;
      keyframe_s = seeked.time_s();
    }
  }
  EXPECT_NEAR(e.playback_state().time_s(), 6.5, 0.01);
  EXPECT_EQ(mesh_frames, 1);
  // The 250 recorded batches of 20 samples go as a few messages of up to 1,000.
  EXPECT_LE(device_messages, 6);
  // The last mesh frame before 6.5 s (at 60 Hz), not the recorded keyframe (at about 6 s).
  EXPECT_GT(keyframe_s, 6.4);
  EXPECT_LE(keyframe_s, 6.5);
  ASSERT_FALSE(caught.empty());
  EXPECT_GE(caught.front(), 1480u);
  EXPECT_LE(caught.front(), 1540u);
  EXPECT_GE(caught.back(), 6460u);
  EXPECT_LT(caught.back(), 6500u);
  for (size_t i = 1; i < caught.size(); ++i) ASSERT_EQ(caught[i], caught[i - 1] + 1);
  // Played on from there, the recorded deltas apply on top of that keyframe.
  send(v1::PlaybackControl::ACTION_PLAY, 0);
  do e = read();
  while (!e.has_mesh_delta() && !e.has_mesh_keyframe());
  EXPECT_EQ(seeked.Apply(e, &error), MirrorStatus::kOk) << EnvelopeBodyName(e) << ": " << error;
  EXPECT_GT(seeked.time_s(), keyframe_s);
  send(v1::PlaybackControl::ACTION_PAUSE, 0);
  // Speed outside 0.1..10: an error event, and the replay carries on. (At 10x the half second
  // left plays in 50 ms: on a slow run the Pause comes after the end, and the recorded events
  // there, the agent's Ended, are played before the error; the read times out if none comes.)
  send(v1::PlaybackControl::ACTION_SET_SPEED, 20);
  do e = read();
  while (!e.has_session_event() || e.session_event().kind() != v1::SessionEvent::KIND_ERROR);
  EXPECT_NE(e.session_event().message().find("speed"), std::string::npos) << e.session_event().message();
  // A live or unknown session cannot be replayed.
  EXPECT_EQ(WsConnect(port, "/ws/replay/nope", {{"Authorization", "Bearer " + observer}}).status, 404);
}

TEST(Sessions, AnAgentThatDiesAndDoesNotComeBackLeavesAWholeRecording) {
  const std::string dir = TempDir("sessions-agent-dies");
  ServerProcess server(dir + "/data", {"--resume-window", "1"});
  ASSERT_TRUE(server.ready()) << server.Log();
  const uint16_t port = server.port();
  const std::string observer = server.Token("observer");
  ChildProcess agent(IDMS_AGENT_BIN, AgentArgs(server, dir, 10), dir + "/agent.log");
  std::string id;
  int64_t samples = 0;
  ASSERT_TRUE(Eventually([&] {
    const json s = Sessions(port, observer);
    if (s.empty() || s[0]["samples"].get<int>() < 1000) return false;
    id = s[0]["id"];
    return true;
  }));
  agent.Signal(SIGKILL);
  ASSERT_TRUE(agent.Wait(seconds(30)));
  // Past the resume window: closed as interrupted, its recording finished and whole.
  ASSERT_TRUE(Eventually([&] {
    const json s = Sessions(port, observer);
    samples = s[0]["samples"];
    return s[0]["state"] == "interrupted";
  })) << server.Log();
  const HttpReply rec = Get(port, "/api/sessions/" + id + "/recording.mcap", observer);
  ASSERT_EQ(rec.status, 200);
  std::ofstream(dir + "/rec.mcap", std::ios::binary) << rec.body;
  const std::vector<uint64_t> ticks = RecordedTicks(dir + "/rec.mcap");
  EXPECT_EQ(static_cast<int64_t>(ticks.size()), samples);
  for (size_t i = 0; i < ticks.size(); ++i) ASSERT_EQ(ticks[i], i);
  IndependentReaderAccepts(dir + "/rec.mcap", ticks.size());
}

// The server dies under a live session (SIGKILL, then SIGTERM); the agent reconnects to the
// restarted server, resumes the same session, and the recording holds every tick once, in order.
void ResumeAcrossRestart(int signal) {
  const std::string dir = TempDir(signal == SIGKILL ? "resume-kill" : "resume-term");
  auto server = std::make_unique<ServerProcess>(dir + "/data");
  ASSERT_TRUE(server->ready()) << server->Log();
  const std::string port = server->port_string(), observer = server->Token("observer");
  std::vector<std::string> args = AgentArgs(*server, dir, 5);
  ChildProcess agent(IDMS_AGENT_BIN, args, dir + "/agent.log");
  std::string id;
  ASSERT_TRUE(Eventually([&] {
    const json s = Sessions(server->port(), observer);
    if (s.empty() || s[0]["samples"].get<int>() < 1500) return false;
    id = s[0]["id"];
    return true;
  })) << server->Log();
  server->process().Signal(signal);
  ASSERT_TRUE(server->process().Wait(seconds(30)));
  const std::string first_log = server->Log();
  // The same address again (the agent knows no other).
  server = std::make_unique<ServerProcess>(dir + "/data", std::vector<std::string>{"--listen", "127.0.0.1:" + port});
  ASSERT_TRUE(server->ready()) << server->Log();
  ASSERT_EQ(agent.Wait(seconds(90)), 0) << agent.Log();
  const json summary = json::parse(ReadText(dir + "/summary.json"));
  EXPECT_GE(summary["reconnects"].get<int>(), 1);
  EXPECT_EQ(summary["session_id"], id);
  EXPECT_EQ(summary["samples_dropped"], 0);
  ASSERT_TRUE(Eventually([&] { return Sessions(server->port(), observer)[0]["state"] == "ended"; })) << server->Log();
  const HttpReply rec = Get(server->port(), "/api/sessions/" + id + "/recording.mcap", observer);
  ASSERT_EQ(rec.status, 200);
  std::ofstream(dir + "/rec.mcap", std::ios::binary) << rec.body;
  const std::vector<uint64_t> ticks = RecordedTicks(dir + "/rec.mcap");
  ASSERT_EQ(ticks.size(), 5000u) << first_log << server->Log();
  for (size_t i = 0; i < ticks.size(); ++i) ASSERT_EQ(ticks[i], i);
  IndependentReaderAccepts(dir + "/rec.mcap", 5000);
}

TEST(Sessions, AgentResumesAfterTheServerIsKilledAndEveryTickIsRecordedOnce) { ResumeAcrossRestart(SIGKILL); }
TEST(Sessions, AgentResumesAfterTheServerStopsAndEveryTickIsRecordedOnce) { ResumeAcrossRestart(SIGTERM); }

}  // namespace
}  // namespace idms::test
