// What the session integration tests read back from a real idms-server: the session list, a
// session's recording downloaded and read (by our reader and by the MCAP project's own).
#pragma once

#include <atomic>
#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/websocket/stream.hpp>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "idms/protocol/idms.pb.h"
#include "idms/protocol/mesh_mirror.h"

namespace idms::test {

// GET /api/sessions' "sessions" array (empty on any error).
nlohmann::json Sessions(uint16_t port, const std::string& token);

// The newest session's id once it is live with at least `samples` samples ("" after 20 s).
std::string WaitForLiveSession(uint16_t port, const std::string& token, int samples = 0);

// A series' value in /metrics (the whole line up to the value must match `series`), or -1.
double MetricValue(uint16_t port, const std::string& token, const std::string& series);

// GET /api/sessions/{id}/recording.mcap into `path`; false (with a test failure) unless 200.
bool DownloadRecording(uint16_t port, const std::string& id, const std::string& token, const std::string& path);

// Every device sample of a recording, in the order recorded; their ticks.
std::vector<v1::DeviceSample> RecordedSamples(const std::string& path);
std::vector<uint64_t> RecordedTicks(const std::string& path);

// Every SessionEvent on the recording's /events channel, in order.
std::vector<v1::SessionEvent> RecordedSessionEvents(const std::string& path);

// Every mesh frame (keyframe or delta envelope) of a recording, in order.
std::vector<v1::Envelope> RecordedMeshFrames(const std::string& path);

// The MCAP project's own reader (@mcap/core, from npm) and protobufjs agree: every record and CRC,
// every message decoded from the schemas stored in the file, and `ticks` device ticks once, in
// order (any count when `ticks` is 0).
void IndependentReaderAccepts(const std::string& path, size_t ticks);

// A live viewer on /ws/session/{id}, reading on its own thread: every frame kept, mesh frames
// applied to a mirror. It can stop reading (Pause) to play a viewer that cannot keep up; with a
// small receive buffer the server's queue for it fills within a second or two.
struct TestViewerOptions {
  int receive_buffer_bytes = 0;  // SO_RCVBUF before connecting; 0: the system's
};
class TestViewer {
 public:
  TestViewer(uint16_t port, const std::string& session, const std::string& token,
             TestViewerOptions options = TestViewerOptions());
  ~TestViewer();
  TestViewer(const TestViewer&) = delete;
  TestViewer& operator=(const TestViewer&) = delete;

  void Send(const v1::Envelope& e);
  void Pause();  // reads nothing more until Resume
  void Resume();
  bool WaitClosed(std::chrono::milliseconds timeout);
  bool closed() const { return closed_.load(); }

  std::vector<v1::Envelope> Frames();
  int Keyframes();
  std::vector<float> Positions();
  double quant_step();
  int gaps() const { return gaps_.load(); }  // mesh frames the mirror could not apply

 private:
  void Read();  // on io_'s thread: the next message, unless paused

  boost::asio::io_context io_;
  boost::beast::websocket::stream<boost::beast::tcp_stream> ws_{io_};
  std::thread thread_;
  std::mutex mu_;
  bool paused_ = false;   // under mu_
  bool reading_ = false;  // io_'s thread only: a read is outstanding
  boost::beast::flat_buffer buffer_;
  std::optional<boost::asio::executor_work_guard<boost::asio::io_context::executor_type>> work_;
  std::vector<v1::Envelope> frames_;
  MeshMirror mirror_;
  std::atomic<bool> closed_{false};
  std::atomic<int> gaps_{0};
};

// The first mesh frame (keyframe or delta) among a viewer's frames, or nullptr. A relayed
// viewer's keyframe may come with the samples sent just before it (one Frames message).
const v1::Envelope* FirstMeshFrame(const std::vector<v1::Envelope>& frames);

// max |mirror - truth| over a viewer's surface (truth: x y z per vertex); infinity when the sizes differ.
double MaxMirrorError(TestViewer& viewer, const std::vector<double>& truth);

}  // namespace idms::test
