// Relaying another server's live session to this server's viewers (relay.h).
#include "relay.h"

#include <boost/asio/post.hpp>

#include "idms/protocol/envelope.h"
#include "idms/server/log.h"
#include "sessions.h"

namespace idms::server {

namespace asio = boost::asio;
using Clock = std::chrono::steady_clock;

namespace {
constexpr uint16_t kNormal = 1000;
constexpr size_t kMaxWaiting = 512;  // frames held while the state they follow is on its way
constexpr auto kAskEvery = std::chrono::seconds(1);
constexpr auto kSilence = std::chrono::milliseconds(1500);  // no frame this long: ask the owner again
constexpr auto kNeverSynced = std::chrono::seconds(5);      // no owner answered: no such session
}  // namespace

std::string LiveSubject(const std::string& session) { return "idms.live." + session; }
std::string JoinSubject(const std::string& session) { return "idms.join." + session; }
std::string ViewerSubject(const std::string& session) { return "idms.viewer." + session; }

RelayedSession::RelayedSession(ServerCore& core, SessionHub& hub, Bus& bus, RelayCounters& counters, std::string id,
                               std::function<void(RelayedSession*)> on_empty)
    : core_(core),
      hub_(hub),
      bus_(bus),
      counters_(counters),
      id_(std::move(id)),
      strand_(asio::make_strand(core.ioc)),
      timer_(strand_),
      on_empty_(std::move(on_empty)),
      audience_(core, hub),
      last_heard_(Clock::now()),
      asked_at_(Clock::now()) {}

RelayedSession::~RelayedSession() = default;

bool RelayedSession::Start(std::string* error) {
  const std::weak_ptr<RelayedSession> w = weak_from_this();
  inbox_ = bus_.NewInbox();
  inbox_sub_ = bus_.Subscribe(
      inbox_,
      [w](std::string_view data, const std::string&) {
        v1::RelayJoin join;
        if (!join.ParseFromArray(data.data(), static_cast<int>(data.size()))) return;
        if (auto s = w.lock()) asio::post(s->strand_, [s, join = std::move(join)] { s->OnJoin(join); });
      },
      error);
  if (!inbox_sub_) return false;
  live_sub_ = bus_.Subscribe(
      LiveSubject(id_),
      [w](std::string_view data, const std::string&) {
        v1::RelayFrame frame;
        if (!frame.ParseFromArray(data.data(), static_cast<int>(data.size()))) return;
        if (auto s = w.lock())
          asio::post(s->strand_, [s, frame = std::move(frame)]() mutable { s->OnFrame(std::move(frame)); });
      },
      error);
  if (!live_sub_) return false;
  asio::post(strand_, [s = shared_from_this()] {
    s->AskForState();
    s->Tick();
  });
  return true;
}

void RelayedSession::AskForState() {
  asked_at_ = Clock::now();
  v1::RelayJoinRequest ask;
  ask.set_node(core_.options.node_id);
  bus_.Publish(JoinSubject(id_), ask.SerializeAsString(), inbox_);
}

void RelayedSession::Tick() {
  timer_.expires_after(std::chrono::milliseconds(250));
  timer_.async_wait([w = weak_from_this()](boost::system::error_code ec) {
    const auto s = w.lock();
    if (ec || !s || !s->live_) return;
    const auto now = Clock::now();
    // Nobody answers: a session that never was (or is no longer) live anywhere. A session that
    // was: its agent may resume on another server (a new owner, a new epoch) within the window.
    const auto give_up = s->ever_synced_ ? std::chrono::duration_cast<Clock::duration>(s->core_.options.resume_window)
                                         : std::chrono::duration_cast<Clock::duration>(kNeverSynced);
    if (now - s->last_heard_ > give_up) {
      return s->Close(s->ever_synced_ ? "the session's server stopped and its agent did not come back"
                                      : "no live session " + s->id_);
    }
    const bool silent = now - s->last_heard_ > kSilence;
    if ((!s->synced_ || silent) && now - s->asked_at_ > kAskEvery) s->AskForState();
    s->Tick();
  });
}

void RelayedSession::OnFrame(v1::RelayFrame frame) {
  if (!live_) return;
  const Owner owner{frame.epoch(), frame.incarnation()};
  if (ever_synced_ && owner < owner_) return;  // an owner that lost the session: fenced off
  last_heard_ = Clock::now();
  if (!synced_) {
    waiting_.push_back(std::move(frame));
    if (waiting_.size() > kMaxWaiting) waiting_.pop_front();
    return;
  }
  if (owner == owner_ && frame.sequence() <= sequence_) return;  // already had it
  if (owner != owner_ || frame.sequence() != sequence_ + 1) {
    // A gap (the bus dropped frames for us, or we reconnected), or a new owner: hold what comes
    // and ask for the state; the viewers keep the surface they have meanwhile.
    owner != owner_ ? ++counters_.epoch_changes : ++counters_.gaps;
    synced_ = false;
    waiting_.clear();
    waiting_.push_back(std::move(frame));
    return AskForState();
  }
  Deliver(frame);
}

void RelayedSession::Deliver(v1::RelayFrame& frame) {
  sequence_ = frame.sequence();
  if (!frame.close_reason().empty()) return Close(frame.close_reason());
  std::vector<v1::Envelope> frames;
  std::string error;
  if (!ParseFrames(frame.message(), &frames, &error)) {
    Log(LogLevel::kWarn, "relayed frame refused: " + error, {{"session", id_}});
    ++counters_.gaps;
    synced_ = false;
    return AskForState();
  }
  Audience::Outgoing out;
  out.bytes = std::make_shared<const std::string>(std::move(*frame.mutable_message()));  // parsed above
  out.deltas = static_cast<int>(frame.deltas());
  bool ended = false;
  for (const v1::Envelope& e : frames) {
    if (e.has_mesh_keyframe() || e.has_mesh_delta()) {
      if (mirror_.Apply(e, &error) != MirrorStatus::kOk) {
        // The owner's stream and our mirror disagree: start again from its state.
        ++counters_.gaps;
        synced_ = false;
        return AskForState();
      }
      if (e.has_mesh_keyframe()) ++out.others;
      continue;
    }
    if (e.has_device_samples()) {
      ++out.samples;
      continue;
    }
    ++out.others;
    const bool comings_and_goings =
        e.has_session_event() && (e.session_event().kind() == v1::SessionEvent::KIND_VIEWER_JOINED ||
                                  e.session_event().kind() == v1::SessionEvent::KIND_VIEWER_LEFT);
    if ((e.has_session_event() || e.has_annotation() || e.has_topology_event()) && !comings_and_goings) {
      audience_.Remember(Serialized(e));
    }
    ended = ended || (e.has_session_event() && e.session_event().kind() == v1::SessionEvent::KIND_ENDED);
  }
  if (out.deltas > 0 && out.samples + out.others > 0) {
    out.without_deltas_maker = [&frames] {
      v1::Envelope gathered;
      for (const v1::Envelope& e : frames) {
        if (!e.has_mesh_delta()) gathered.mutable_frames()->add_envelopes(e.SerializeAsString());
      }
      return Serialized(gathered);
    };
  }
  audience_.Offer(out);
  ++counters_.frames_relayed;
  const uint64_t now = UnixNs();
  if (frame.sent_unix_ns() > 0 && now > frame.sent_unix_ns()) {
    const uint64_t lag = now - frame.sent_unix_ns();
    counters_.lag_ns_sum += lag;
    ++counters_.lag_count;
    for (uint64_t max = counters_.lag_ns_max.load();
         lag > max && !counters_.lag_ns_max.compare_exchange_weak(max, lag);) {
    }
  }
  if (ended) Close("the session ended");
}

void RelayedSession::OnJoin(const v1::RelayJoin& join) {
  if (!live_) return;
  if (ever_synced_ && Owner{join.epoch(), join.incarnation()} < owner_) return;  // a stale owner's answer
  last_heard_ = Clock::now();
  ++counters_.joins;
  if (!join.live()) return Close("the session has ended");
  std::string error;
  if (!join.keyframe().empty()) {
    v1::Envelope k;
    if (!ParseEnvelope(join.keyframe(), &k, &error) || mirror_.Apply(k, &error) != MirrorStatus::kOk) {
      Log(LogLevel::kWarn, "relayed state refused: " + error, {{"session", id_}});
      return;  // asked again by the timer
    }
  }
  welcome_ = join.welcome();
  audience_.ForgetHistory();
  for (const std::string& h : join.history()) audience_.Remember(std::make_shared<const std::string>(h));
  const bool resync = ever_synced_;
  owner_ = {join.epoch(), join.incarnation()};
  sequence_ = join.sequence();
  synced_ = ever_synced_ = true;
  // The viewers watching: the surface now (they kept theirs through the gap); the ones who
  // joined while we waited: their Welcome first.
  if (resync) {
    if (const auto k = KeyframeOf(mirror_)) audience_.Resync(k);
  }
  for (const auto& [viewer, admin] : unwelcomed_) Welcome(viewer, admin);
  unwelcomed_.clear();
  // What came meanwhile, from where the state was taken.
  std::deque<v1::RelayFrame> waiting;
  waiting.swap(waiting_);
  for (v1::RelayFrame& f : waiting) {
    if (!synced_ || !live_) break;
    OnFrame(std::move(f));
  }
}

void RelayedSession::Welcome(uint64_t viewer, bool admin) {
  v1::Envelope w;
  *w.mutable_welcome() = welcome_;
  w.mutable_welcome()->set_protocol_version(kProtocolVersion);
  w.mutable_welcome()->set_role(admin ? v1::ROLE_ADMIN : v1::ROLE_OBSERVER);
  w.mutable_welcome()->set_identity("idms-server " + core_.options.node_id + " (relayed)");
  audience_.Greet(viewer, Serialized(w), KeyframeOf(mirror_));
}

void RelayedSession::ViewerAttached(uint64_t viewer, std::weak_ptr<WsPeer> peer_weak, bool admin,
                                    std::shared_ptr<std::atomic<bool>> drain_wanted) {
  const std::shared_ptr<WsPeer> peer = peer_weak.lock();
  if (!peer) return;
  if (!live_) return peer->Close(kNormal, "the session has ended");
  audience_.Add(viewer, std::move(peer_weak), admin, std::move(drain_wanted));
  if (synced_ || ever_synced_) return Welcome(viewer, admin);
  unwelcomed_.emplace_back(viewer, admin);
}

void RelayedSession::ViewerDetached(uint64_t viewer) {
  audience_.Remove(viewer);
  std::erase_if(unwelcomed_, [&](const auto& u) { return u.first == viewer; });
  if (audience_.size() == 0 && live_) Close("");
}

void RelayedSession::ViewerDrained(uint64_t viewer) {
  audience_.Drained(viewer, [this] { return KeyframeOf(mirror_); });
}

void RelayedSession::Forward(const v1::Envelope& e, const std::string& peer, bool admin) {
  v1::RelayViewerMessage m;
  *m.mutable_envelope() = e;
  m.set_peer(peer + " via " + core_.options.node_id);
  m.set_admin(admin);
  bus_.Publish(ViewerSubject(id_), m.SerializeAsString());
}

void RelayedSession::ViewerNote(const v1::Annotation& note, const std::string& peer) {
  v1::Envelope e;
  *e.mutable_annotation() = note;
  Forward(e, peer, false);
}

void RelayedSession::ViewerCommand(const v1::Command& command, const std::string& peer) {
  v1::Envelope e;
  *e.mutable_command() = command;
  Forward(e, peer, true);  // the endpoint lets only an admin's through
}

void RelayedSession::Close(const std::string& why) {
  if (!live_.exchange(false)) return;
  timer_.cancel();
  audience_.CloseAll(kNormal, why.empty() ? "the session has ended" : why);
  live_sub_.reset();
  inbox_sub_.reset();
  if (on_empty_) on_empty_(this);
}

}  // namespace idms::server
