// Live sessions: an agent publishes (/ws/agent), viewers watch (/ws/session/{id}), everything is
// recorded. A LiveSession lives on its own strand: frames from the agent, viewers joining and
// leaving, commands and the once-a-second tick are all serialised there. Recording writes run on
// the recorder thread; the index (SQLite) keeps what a list or a resume after a restart needs.
#pragma once

#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "idms/protocol/mesh_mirror.h"
#include "idms/protocol/recording.h"
#include "idms/server/storage.h"
#include "server_internal.h"
#include "ws_endpoint.h"

namespace idms::server {

class ViewerEndpoint;
class Recorder;

// /ws/replay/{id} (replay.cc): null with *refusal for an unknown or live session.
std::shared_ptr<WsEndpoint> MakeReplayEndpoint(ServerCore& core, const std::string& id, std::string* refusal);

// The session's figures, updated as samples arrive (on the session's strand).
struct SessionSummary {
  double peak_force = 0;            // |force| maximum, force units
  double force_sum_in_contact = 0;  // for the mean contact force
  int64_t contact_samples = 0;
  double contact_time_s = 0;
  double path_length = 0;  // of the tool centre, model units
  int64_t warnings = 0;
  uint64_t overruns = 0;
  uint32_t tick_p99_us = 0;      // compute time p99 (the agent's LoopStats)
  uint64_t samples_dropped = 0;  // lost to the agent's backlog while disconnected
  bool have_last = false;
  double last_pos[3] = {0, 0, 0};
  double first_time_s = -1, last_time_s = 0;  // simulation time of the first and last sample
  void Add(const v1::DeviceSamples& batch);
  std::string Json() const;
};

class LiveSession : public std::enable_shared_from_this<LiveSession> {
 public:
  LiveSession(ServerCore& core, SessionRow row, v1::Scene scene, std::shared_ptr<Recorder> recorder);
  ~LiveSession();
  const std::string& id() const { return id_; }
  boost::asio::strand<boost::asio::io_context::executor_type>& strand() { return strand_; }

  void Start();  // the once-a-second timer (after construction: it needs shared_from_this)

  // On the strand (post there):
  void AgentAttached(std::shared_ptr<WsPeer> agent, bool resumed);
  void AgentFrame(std::shared_ptr<const v1::Envelope> envelope, std::shared_ptr<const std::string> bytes);
  void AgentDetached(bool ended_cleanly);
  void ViewerAttached(std::shared_ptr<ViewerEndpoint> viewer);
  void ViewerDetached(ViewerEndpoint* viewer);
  void ViewerCommand(const v1::Command& command, const std::string& peer);
  void ViewerAnnotation(const v1::Annotation& note, const std::string& peer);
  void KeyframeFor(std::shared_ptr<ViewerEndpoint> viewer);
  void Stop(const std::string& why);  // server shutdown: tell everyone, finish the recording

  // Any thread.
  SessionRow Snapshot() const;
  int viewers() const { return num_viewers_.load(); }
  bool live() const { return live_.load(); }
  const v1::Scene& scene() const { return scene_; }

 private:
  void Refuse(const std::string& what);
  void Broadcast(std::shared_ptr<const std::string> bytes, bool is_delta, bool is_samples);
  void Record(std::shared_ptr<const v1::Envelope> envelope);
  void RecordEvent(v1::SessionEvent::Kind kind, const std::string& message, const std::string& peer);
  void Tick();                                     // once a second: flush the recording, store the row
  void FinishRecording(const std::string& state);  // no longer live: "ended" or "interrupted"
  void Persist();

  ServerCore& core_;
  std::string id_;
  v1::Scene scene_;
  boost::asio::strand<boost::asio::io_context::executor_type> strand_;
  boost::asio::steady_timer timer_;
  std::shared_ptr<Recorder> recorder_;
  MeshMirror mirror_;
  std::shared_ptr<WsPeer> agent_;
  std::chrono::steady_clock::time_point agent_gone_since_ = std::chrono::steady_clock::now();
  std::vector<std::shared_ptr<ViewerEndpoint>> viewers_;
  SessionSummary summary_;
  uint64_t next_tick_ = 0;
  uint64_t annotations_ = 0;
  mutable std::mutex row_mu_;  // row_ is read by the REST handlers
  SessionRow row_;
  std::atomic<int> num_viewers_{0};
  std::atomic<bool> live_{true};
};

// Every live session, and the way in for agents and viewers. Thread-safe.
class SessionHub {
 public:
  SessionHub(ServerCore& core, SessionIndex* index, std::string recordings_dir);

  // At start-up: sessions the index says were live when the server stopped are repaired
  // (their recording finished and indexed) and marked interrupted.
  void RecoverInterrupted();
  // An agent's Hello: a new session, or a resume with the right token. Returns the session and
  // fills the Welcome; null with *error (said to the agent) otherwise.
  std::shared_ptr<LiveSession> OpenForAgent(const v1::Hello& hello, const std::string& peer, v1::Welcome* welcome,
                                            std::string* error);
  std::shared_ptr<LiveSession> FindLive(const std::string& id);
  void Forget(const std::string& id);  // the session ended
  std::vector<SessionRow> List();      // live first (their current figures), then the index
  std::optional<SessionRow> Get(const std::string& id);
  std::string RecordingPath(const SessionRow& row) const { return recordings_dir_ + "/" + row.recording; }
  bool Delete(const std::string& id, std::string* error);  // not while live
  void StopAll();
  SessionIndex& index() { return *index_; }
  ServerCore& core() { return core_; }

  // Fan-out counters over all viewers (for /metrics and the bench).
  std::atomic<uint64_t> viewer_frames{0}, viewer_bytes{0}, deltas_skipped{0}, samples_dropped{0}, resyncs{0},
      stalled_closed{0}, recording_bytes{0}, recording_failures{0};
  int live_count();
  // Prometheus lines: live sessions, viewers, and per live session its samples, tick p99 and overruns.
  std::string MetricsText();

 private:
  // A live session and its recorder, under mu_; continue_finished: a resume after a restart.
  std::shared_ptr<LiveSession> StartSession(const SessionRow& row, const v1::Scene& scene, bool continue_finished);

  ServerCore& core_;
  SessionIndex* index_;
  std::string recordings_dir_;
  std::mutex mu_;
  std::map<std::string, std::shared_ptr<LiveSession>> live_;
};

}  // namespace idms::server
