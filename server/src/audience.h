// The viewers of one session on this server and what is sent to them, with the same back-pressure
// for all: a viewer more than kQueueLimit messages behind skips mesh deltas (until a keyframe puts
// it right once it drains) and loses sample batches and events (counted); one stalled past
// --viewer-stall-timeout is closed. Owned by the session that feeds it (a LiveSession for a
// session owned here, a RelayedSession for one relayed from its owner) and used on its strand.
#pragma once

#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/strand.hpp>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "idms/protocol/idms.pb.h"
#include "idms/protocol/mesh_mirror.h"
#include "ws_endpoint.h"

namespace idms::server {

class SessionHub;
struct ServerCore;

// A session as its viewers' endpoints see it: a LiveSession (owned here) or a RelayedSession
// (relayed from its owner over the bus). Every call but strand() and live() on its strand.
class WatchedSession {
 public:
  using Strand = boost::asio::strand<boost::asio::io_context::executor_type>;
  virtual ~WatchedSession() = default;
  virtual Strand& strand() = 0;
  virtual bool live() const = 0;
  // `drain_wanted`: shared with the viewer's endpoint, set here when the viewer starts skipping,
  // so that its connection reports the next drain (ViewerDrained) and no other.
  virtual void ViewerAttached(uint64_t viewer, std::weak_ptr<WsPeer> peer, bool admin,
                              std::shared_ptr<std::atomic<bool>> drain_wanted) = 0;
  virtual void ViewerDetached(uint64_t viewer) = 0;
  virtual void ViewerDrained(uint64_t viewer) = 0;  // its queue emptied: a keyframe if it was skipping
  virtual void ViewerNote(const v1::Annotation& note, const std::string& peer) = 0;
  virtual void ViewerCommand(const v1::Command& command, const std::string& peer) = 0;
};

class Audience {
 public:
  using Bytes = std::shared_ptr<const std::string>;
  // One message to every viewer: what it carries, and the same without its mesh deltas (for a
  // viewer that skips them), made on demand by without_deltas_maker (null: nothing but deltas).
  struct Outgoing {
    Bytes bytes;
    int deltas = 0, samples = 0, others = 0;
    std::function<Bytes()> without_deltas_maker;
    Bytes without_deltas;
    bool made = false;
  };

  Audience(ServerCore& core, SessionHub& hub) : core_(core), hub_(hub) {}

  void Add(uint64_t id, std::weak_ptr<WsPeer> peer, bool admin, std::shared_ptr<std::atomic<bool>> drain_wanted);
  bool Remove(uint64_t id);  // false when it was not here
  // To every viewer, with back-pressure.
  void Offer(Outgoing& out);
  // To one viewer (its Welcome, its keyframe, the history), or to every viewer, as they are.
  void SendTo(uint64_t id, const Bytes& bytes);
  void SendToAll(const Bytes& bytes);
  // A viewer's start: its Welcome, the surface now (a keyframe; null before the first) and the
  // events and notes so far (Remember), in that order.
  void Greet(uint64_t id, const Bytes& welcome, const Bytes& keyframe);
  // An event or note for viewers who join later: kept, bounded in count and bytes, oldest dropped.
  void Remember(const Bytes& bytes);
  void ForgetHistory();
  const std::deque<Bytes>& history() const { return history_; }
  // The viewer `id` drained its queue: a keyframe (from `keyframe`, null when there is none yet)
  // if it was skipping.
  void Drained(uint64_t id, const std::function<Bytes()>& keyframe);
  // Every viewer gets `keyframe` and stops skipping (a relayed stream had a gap).
  void Resync(const Bytes& keyframe);
  void CloseAll(uint16_t code, const std::string& why);
  size_t size() const { return viewers_.size(); }

  static constexpr size_t kQueueLimit = 256;                // messages queued for a viewer before it counts as behind
  static constexpr size_t kQueueBytes = size_t{8} << 20;    // bytes queued for a viewer, likewise
  static constexpr size_t kHistoryFrames = 512;             // events and notes kept for late viewers
  static constexpr size_t kHistoryBytes = size_t{1} << 20;  // likewise, in bytes

 private:
  struct Viewer {
    uint64_t id = 0;
    std::weak_ptr<WsPeer> peer;
    bool admin = false;
    bool closed = false;    // closed here (stalled); detaching
    bool skipping = false;  // behind: deltas skipped until a keyframe
    std::shared_ptr<std::atomic<bool>> drain_wanted;
    std::optional<std::chrono::steady_clock::time_point> behind_since;
  };
  void Send(Viewer& v, const Bytes& bytes);

  ServerCore& core_;
  SessionHub& hub_;
  std::vector<Viewer> viewers_;
  std::deque<Bytes> history_;
  size_t history_bytes_ = 0;
};

// The surface a mirror holds, as one keyframe Envelope; null before the mirror has one.
std::shared_ptr<const std::string> KeyframeOf(MeshMirror& mirror);

}  // namespace idms::server
