// Soak (issue 27; STYLE: "a soak test, not a reading"): the real idms-server churned for
// IDMS_SOAK_SECONDS (180 by default) by viewers, replays, uploads, library watchers, keep-alive
// clients and agents that lose their connection and resume or are killed; afterwards its
// descriptors, gauges, threads and memory must come back to the baselines taken after a warm-up.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <array>
#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "idms/protocol/envelope.h"
#include "server_process.h"
#include "session_checks.h"
#include "test_clients.h"

namespace idms::test {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using json = nlohmann::json;
using std::chrono::milliseconds;
using std::chrono::seconds;
using Clock = std::chrono::steady_clock;
using Ws = websocket::stream<beast::tcp_stream>;

// ---- What is measured of the server process ----

struct Figures {
  int fds = -1;                                            // entries of /proc/PID/fd
  int sockets = -1;                                        // of which sockets
  int threads = -1;                                        // /proc/PID/status Threads
  int64_t rss_kib = -1;                                    // /proc/PID/status VmRSS
  double websockets = -1, connections = -1, viewers = -1;  // /metrics gauges
};

// What the descriptors are: "socket", "anon_inode:[eventfd]", or a file's path.
std::map<std::string, int> DescriptorKinds(int pid) {
  std::map<std::string, int> kinds;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/fd", ec)) {
    std::error_code link_ec;
    std::string target = std::filesystem::read_symlink(e.path(), link_ec).string();
    if (target.rfind("socket:", 0) == 0) target = "socket";
    if (target.rfind("pipe:", 0) == 0) target = "pipe";
    ++kinds[link_ec ? "?" : target];
  }
  return kinds;
}

Figures Measure(int pid, uint16_t port, const std::string& token) {
  Figures f;
  const std::map<std::string, int> kinds = DescriptorKinds(pid);
  f.fds = 0;
  for (const auto& [kind, n] : kinds) f.fds += n;
  f.sockets = kinds.count("socket") ? kinds.at("socket") : 0;
  f.threads = Threads(pid);
  f.rss_kib = RssKiB(pid);
  f.websockets = MetricValue(port, token, "idms_open_websockets");
  f.connections = MetricValue(port, token, "idms_open_connections");
  f.viewers = MetricValue(port, token, "idms_viewers");
  return f;
}

std::string Describe(const Figures& f) {
  std::ostringstream s;
  s << "fds " << f.fds << " (sockets " << f.sockets << "), threads " << f.threads << ", VmRSS " << f.rss_kib / 1024.0
    << " MiB, idms_open_websockets " << f.websockets << ", idms_open_connections " << f.connections << ", idms_viewers "
    << f.viewers;
  return s.str();
}

// ---- A relay the agent connects through, so the test can cut its connection ----

// A TCP relay between the agent and the server: Cut() resets every relayed connection (no close
// frame, no FIN) while both processes stay up, so the agent reconnects and resumes its session.
class Relay {
 public:
  explicit Relay(uint16_t target) : target_(target) {
    acceptor_.open(tcp::v4());
    acceptor_.bind(tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0));
    acceptor_.listen();
    Accept();
    thread_ = std::thread([this] { io_.run(); });
  }
  ~Relay() {
    io_.stop();
    thread_.join();
  }
  uint16_t port() const { return acceptor_.local_endpoint().port(); }
  void Cut() {
    asio::post(io_, [this] {
      for (const std::weak_ptr<Pipe>& w : pipes_) {
        if (auto p = w.lock()) p->Reset();
      }
      pipes_.clear();
    });
  }

 private:
  struct Pipe {
    explicit Pipe(tcp::socket s) : a(std::move(s)), b(a.get_executor()) {}
    void Reset() {
      beast::error_code ec;
      for (tcp::socket* s : {&a, &b}) {
        if (!s->is_open()) continue;
        s->set_option(asio::socket_base::linger(true, 0), ec);
        s->close(ec);
      }
    }
    tcp::socket a, b;
    std::array<char, 16384> ab{}, ba{};
  };

  void Accept() {
    acceptor_.async_accept([this](beast::error_code ec, tcp::socket s) {
      if (ec) return;
      auto p = std::make_shared<Pipe>(std::move(s));
      pipes_.push_back(p);
      p->b.async_connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), target_), [p](beast::error_code cec) {
        if (cec) return p->Reset();
        Pump(p, p->a, p->b, p->ab);
        Pump(p, p->b, p->a, p->ba);
      });
      Accept();
    });
  }
  // One direction: read what comes, write it on, until either side fails; then close both.
  static void Pump(std::shared_ptr<Pipe> p, tcp::socket& from, tcp::socket& to, std::array<char, 16384>& buf) {
    from.async_read_some(asio::buffer(buf), [p, &from, &to, &buf](beast::error_code ec, size_t n) {
      if (ec) return p->Reset();
      asio::async_write(to, asio::buffer(buf.data(), n), [p, &from, &to, &buf](beast::error_code wec, size_t) {
        if (wec) return p->Reset();
        Pump(p, from, to, buf);
      });
    });
  }

  asio::io_context io_;
  tcp::acceptor acceptor_{io_};
  uint16_t target_;
  std::vector<std::weak_ptr<Pipe>> pipes_;  // io_'s thread only
  std::thread thread_;
};

