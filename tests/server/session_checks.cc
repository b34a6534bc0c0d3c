// Reading back what a real idms-server recorded, for the session integration tests.
#include "session_checks.h"

#include <gtest/gtest.h>

#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>
#include <cmath>
#include <fstream>
#include <future>
#include <limits>
#include <sstream>

#include "child_process.h"
#include "idms/protocol/envelope.h"
#include "idms/protocol/recording.h"
#include "server_process.h"

namespace idms::test {

nlohmann::json Sessions(uint16_t port, const std::string& token) {
  const HttpReply r = Get(port, "/api/sessions", token);
  return r.status == 200 ? nlohmann::json::parse(r.body)["sessions"] : nlohmann::json::array();
}

std::string WaitForLiveSession(uint16_t port, const std::string& token, int samples) {
  std::string id;
  Eventually([&] {
    const nlohmann::json s = Sessions(port, token);
    if (s.empty() || s[0]["state"] != "live" || s[0]["samples"].get<int>() < samples) return false;
    id = s[0]["id"];
    return true;
  });
  return id;
}

double MetricValue(uint16_t port, const std::string& token, const std::string& series) {
  const HttpReply r = Get(port, "/metrics", token);
  std::istringstream lines(r.body);
  for (std::string line; std::getline(lines, line);) {
    if (line.size() > series.size() && line.compare(0, series.size(), series) == 0 && line[series.size()] == ' ')
      return std::stod(line.substr(series.size() + 1));
  }
  return -1;
}

bool DownloadRecording(uint16_t port, const std::string& id, const std::string& token, const std::string& path) {
  const HttpReply r = Get(port, "/api/sessions/" + id + "/recording.mcap", token);
  EXPECT_EQ(r.status, 200) << r.body;
  if (r.status != 200) return false;
  std::ofstream(path, std::ios::binary) << r.body;
  // Ranges of the same file (streamed from it): first-last, a suffix; an invalid Range is ignored.
  const HttpReply part = Http(port, HttpCall{"GET",
                                             "/api/sessions/" + id + "/recording.mcap",
                                             {{"Authorization", "Bearer " + token}, {"Range", "bytes=8-107"}},
                                             ""});
  EXPECT_EQ(part.status, 206);
  EXPECT_EQ(part.body, r.body.substr(8, 100));
  EXPECT_EQ(part.headers.at("content-range"), "bytes 8-107/" + std::to_string(r.body.size()));
  const HttpReply tail = Http(port, HttpCall{"GET",
                                             "/api/sessions/" + id + "/recording.mcap",
                                             {{"Authorization", "Bearer " + token}, {"Range", "bytes=-16"}},
                                             ""});
  EXPECT_EQ(tail.status, 206);
  EXPECT_EQ(tail.body, r.body.substr(r.body.size() - 16));
  const HttpReply invalid = Http(port, HttpCall{"GET",
                                                "/api/sessions/" + id + "/recording.mcap",
                                                {{"Authorization", "Bearer " + token}, {"Range", "bytes=--5"}},
                                                ""});
  EXPECT_EQ(invalid.status, 200);
  EXPECT_EQ(invalid.body.size(), r.body.size());
  return true;
}

namespace {

// Every message of the selected topics, in log-time order.
template <class F>
void ForEachRecorded(const std::string& path, RecordingReaderOptions options, F&& f) {
  RecordingReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, options, &error)) << error;
  RecordedMessage m;
  while (reader.Next(&m, &error)) f(m.envelope);
  EXPECT_EQ(error, "");
}

}  // namespace

std::vector<v1::DeviceSample> RecordedSamples(const std::string& path) {
  RecordingReaderOptions options;
  options.mesh = options.events = options.annotations = false;
  std::vector<v1::DeviceSample> samples;
  ForEachRecorded(path, options, [&](const v1::Envelope& e) {
    for (const v1::DeviceSample& s : e.device_samples().samples()) samples.push_back(s);
  });
  return samples;
}

std::vector<uint64_t> RecordedTicks(const std::string& path) {
  std::vector<uint64_t> ticks;
  for (const v1::DeviceSample& s : RecordedSamples(path)) ticks.push_back(s.tick());
  return ticks;
}

std::vector<v1::SessionEvent> RecordedSessionEvents(const std::string& path) {
  RecordingReaderOptions options;
  options.mesh = options.device = options.annotations = false;
  std::vector<v1::SessionEvent> events;
  ForEachRecorded(path, options, [&](const v1::Envelope& e) {
    if (e.has_session_event()) events.push_back(e.session_event());
  });
  return events;
}

std::vector<v1::Envelope> RecordedMeshFrames(const std::string& path) {
  RecordingReaderOptions options;
  options.device = options.events = options.annotations = false;
  std::vector<v1::Envelope> frames;
  ForEachRecorded(path, options, [&](const v1::Envelope& e) {
    if (e.has_mesh_keyframe() || e.has_mesh_delta()) frames.push_back(e);
  });
  return frames;
}

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace websocket = beast::websocket;

