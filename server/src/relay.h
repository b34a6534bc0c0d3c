// A live session owned by another server, relayed to this server's viewers over the bus
// (bus.h; idms.proto, "Between servers"). One RelayedSession per session with viewers here: it
// subscribes to the owner's stream while it has viewers, asks the owner for the session's state
// (RelayJoin: scene, surface, history) when it starts and whenever the stream has a gap or a new
// epoch (a new owner), keeps its own mirror of the surface for viewers who join later, and fans
// the owner's messages out to its viewers with the same back-pressure as the owner's (Audience).
#pragma once

#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <deque>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "audience.h"
#include "idms/protocol/mesh_mirror.h"
#include "idms/server/bus.h"

namespace idms::server {

// The relay's counters, for /metrics (per node).
struct RelayCounters {
  std::atomic<uint64_t> frames_published{0}, frames_relayed{0}, gaps{0}, epoch_changes{0}, joins{0}, lag_ns_sum{0},
      lag_count{0}, lag_ns_max{0};
};

// Subjects on the bus.
std::string LiveSubject(const std::string& session);    // RelayFrame, owner -> relays
std::string JoinSubject(const std::string& session);    // RelayJoinRequest -> owner
std::string ViewerSubject(const std::string& session);  // RelayViewerMessage -> owner

class RelayedSession : public WatchedSession, public std::enable_shared_from_this<RelayedSession> {
 public:
  // `on_empty`: its last viewer left or it closed (on its strand): the hub forgets it.
  RelayedSession(ServerCore& core, SessionHub& hub, Bus& bus, RelayCounters& counters, std::string id,
                 std::function<void(RelayedSession*)> on_empty);
  ~RelayedSession() override;
  bool Start(std::string* error);  // subscribes and asks for the state (after construction)

  Strand& strand() override { return strand_; }
  bool live() const override { return live_.load(); }
  void ViewerAttached(uint64_t viewer, std::weak_ptr<WsPeer> peer, bool admin,
                      std::shared_ptr<std::atomic<bool>> drain_wanted) override;
  void ViewerDetached(uint64_t viewer) override;
  void ViewerDrained(uint64_t viewer) override;
  void ViewerNote(const v1::Annotation& note, const std::string& peer) override;
  void ViewerCommand(const v1::Command& command, const std::string& peer) override;
  const std::string& id() const { return id_; }
  // On the strand: closes its viewers with `why`, unsubscribes, and the hub forgets it.
  void Close(const std::string& why);

 private:
  void OnFrame(v1::RelayFrame frame);
  void OnJoin(const v1::RelayJoin& join);
  void Deliver(v1::RelayFrame& frame);  // takes the frame's message
  void AskForState();
  void Tick();  // every 250 ms: asks again when the owner is silent; gives up after the resume window
  void Welcome(uint64_t viewer, bool admin);
  void Forward(const v1::Envelope& e, const std::string& peer, bool admin);

  ServerCore& core_;
  SessionHub& hub_;
  Bus& bus_;
  RelayCounters& counters_;
  const std::string id_;
  Strand strand_;
  boost::asio::steady_timer timer_;
  std::function<void(RelayedSession*)> on_empty_;
  std::atomic<bool> live_{true};
  Audience audience_;
  std::unique_ptr<Bus::Subscription> live_sub_, inbox_sub_;
  std::string inbox_;
  MeshMirror mirror_;
  bool synced_ = false;  // owner_ / sequence_ / the mirror follow the owner's stream
  bool ever_synced_ = false;
  // The owner followed: (lease epoch, incarnation), ordered; a smaller one is a fenced owner.
  using Owner = std::pair<uint64_t, uint64_t>;
  Owner owner_{0, 0};
  uint64_t sequence_ = 0;
  v1::Welcome welcome_;
  std::deque<v1::RelayFrame> waiting_;                 // frames that came before the state they follow (bounded)
  std::vector<std::pair<uint64_t, bool>> unwelcomed_;  // viewers (id, admin) who joined before the first state
  std::chrono::steady_clock::time_point last_heard_, asked_at_;
};

}  // namespace idms::server