// ---- Clients ----

// How a client leaves: a close frame (or an orderly HTTP close), a FIN without a close frame, or a
// reset (SO_LINGER 0: the connection simply vanishes).
enum class Exit { kClean, kFin, kReset };
Exit ExitFor(int i) { return static_cast<Exit>(i % 3); }

void Drop(tcp::socket& s, Exit how) {
  beast::error_code ec;
  if (how == Exit::kReset) s.set_option(asio::socket_base::linger(true, 0), ec);
  if (how == Exit::kFin) s.shutdown(tcp::socket::shutdown_both, ec);
  s.close(ec);
}

void Quit(Ws& ws, Exit how) {
  beast::error_code ec;
  if (how == Exit::kClean) ws.close(websocket::close_code::normal, ec);
  Drop(beast::get_lowest_layer(ws).socket(), how);
}

// Connects and upgrades; false (with the reason in `error`) on any failure.
bool Open(Ws& ws, uint16_t port, const std::string& target, const std::string& token, std::string* error) {
  beast::error_code ec;
  beast::get_lowest_layer(ws).expires_after(seconds(30));
  beast::get_lowest_layer(ws).connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port), ec);
  if (!ec) {
    ws.set_option(websocket::stream_base::decorator(
        [token](websocket::request_type& req) { req.set("Authorization", "Bearer " + token); }));
    ws.handshake("127.0.0.1", target, ec);
  }
  if (ec) *error = target + ": " + ec.message();
  return !ec;
}

// One message of a live session's viewer: an envelope, or several in a Frames.
bool ReadFrames(Ws& ws, std::vector<v1::Envelope>* frames, std::string* error) {
  beast::flat_buffer buffer;
  beast::error_code ec;
  ws.read(buffer, ec);
  if (ec) return *error = "read: " + ec.message(), false;
  const auto data = buffer.data();
  return ParseFrames(std::string_view(static_cast<const char*>(data.data()), data.size()), frames, error);
}

// One message that carries one envelope (a replay's, a Welcome).
bool ReadEnvelope(Ws& ws, v1::Envelope* e, std::string* error) {
  std::vector<v1::Envelope> frames;
  if (!ReadFrames(ws, &frames, error)) return false;
  if (frames.size() != 1) return *error = std::to_string(frames.size()) + " envelopes in one message", false;
  *e = std::move(frames.front());
  return true;
}

void SendEnvelope(Ws& ws, const v1::Envelope& e) {
  std::string bytes;
  SerializeEnvelope(e, &bytes);
  ws.binary(true);
  beast::error_code ec;
  ws.write(asio::buffer(bytes), ec);
}

// Counts what the churn did and what went wrong (the first few errors kept for the message).
struct Tally {
  std::map<std::string, int> done;
  std::map<std::string, int> failed;
  std::vector<std::string> errors;
  void Fail(const std::string& what, const std::string& error) {
    ++failed[what];
    if (errors.size() < 10) errors.push_back(what + ": " + error);
  }
};

