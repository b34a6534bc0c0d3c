// Every live session, and the way in for agents and viewers: the SessionHub opens or resumes a
// session for an agent's Hello, finds live sessions for viewers, lists live and recorded ones,
// repairs what a crash left, and keeps the index (SQLite) off the network threads.
#pragma once

#include <boost/asio/strand.hpp>
#include <boost/asio/thread_pool.hpp>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "idms/protocol/idms.pb.h"
#include "idms/server/bus.h"
#include "idms/server/storage.h"
#include "live_session.h"
#include "recordings.h"
#include "relay.h"
#include "server_internal.h"

namespace idms::server {

// The bytes of one Envelope, shared by every connection it goes to.
std::shared_ptr<const std::string> Serialized(const v1::Envelope& e);
// A SessionEvent KIND_ERROR saying `message`.
v1::Envelope ErrorEvent(const std::string& message);

// /ws/replay/{id} (replay.cc): null with *refusal for an unknown or live session.
std::shared_ptr<WsEndpoint> MakeReplayEndpoint(ServerCore& core, const std::string& id, std::string* refusal);

// What the hub made of an agent's Hello.
struct AgentAdmission {
  std::shared_ptr<LiveSession> session;  // null: refused
  bool resumed = false;
  std::string resume_token;  // for the Welcome
  v1::SessionEvent refusal;  // when refused: KIND_ERROR, KIND_ENDED or KIND_RESUME_LATER, and why
};

class SessionHub {
 public:
  // `index` and `recordings` outlive the hub.
  SessionHub(ServerCore& core, SessionIndex* index, RecordingStore* recordings);

  // At start-up: sessions the index says were live when the server stopped are repaired
  // (their recording finished and indexed) and marked interrupted.
  void RecoverInterrupted();
  // An agent's Hello: a new session, or a resume with the right token of a session live here or
  // interrupted. Any thread. The session itself sends the Welcome (LiveSession::AgentAttached).
  AgentAdmission OpenForAgent(const v1::Hello& hello, const std::string& peer);
  std::shared_ptr<LiveSession> FindLive(const std::string& id);
  // For a viewer: the live session here, else (with a bus) this server's relay of the session
  // another server owns (made for the first viewer; it closes its viewers when no owner answers).
  std::shared_ptr<WatchedSession> FindForViewer(const std::string& id);
  // The bus to the other servers (null: alone). Set before the first session; outlives the hub.
  void SetBus(Bus* bus) { bus_ = bus; }
  Bus* bus() const { return bus_; }
  RelayCounters& relay_counters() { return relay_; }
  // The session's recording is finished and its row stored: it is no longer live here.
  void Forget(const std::string& id, const LiveSession* session);
  std::vector<SessionRow> List();  // live first (their current figures), then the index
  std::optional<SessionRow> Get(const std::string& id);
  // The file to read a session's recording from; a finished one is fetched from the object store
  // first when it is not in the cache. May throw StoreUnavailable: a worker's call.
  std::string RecordingPath(const SessionRow& row) const;
  bool Delete(const std::string& id, std::string* error);  // not while live
  // An admin's correction of who was at the device. False with *error for an unknown session.
  bool SetTrainee(const std::string& id, const std::string& trainee, std::string* error);
  // A note at session time `time_s` (0 on a live session: now) by `author`: a live session records
  // and broadcasts it; an ended one keeps it in the index beside its recording (at most
  // kMaxAddedNotes). The stamped note, or nullopt with *error and *not_found for an unknown
  // session. Waits for a live session's strand: call it from a worker, never a network thread.
  std::optional<SessionNote> AddNote(const std::string& id, double time_s, const std::string& text,
                                     const std::string& author, std::string* error, bool* not_found);
  static constexpr size_t kMaxAddedNotes = 1000;
  void StopAll();
  // Stores a row on the index's strand (a worker, never a network thread); `then` runs there after.
  void StoreRow(SessionRow row, std::function<void()> then = nullptr);
  SessionIndex& index() { return *index_; }
  RecordingStore& recordings() { return *recordings_; }
  ServerCore& core() { return core_; }

  // Fan-out counters over all viewers (for /metrics and the bench).
  std::atomic<uint64_t> viewer_frames{0}, viewer_bytes{0}, deltas_skipped{0}, samples_dropped{0}, resyncs{0},
      stalled_closed{0}, recording_bytes{0}, recording_failures{0}, events_dropped{0};
  // Session ownership: leases this node took (new sessions, resumes, takeovers), sessions taken
  // over from another node, and sessions this node gave up on finding its lease lost (fenced).
  std::atomic<uint64_t> leases_taken{0}, takeovers{0}, leases_lost{0};
  int live_count();
  // Prometheus lines: live sessions, viewers, and per live session its samples, tick p99 and overruns.
  std::string MetricsText();
  std::string RelayMetrics();

 private:
  // OpenForAgent's work; may throw StoreUnavailable (OpenForAgent refuses with "retry").
  AgentAdmission Admit(const v1::Hello& hello, const std::string& peer);
  // The session's lease for this node (LeaseStore::Acquire): nullopt while another node holds it.
  // May throw StoreUnavailable.
  std::optional<LeaseGrant> TakeLease(const std::string& id);
  // A live session and its recorder, under mu_; `from`: what its recording starts with.
  std::shared_ptr<LiveSession> StartSession(const SessionRow& row, const v1::Scene& scene, RecordingStart from,
                                            LeaseGrant lease);
  // A session live on another server whose lease has lapsed (its owner died or stalled): its
  // durable recording recovered into this server's live file and the row's figures taken from it,
  // so that the agent resends exactly the ticks after it.
  void TakeOver(SessionRow* row);
  // What a mesh frame of the scene's model can need (the library's counts), else the defaults.
  DecodeLimits LimitsFor(const v1::Scene& scene);

  ServerCore& core_;
  SessionIndex* index_;
  RecordingStore* recordings_;
  boost::asio::strand<boost::asio::thread_pool::executor_type> index_strand_;
  std::mutex mu_;
  std::map<std::string, std::shared_ptr<LiveSession>> live_;
  std::map<std::string, std::shared_ptr<RelayedSession>> relayed_;  // under mu_
  Bus* bus_ = nullptr;
  RelayCounters relay_;
  std::mutex ended_rows_mu_;  // an ended session's row is read, changed and stored under it
};

}  // namespace idms::server
