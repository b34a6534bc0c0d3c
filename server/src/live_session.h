// One live session: an agent publishes, viewers watch, everything is recorded. A LiveSession lives
// on its own strand: the agent's frames, viewers joining, leaving and draining, commands and the
// once-a-second tick are all serialised there, and every member below the public API belongs to
// that strand (asserted). Connections are held weakly (ws_endpoint.h): a session never keeps a
// closed connection alive, and a connection that is not the session's current agent is ignored.
#pragma once

#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <chrono>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "audience.h"
#include "idms/protocol/mesh_mirror.h"
#include "idms/server/bus.h"
#include "idms/server/storage.h"
#include "server_internal.h"
#include "session_summary.h"
#include "ws_endpoint.h"

namespace idms::server {

class Recorder;
class SessionHub;

// A session's lease as this server took it: its epoch, and until when it holds by this server's
// clock (counted from before it was asked for, so never later than the store's own deadline).
struct LeaseGrant {
  int64_t epoch = 0;
  std::chrono::steady_clock::time_point until;
};

class LiveSession : public WatchedSession, public std::enable_shared_from_this<LiveSession> {
 public:
  // `limits`: what the session's model can need of a mesh frame (the mirror refuses more).
  LiveSession(ServerCore& core, SessionHub& hub, SessionRow row, v1::Scene scene, std::shared_ptr<Recorder> recorder,
              const DecodeLimits& limits, LeaseGrant lease);
  ~LiveSession();
  const std::string& id() const { return id_; }
  Strand& strand() override { return strand_; }

  void Start();  // the once-a-second timer (after construction: it needs shared_from_this)

  // On the strand (post there). `conn` identifies the agent's connection (ServerCore ids): a
  // resume replaces the current one, and whatever a replaced connection still says is ignored.
  // The Welcome is sent from here, so its next_tick is exact: the first tick the new connection
  // must send.
  void AgentAttached(uint64_t conn, std::weak_ptr<WsPeer> agent, bool resumed, const std::string& resume_token);
  void AgentFrame(uint64_t conn, std::shared_ptr<const v1::Envelope> envelope,
                  std::shared_ptr<const std::string> bytes);
  void AgentDetached(uint64_t conn);
  void ViewerAttached(uint64_t viewer, std::weak_ptr<WsPeer> peer, bool admin,
                      std::shared_ptr<std::atomic<bool>> drain_wanted) override;
  void ViewerDetached(uint64_t viewer) override;
  void ViewerDrained(uint64_t viewer) override;
  void ViewerCommand(const v1::Command& command, const std::string& peer) override;
  void ViewerNote(const v1::Annotation& note, const std::string& peer) override { ViewerAnnotation(note, peer); }
  // A note from a viewer or the notes API, stamped (id, author, time) and recorded; the stamped
  // note, or nothing once the session is no longer live.
  std::optional<v1::Annotation> ViewerAnnotation(const v1::Annotation& note, const std::string& peer);
  void Stop(const std::string& why);  // server shutdown: tell everyone, finish the recording

  // Any thread.
  SessionRow Snapshot() const;
  void SetTrainee(const std::string& trainee);  // any thread; stored at once
  int viewers() const { return num_viewers_.load(); }
  // False once the session is ending (ENDED, the resume window, shutdown): no resume, no viewer.
  bool live() const override { return live_.load(); }
  const v1::Scene& scene() const { return scene_; }