// A wave of live viewers: each gets its Welcome and a keyframe, then leaves one way or another.
void ViewerWave(uint16_t port, const std::string& session, const std::string& token, int round, Tally* tally) {
  asio::io_context io;
  std::vector<std::unique_ptr<Ws>> viewers;
  for (int i = 0; i < 6; ++i) {
    auto ws = std::make_unique<Ws>(io);
    std::string error;
    if (!Open(*ws, port, "/ws/session/" + session, token, &error)) {
      tally->Fail("viewer", error);
      continue;
    }
    v1::Envelope welcome, frame;
    if (!ReadEnvelope(*ws, &welcome, &error) || !welcome.has_welcome()) {
      tally->Fail("viewer", "no Welcome: " + error);
    } else {
      // The surface comes first among the mesh frames: at once from the server's mirror, or, for a
      // session whose agent has only just started (after a kill), as the agent's first keyframe.
      bool mesh = false;
      for (int n = 0; n < 400 && !mesh; ++n) {
        std::vector<v1::Envelope> frames;
        if (!ReadFrames(*ws, &frames, &error)) break;
        for (const v1::Envelope& f : frames) {
          if (!mesh && (f.has_mesh_keyframe() || f.has_mesh_delta())) frame = f, mesh = true;
        }
      }
      if (!mesh || !frame.has_mesh_keyframe())
        tally->Fail("viewer", "the first mesh frame is not a keyframe: " + error);
    }
    viewers.push_back(std::move(ws));
  }
  for (size_t i = 0; i < viewers.size(); ++i) {
    Quit(*viewers[i], ExitFor(round + static_cast<int>(i)));
    ++tally->done["viewer"];
  }
}

// A replay opened, sought, played at 10x for a few frames, and left.
void ReplayOnce(uint16_t port, const std::string& recording, const std::string& token, int round, Tally* tally) {
  asio::io_context io;
  Ws ws(io);
  std::string error;
  if (!Open(ws, port, "/ws/replay/" + recording, token, &error)) return tally->Fail("replay", error);
  v1::Envelope e;
  if (!ReadEnvelope(ws, &e, &error) || !e.has_welcome()) return tally->Fail("replay", "no Welcome: " + error);
  auto control = [&](v1::PlaybackControl::Action action, double value) {
    v1::Envelope c;
    c.mutable_playback_control()->set_action(action);
    if (action == v1::PlaybackControl::ACTION_SEEK) c.mutable_playback_control()->set_seek_time_s(value);
    if (action == v1::PlaybackControl::ACTION_SET_SPEED) c.mutable_playback_control()->set_speed(value);
    SendEnvelope(ws, c);
  };
  control(v1::PlaybackControl::ACTION_SEEK, 0.5 + (round % 5) * 0.5);
  control(v1::PlaybackControl::ACTION_SET_SPEED, 10);
  control(v1::PlaybackControl::ACTION_PLAY, 0);
  // The seek's state and catch-up, then playing frames.
  for (int i = 0; i < 20; ++i) {
    if (!ReadEnvelope(ws, &e, &error)) return tally->Fail("replay", "frame " + std::to_string(i) + ": " + error);
  }
  Quit(ws, ExitFor(round));
  ++tally->done["replay"];
}