TestViewer::TestViewer(uint16_t port, const std::string& session, const std::string& token, TestViewerOptions options) {
  ws_.set_option(websocket::stream_base::decorator(
      [token](websocket::request_type& req) { req.set("Authorization", "Bearer " + token); }));
  asio::ip::tcp::socket& socket = beast::get_lowest_layer(ws_).socket();
  socket.open(asio::ip::tcp::v4());
  // Before connect, so that the window the server sees is the small one.
  if (options.receive_buffer_bytes > 0) {
    socket.set_option(asio::socket_base::receive_buffer_size(options.receive_buffer_bytes));
  }
  socket.connect(asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
  ws_.handshake("127.0.0.1", "/ws/session/" + session);
  // Reads and writes are asynchronous on one thread: a WebSocket stream must never read on one
  // thread while it writes on another.
  work_.emplace(io_.get_executor());
  asio::post(io_, [this] { Read(); });
  thread_ = std::thread([this] { io_.run(); });
}

TestViewer::~TestViewer() {
  asio::post(io_, [this] {
    beast::error_code ec;
    beast::get_lowest_layer(ws_).socket().shutdown(asio::ip::tcp::socket::shutdown_both, ec);
    beast::get_lowest_layer(ws_).socket().close(ec);
    work_.reset();
  });
  thread_.join();
}

void TestViewer::Send(const v1::Envelope& e) {
  auto bytes = std::make_shared<std::string>();
  SerializeEnvelope(e, bytes.get());
  std::promise<void> written;
  asio::post(io_, [this, bytes, &written] {
    ws_.binary(true);
    ws_.async_write(asio::buffer(*bytes), [bytes, &written](beast::error_code, size_t) { written.set_value(); });
  });
  written.get_future().wait();
}

void TestViewer::Pause() {
  std::lock_guard lock(mu_);
  paused_ = true;
}

void TestViewer::Resume() {
  {
    std::lock_guard lock(mu_);
    paused_ = false;
  }
  asio::post(io_, [this] {
    if (!reading_) Read();
  });
}

bool TestViewer::WaitClosed(std::chrono::milliseconds timeout) {
  return Eventually([&] { return closed_.load(); }, timeout);
}

std::vector<v1::Envelope> TestViewer::Frames() {
  std::lock_guard lock(mu_);
  return frames_;
}

int TestViewer::Keyframes() {
  std::lock_guard lock(mu_);
  int n = 0;
  for (const v1::Envelope& e : frames_) n += e.has_mesh_keyframe() ? 1 : 0;
  return n;
}

std::vector<float> TestViewer::Positions() {
  std::lock_guard lock(mu_);
  auto p = mirror_.positions();
  return std::vector<float>(p.begin(), p.end());
}

double TestViewer::quant_step() {
  std::lock_guard lock(mu_);
  return mirror_.quant_step();
}

void TestViewer::Read() {
  {
    std::lock_guard lock(mu_);
    reading_ = !paused_;
  }
  if (!reading_) return;  // Resume starts again
  ws_.async_read(buffer_, [this](beast::error_code ec, size_t) {
    reading_ = false;
    if (ec) return void(closed_ = true);
    std::vector<v1::Envelope> frames;
    std::string error;
    const auto data = buffer_.data();
    ParseFrames(std::string_view(static_cast<const char*>(data.data()), data.size()), &frames, &error);
    {
      std::lock_guard lock(mu_);
      for (v1::Envelope& e : frames) {
        if (e.has_mesh_keyframe() || e.has_mesh_delta()) {
          if (mirror_.Apply(e, &error) != MirrorStatus::kOk) ++gaps_;
        }
        frames_.push_back(std::move(e));
      }
    }
    buffer_.consume(buffer_.size());
    Read();
  });
}

const v1::Envelope* FirstMeshFrame(const std::vector<v1::Envelope>& frames) {
  for (const v1::Envelope& e : frames) {
    if (e.has_mesh_keyframe() || e.has_mesh_delta()) return &e;
  }
  return nullptr;
}

double MaxMirrorError(TestViewer& viewer, const std::vector<double>& truth) {
  const std::vector<float> seen = viewer.Positions();
  if (seen.size() != truth.size()) return std::numeric_limits<double>::infinity();
  double worst = 0;
  for (size_t i = 0; i < truth.size(); ++i) worst = std::max(worst, std::abs(seen[i] - truth[i]));
  return worst;
}

void IndependentReaderAccepts(const std::string& path, size_t ticks) {
  std::vector<std::string> args = {std::string(IDMS_SOURCE_DIR) + "/tests/mcap-js/check_recording.mjs", path};
  if (ticks > 0) args.insert(args.end(), {"--expect-ticks", std::to_string(ticks)});
  ChildProcess node(IDMS_NODE_BIN, args, path + ".check.log");
  EXPECT_EQ(node.Wait(std::chrono::seconds(60)), 0) << node.Log();
}

}  // namespace idms::test