 private:
  void AssertOnStrand() const;
  void Refuse(const std::string& what);
  // What a relayed frame is, for a viewer that is behind: deltas are skipped until a keyframe,
  // sample batches and everything else dropped (and counted).
  enum class FrameKind { kSamples, kDelta, kOther };
  // To every viewer: a sample batch waits (up to kGatherTime) for the next mesh frame or event,
  // which takes everything waiting with it in one Frames message (idms.proto); the others go at
  // once. The agent sends each mesh period's samples just before its surface, so in a live stream
  // the wait is microseconds; the timer is for samples without surfaces (and older agents).
  void Broadcast(const std::shared_ptr<const std::string>& bytes, FrameKind kind);
  void Flush();  // what is waiting, to every viewer (and to the bus), now
  void Record(std::shared_ptr<const v1::Envelope> envelope);
  void RecordEvent(v1::SessionEvent::Kind kind, const std::string& message, const std::string& peer);
  void SendToAgent(const v1::Envelope& e);
  void Tick();  // once a second: flush the recording, acknowledge it, store the row
  // No longer live: "ended" or "interrupted"; viewers are closed with `why`. Once the recording
  // is finished and its row stored, the hub forgets the session (and an ENDED agent gets its
  // final Ack).
  void End(const std::string& state, const std::string& why);
  void Persist(std::function<void()> then = nullptr);  // the row, on the index's strand

  // Ownership. The session is published, recorded and acknowledged only while this server's
  // lease holds by its own clock (Owns, on every frame: a clock read). The lease is renewed once
  // a second off the strand; past its deadline (a stall, a SIGSTOP, renewals refused) the session
  // lapses: the agent is sent away to resume, nothing is published, and the store decides: the
  // lease renewed or taken again (a new epoch), and the session goes on; another server holding
  // it, and this one gives the session up (GiveUp). A database that cannot be reached renews
  // nothing and takes nothing away: the owner keeps the session while it is down.
  bool Owns();
  void RenewLease();
  void CheckLease();  // lapsed: ask the store whether the session is still this server's
  void GiveUp();      // another server owns it: viewers and agent sent on, nothing stored
  LeaseGrant lease_;
  const uint64_t incarnation_ = UnixNs();  // when this server took the session (RelayFrame.incarnation)
  bool renewing_ = false, lapsed_ = false, unreachable_logged_ = false;

  ServerCore& core_;
  SessionHub& hub_;
  std::string id_;
  v1::Scene scene_;
  Strand strand_;
  boost::asio::steady_timer timer_;
  std::shared_ptr<Recorder> recorder_;
  MeshMirror mirror_;
  std::weak_ptr<WsPeer> agent_;
  uint64_t agent_conn_ = 0;  // 0: no agent
  std::chrono::steady_clock::time_point agent_gone_since_ = std::chrono::steady_clock::now();
  Audience audience_;
  // With a bus: what this server, the session's owner, publishes for the other servers' viewers
  // (relay.h), and the subscriptions that answer them.
  uint64_t relay_sequence_ = 0;
  std::unique_ptr<Bus::Subscription> join_sub_, viewer_sub_;
  void Publish(const std::shared_ptr<const std::string>& bytes, int deltas, const std::string& close_reason);
  void AnswerJoin(const std::string& reply);
  void FromRelayedViewer(const v1::RelayViewerMessage& m);
  // Frames gathered for the viewers (Broadcast) and the timer that sends them when no mesh frame
  // comes; pending_since_: when the oldest was gathered.
  std::vector<std::pair<std::shared_ptr<const std::string>, FrameKind>> pending_;
  std::chrono::steady_clock::time_point pending_since_;
  boost::asio::steady_timer gather_timer_;
  bool gather_armed_ = false;
  void ArmGatherTimer();
  SessionSummary summary_;
  uint64_t next_tick_ = 0;
  // Recordings are on the session's clock: log time = epoch + the frame's simulation time, so the
  // replay's timeline, seek times, annotations and ?t= links all speak session time, however late
  // frames arrived. The epoch is the session's start (second precision), stable across restarts.
  uint64_t epoch_ns_ = 0;
  mutable std::mutex row_mu_;  // row_ is read by the REST handlers
  SessionRow row_;
  std::atomic<int> num_viewers_{0};
  std::atomic<bool> live_{true};
};

}  // namespace idms::server