// A library watcher sees a model uploaded and deleted (each on a keep-alive connection of its own).
void LibraryChurn(uint16_t port, const std::string& admin, const std::string& observer, const std::string& upload,
                  int round, Tally* tally) {
  asio::io_context io;
  Ws watcher(io);
  std::string error;
  if (!Open(watcher, port, "/ws/library", observer, &error)) return tally->Fail("library", error);
  beast::flat_buffer buffer;
  beast::error_code ec;
  watcher.read(buffer, ec);  // {"event": "hello"}
  beast::tcp_stream http_stream(io);
  http_stream.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port), ec);
  const std::string name = "soak_" + std::to_string(round);
  std::string reply;
  const int put = KeepAliveRequest(http_stream, http::verb::put, "/api/models/" + name, admin, upload, &reply);
  if (put != 201) return tally->Fail("upload", "PUT " + name + ": " + std::to_string(put) + " " + reply);
  ++tally->done["upload"];
  const int version = json::parse(reply).value("version", 0);
  for (const char* expected : {"model_added", "model_deleted"}) {
    if (std::string(expected) == "model_deleted") {
      const std::string target = "/api/models/" + name + "?version=" + std::to_string(version);
      const int del = KeepAliveRequest(http_stream, http::verb::delete_, target, admin);
      if (del != 200) return tally->Fail("delete", "DELETE " + target + ": " + std::to_string(del));
      ++tally->done["delete"];
    }
    buffer.consume(buffer.size());
    watcher.read(buffer, ec);
    const json event = json::parse(beast::buffers_to_string(buffer.data()), nullptr, false);
    if (ec || !event.is_object() || event.value("event", "") != expected)
      return tally->Fail("library", std::string("no ") + expected + " event");
  }
  Drop(http_stream.socket(), ExitFor(round + 1));
  Quit(watcher, ExitFor(round));
  ++tally->done["library watcher"];
}

// A keep-alive client: several requests on one connection, then gone.
void KeepAlive(uint16_t port, const std::string& token, const std::string& session, int round, Tally* tally) {
  asio::io_context io;
  beast::tcp_stream stream(io);
  beast::error_code ec;
  stream.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port), ec);
  for (const char* target : {"/api/health", "/api/models", "/api/sessions", "/metrics", "/api/models/hex_4x5_home"}) {
    const int status = KeepAliveRequest(stream, http::verb::get, target, token);
    if (status != 200) return tally->Fail("keep-alive", std::string(target) + ": " + std::to_string(status));
  }
  if (KeepAliveRequest(stream, http::verb::get, "/api/sessions/" + session, token) != 200)
    return tally->Fail("keep-alive", "GET /api/sessions/" + session);
  Drop(stream.socket(), ExitFor(round));
  ++tally->done["keep-alive client"];
}

// ---- The test ----

// Polls `condition` every half second until it holds or `timeout` passes (each poll asks /metrics,
// so not at Eventually's 50 Hz).
template <class F>
bool Settles(F condition, std::chrono::seconds timeout) {
  const auto deadline = Clock::now() + timeout;
  while (!condition()) {
    if (Clock::now() >= deadline) return false;
    std::this_thread::sleep_for(milliseconds(500));
  }
  return true;
}

std::vector<std::string> AgentArgs(const std::string& url, const std::string& token, const std::string& dir) {
  return {"--server",     url,        "--token",          token,        "--model", "hex_4x5_home", "--cache-dir",
          dir + "/cache", "--device", "scripted:palpate", "--duration", "0"};
}

int SoakSeconds() {
  const char* s = std::getenv("IDMS_SOAK_SECONDS");
  return s != nullptr && std::atoi(s) > 0 ? std::atoi(s) : 180;
}

TEST(Soak, DescriptorsGaugesThreadsAndMemoryReturnToTheirBaselinesAfterChurn) {
  const std::string dir = TempDir("soak");
  // A short resume window, so that the sessions of the agents killed during the churn are closed
  // (interrupted) within it rather than ten minutes later.
  ServerProcess server(dir + "/data", {"--resume-window", "3"});
  ASSERT_TRUE(server.ready()) << server.Log();
  const uint16_t port = server.port();
  const int pid = server.process().pid();
  const std::string observer = server.Token("observer"), admin = server.Token("admin"),
                    agent_token = server.Token("agent");
  const std::string source(IDMS_SOURCE_DIR);
  const std::string upload =
      JsonUpload(ReadText(source + "/models/hex_4x5_home.fem"), ReadText(source + "/models/hex_4x5_home.plg"), "soak");

  // A finished recording to replay: 3 s of palpation, as fast as the agent runs.
  {
    std::vector<std::string> args = AgentArgs("ws://127.0.0.1:" + server.port_string(), agent_token, dir);
    args.back() = "3";
    args.push_back("--no-realtime");
    ChildProcess recorder(IDMS_AGENT_BIN, args, dir + "/recorder.log");
    ASSERT_EQ(recorder.Wait(seconds(120)), 0) << recorder.Log();
  }
  std::string recording;
  ASSERT_TRUE(Eventually([&] {
    const json s = Sessions(port, observer);
    if (s.empty() || s[0]["state"] != "ended") return false;
    recording = s[0]["id"];
    return true;
  }));

  // The live agent, through the relay, in real time.
  Relay relay(port);
  const std::string relay_url = "ws://127.0.0.1:" + std::to_string(relay.port());
  int agents_started = 0;
  auto start_agent = [&] {
    ++agents_started;
    return std::make_unique<ChildProcess>(IDMS_AGENT_BIN, AgentArgs(relay_url, agent_token, dir),
                                          dir + "/agent" + std::to_string(agents_started) + ".log");
  };
  std::unique_ptr<ChildProcess> agent = start_agent();
  std::string session = WaitForLiveSession(port, observer, 200);
  ASSERT_FALSE(session.empty()) << server.Log() << agent->Log();
  auto samples = [&] {
    for (const json& s : Sessions(port, observer)) {
      if (s["id"] == session) return s["samples"].get<int64_t>();
    }
    return int64_t{-1};
  };

  // Warm-up: every kind of client once (thread pools, SQLite's statements, caches all started),
  // then the baselines.
  Tally tally;
  for (int round = 0; round < 3; ++round) {
    ViewerWave(port, session, observer, round, &tally);
    ReplayOnce(port, recording, observer, round, &tally);
    LibraryChurn(port, admin, observer, upload, round, &tally);
    KeepAlive(port, observer, session, round, &tally);
  }
  ASSERT_TRUE(tally.failed.empty()) << "warm-up: " << tally.errors[0] << "\n" << server.Log();
  // Idle, the server holds the agent's WebSocket and the HTTP connection asking for /metrics
  // (idms_open_connections counts both, HTTP and WebSocket; idms_open_websockets the agent's).
  // The warm-up's clients are gone: the baseline waits until the server has closed their side too.
  // If it never does, that is the leak this test is for; the churn still runs, so that the figures
  // show how it grows.
  Figures baseline;
  const bool idle = Settles(
      [&] {
        baseline = Measure(pid, port, observer);
        return baseline.websockets == 1 && baseline.viewers == 0 && baseline.connections == 2;
      },
      seconds(30));
  EXPECT_TRUE(idle) << "after the warm-up (18 viewers, 3 replays, 3 library watchers, all gone) the server still "
                       "holds their connections: "
                    << Describe(baseline) << "; expected idms_open_websockets 1 (the agent), idms_open_connections 2";
  const std::map<std::string, int> baseline_kinds = DescriptorKinds(pid);
  std::printf("soak: baseline after warm-up: %s\n", Describe(baseline).c_str());
  std::fflush(stdout);

  // The churn.
  const int soak_s = SoakSeconds();
  const auto end = Clock::now() + seconds(soak_s);
  int round = 3, cuts = 0, kills = 0;
  for (; Clock::now() < end; ++round) {
    ViewerWave(port, session, observer, round, &tally);
    ReplayOnce(port, recording, observer, round, &tally);
    LibraryChurn(port, admin, observer, upload, round, &tally);
    KeepAlive(port, observer, session, round, &tally);
    // Progress, so that even a run stuck on a server that stopped answering shows the trend.
    if (round % 20 == 0) {
      std::printf("soak: round %d: %s\n", round, Describe(Measure(pid, port, observer)).c_str());
      std::fflush(stdout);
    }
    if (round % 5 == 4) {
      // The agent's connection reset under it: it reconnects and resumes the same session.
      const int64_t before = samples();
      relay.Cut();
      ++cuts;
      if (!Eventually([&] { return samples() > before + 500; }, seconds(60)))
        tally.Fail("agent resume", "session " + session + " stopped at " + std::to_string(samples()) + " samples");
    }
    if (round % 8 == 7) {
      // The agent killed: its session waits for a resume that never comes and is closed as
      // interrupted; a new agent opens a new one, with two viewers waiting on the old one.
      asio::io_context io;
      Ws stay1(io), stay2(io);
      std::string error;
      const bool stayed = Open(stay1, port, "/ws/session/" + session, observer, &error) &&
                          Open(stay2, port, "/ws/session/" + session, observer, &error);
      agent->Signal(SIGKILL);
      agent->Wait(seconds(30));
      ++kills;
      agent = start_agent();
      const std::string old = session;
      // The newest session is listed first (started within the second of the old one or not).
      if (!Eventually([&] {
            const json s = Sessions(port, observer);
            if (s.empty() || s[0]["id"] == old || s[0]["state"] != "live") return false;
            session = s[0]["id"];
            return true;
          }))
        tally.Fail("agent restart", "no new live session\n" + agent->Log());
      if (stayed) {
        Quit(stay1, Exit::kFin);  // not a close frame: that waits for the server's answer, unbounded
        Quit(stay2, Exit::kReset);
      } else {
        tally.Fail("viewer", error);
      }
    }
  }
  std::printf("soak: %d s, %d rounds, %d agent connections reset, %d agents killed:", soak_s, round - 3, cuts, kills);
  for (const auto& [what, n] : tally.done) std::printf(" %d %s,", n, what.c_str());
  std::printf("\n");
  std::fflush(stdout);

  // Settle: the server closes what the clients left and the killed agents' sessions; the figures
  // are polled until they are back or the deadline passes.
  const Figures churned = Measure(pid, port, observer);
  std::printf("soak: right after the churn: %s\n", Describe(churned).c_str());
  // Descriptors: +4 for what a different live session may hold open where the first held it (its
  // .live.mcap recording) and SQLite's WAL, which checkpoints on its own schedule. A descriptor
  // leaked per connection, viewer or replay is hundreds after this churn, not a handful.
  const int kFdTolerance = 4;
  // Memory: +20 MiB for allocator fragmentation and glibc's per-thread arenas grown by the churn's
  // peak; the hundreds of viewers, replays and uploads would leave far more if their sessions,
  // queued frames (up to 256 each) or readers stayed.
  const int64_t kRssToleranceKib = 20 * 1024;
  Figures after;
  const bool settled = Settles(
      [&] {
        after = Measure(pid, port, observer);
        return after.fds <= baseline.fds + kFdTolerance && after.threads == baseline.threads &&
               after.websockets == baseline.websockets && after.connections == baseline.connections &&
               after.viewers == baseline.viewers && after.rss_kib <= baseline.rss_kib + kRssToleranceKib;
      },
      seconds(60));
  std::printf("soak: after settling:       %s\n", Describe(after).c_str());
  std::printf("soak: baseline:             %s\n", Describe(baseline).c_str());
  std::fflush(stdout);

  EXPECT_TRUE(tally.failed.empty()) << tally.failed.size() << " kinds of client failed; first errors:\n"
                                    << [&] {
                                         std::string s;
                                         for (const std::string& e : tally.errors) s += "  " + e + "\n";
                                         return s;
                                       }();
  EXPECT_TRUE(settled) << "the server did not return to its baseline within 60 s of the churn's end";
  EXPECT_LE(after.fds, baseline.fds + kFdTolerance) << "descriptors leaked";
  EXPECT_EQ(after.websockets, baseline.websockets) << "idms_open_websockets";
  EXPECT_EQ(after.connections, baseline.connections) << "idms_open_connections";
  EXPECT_EQ(after.viewers, baseline.viewers) << "idms_viewers";
  EXPECT_EQ(after.threads, baseline.threads) << "threads";
  EXPECT_LE(after.rss_kib, baseline.rss_kib + kRssToleranceKib) << "VmRSS, KiB";
  if (!settled) {
    // Which descriptors grew: sockets (connections kept), files (recordings, blobs), eventfds.
    std::string grown;
    for (const auto& [kind, n] : DescriptorKinds(pid)) {
      const int before = baseline_kinds.count(kind) ? baseline_kinds.at(kind) : 0;
      if (n > before) grown += "  " + kind + ": " + std::to_string(before) + " -> " + std::to_string(n) + "\n";
    }
    ADD_FAILURE() << "descriptors that grew:\n" << grown;
  }
  agent->Signal(SIGTERM);
  agent->Wait(seconds(30));
}

}  // namespace
}  // namespace idms::test
