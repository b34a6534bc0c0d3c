// A live session on its strand: the agent's frames checked, mirrored, recorded and fanned out;
// viewers joined with a keyframe and resynchronised when slow; a resume that replaces the agent's
// connection without losing or repeating a tick; the recording acknowledged to the agent once
// stored.
#include "live_session.h"

#include <algorithm>
#include <boost/asio/post.hpp>
#include <cmath>
#include <utility>

#include "frame_checks.h"
#include "idms/protocol/envelope.h"
#include "idms/server/log.h"
#include "idms/sim/check.h"
#include "recordings.h"
#include "relay.h"
#include "sessions.h"

namespace idms::server {

namespace asio = boost::asio;
using Clock = std::chrono::steady_clock;

namespace {

// A sample batch waits at most this long for a mesh frame to travel with (the mesh comes at 60 Hz,
// so usually less than 17 ms): the force plot's latency against one WebSocket message instead of
// two per mesh frame, which is what a viewer costs the server.
constexpr std::chrono::milliseconds kGatherTime{25};
constexpr uint16_t kNormal = 1000;
constexpr uint16_t kGoingAway = 1001;
constexpr uint16_t kPolicyError = 1008;

}  // namespace

LiveSession::LiveSession(ServerCore& core, SessionHub& hub, SessionRow row, v1::Scene scene,
                         std::shared_ptr<Recorder> recorder, const DecodeLimits& limits, LeaseGrant lease)
    : core_(core),
      hub_(hub),
      id_(row.id),
      scene_(std::move(scene)),
      strand_(asio::make_strand(core.ioc)),
      timer_(strand_),
      recorder_(std::move(recorder)),
      mirror_(limits),
      audience_(core, hub),
      gather_timer_(strand_),
      next_tick_(row.next_tick),
      row_(std::move(row)) {
  // A resumed session (after a restart or its resume window) carries on with the figures of all
  // it recorded before.
  summary_ = SessionSummary::FromJson(row_.summary_json);
  lease_ = lease;
  epoch_ns_ = ParseUtcNs(row_.started);
  if (epoch_ns_ == 0) epoch_ns_ = UnixNs();
}

LiveSession::~LiveSession() = default;

void LiveSession::Start() {
  if (Bus* bus = hub_.bus()) {
    const std::weak_ptr<LiveSession> w = weak_from_this();
    std::string error;
    join_sub_ = bus->Subscribe(
        JoinSubject(id_),
        [w](std::string_view, const std::string& reply) {
          if (auto s = w.lock(); s && !reply.empty()) asio::post(s->strand_, [s, reply] { s->AnswerJoin(reply); });
        },
        &error);
    viewer_sub_ = bus->Subscribe(
        ViewerSubject(id_),
        [w](std::string_view data, const std::string&) {
          v1::RelayViewerMessage m;
          if (!m.ParseFromArray(data.data(), static_cast<int>(data.size()))) return;
          if (auto s = w.lock()) asio::post(s->strand_, [s, m = std::move(m)] { s->FromRelayedViewer(m); });
        },
        &error);
    if (!join_sub_ || !viewer_sub_) Log(LogLevel::kWarn, "the session is not relayed: " + error, {{"session", id_}});
  }
  asio::post(strand_, [self = shared_from_this()] { self->Tick(); });
}

void LiveSession::Publish(const std::shared_ptr<const std::string>& bytes, int deltas,
                          const std::string& close_reason) {
  Bus* bus = hub_.bus();
  if (bus == nullptr || !join_sub_) return;
  v1::RelayFrame f;
  f.set_epoch(static_cast<uint64_t>(lease_.epoch));
  f.set_incarnation(incarnation_);
  f.set_sequence(++relay_sequence_);
  if (bytes) f.set_message(*bytes);
  f.set_sent_unix_ns(UnixNs());
  f.set_deltas(static_cast<uint32_t>(deltas));
  f.set_close_reason(close_reason);
  if (bus->Publish(LiveSubject(id_), f.SerializeAsString())) ++hub_.relay_counters().frames_published;
}

void LiveSession::AnswerJoin(const std::string& reply) {
  Bus* bus = hub_.bus();
  if (bus == nullptr || !Owns()) return;
  v1::RelayJoin j;
  j.set_epoch(static_cast<uint64_t>(lease_.epoch));
  j.set_incarnation(incarnation_);
  j.set_sequence(relay_sequence_);
  j.set_live(live_);
  j.set_node(core_.options.node_id);
  j.mutable_welcome()->set_session_id(id_);
  *j.mutable_welcome()->mutable_scene() = scene_;
  if (const auto k = KeyframeOf(mirror_)) j.set_keyframe(*k);
  for (const auto& bytes : audience_.history()) j.add_history(*bytes);
  bus->Publish(reply, j.SerializeAsString());
}

void LiveSession::FromRelayedViewer(const v1::RelayViewerMessage& m) {
  std::string error;
  if (m.envelope().has_annotation() && CheckAnnotation(m.envelope().annotation(), &error)) {
    ViewerAnnotation(m.envelope().annotation(), m.peer());
  } else if (m.envelope().has_command() && m.admin()) {
    ViewerCommand(m.envelope().command(), m.peer());
  }
}

void LiveSession::AssertOnStrand() const { IDMS_CHECK(strand_.running_in_this_thread()); }

SessionRow LiveSession::Snapshot() const {
  std::lock_guard lock(row_mu_);
  return row_;
}

void LiveSession::SetTrainee(const std::string& trainee) {
  {
    std::lock_guard lock(row_mu_);
    row_.trainee = trainee;
  }
  Persist();
}

void LiveSession::Persist(std::function<void()> then) { hub_.StoreRow(Snapshot(), std::move(then)); }

// ---------------------------------------------------------------------------------------------
// Ownership.

bool LiveSession::Owns() {
  AssertOnStrand();
  if (!lapsed_ && Clock::now() < lease_.until) return true;
  if (lapsed_ || !live_) return false;
  lapsed_ = true;
  Log(LogLevel::kWarn, "the session's lease lapsed (not renewed in time); asking whether it is still ours",
      {{"session", id_}, {"epoch", lease_.epoch}});
  // Nothing more is taken from the agent until the store has answered: sent away, it resumes
  // (here once the lease is renewed, or on the server that took the session) and resends from
  // the tick its Welcome names. Nothing waiting is published.
  if (const std::shared_ptr<WsPeer> agent = agent_.lock()) {
    v1::Envelope later = ErrorEvent("the server is checking that it still owns session " + id_ + "; resume");
    later.mutable_session_event()->set_kind(v1::SessionEvent::KIND_RESUME_LATER);
    agent->Send(Serialized(later), true);
    agent->Close(kGoingAway, "ownership of the session in doubt; resume");
  }
  agent_.reset();
  agent_conn_ = 0;
  agent_gone_since_ = Clock::now();
  pending_.clear();
  CheckLease();
  return false;
}

namespace {
enum class LeaseOutcome { kHeld, kRetaken, kLost, kUnreachable };
}  // namespace

void LiveSession::RenewLease() {
  AssertOnStrand();
  if (renewing_ || lapsed_ || !live_) return;
  renewing_ = true;
  const auto asked = Clock::now();
  asio::post(core_.workers, [w = weak_from_this(), asked, epoch = lease_.epoch] {
    const auto s = w.lock();
    if (!s) return;
    LeaseOutcome outcome = LeaseOutcome::kLost;
    try {
      if (s->core_.leases->Renew(s->id_, s->core_.options.node_id, epoch, s->core_.options.lease_ttl)) {
        outcome = LeaseOutcome::kHeld;
      }
    } catch (const StoreUnavailable&) {
      outcome = LeaseOutcome::kUnreachable;
    }
    asio::post(s->strand_, [s, outcome, asked, epoch] {
      s->renewing_ = false;
      if (!s->live_ || s->lapsed_ || epoch != s->lease_.epoch) return;
      if (outcome == LeaseOutcome::kLost) {
        s->lease_.until = {};  // refused: lapse now, and ask
        s->Owns();
        return;
      }
      // Unreachable: nobody else can take the session from the store either; keep it.
      if (outcome == LeaseOutcome::kUnreachable && !std::exchange(s->unreachable_logged_, true)) {
        Log(LogLevel::kWarn, "lease not renewed: the database is unavailable; keeping the session",
            {{"session", s->id_}});
      }
      if (outcome == LeaseOutcome::kHeld) s->unreachable_logged_ = false;
      s->lease_.until = std::max(s->lease_.until, asked + s->core_.options.lease_ttl);
    });
  });
}

void LiveSession::CheckLease() {
  AssertOnStrand();
  const auto asked = Clock::now();
  asio::post(core_.workers, [w = weak_from_this(), asked, epoch = lease_.epoch] {
    const auto s = w.lock();
    if (!s) return;
    LeaseStore& leases = *s->core_.leases;
    const std::string& node = s->core_.options.node_id;
    const auto ttl = s->core_.options.lease_ttl;
    LeaseOutcome outcome = LeaseOutcome::kLost;
    int64_t now_epoch = epoch;
    try {
      if (leases.Renew(s->id_, node, epoch, ttl)) {
        outcome = LeaseOutcome::kHeld;
      } else if (const std::optional<int64_t> taken = leases.Acquire(s->id_, node, ttl)) {
        outcome = LeaseOutcome::kRetaken;  // lapsed, and nobody took it: ours again, a new epoch
        now_epoch = *taken;
      }
    } catch (const StoreUnavailable&) {
      outcome = LeaseOutcome::kUnreachable;
    }
    asio::post(s->strand_, [s, outcome, asked, now_epoch] {
      if (!s->live_) return;
      if (outcome == LeaseOutcome::kLost) return s->GiveUp();
      if (outcome == LeaseOutcome::kRetaken) ++s->hub_.leases_taken;
      Log(LogLevel::kInfo, "the session is still this server's", {{"session", s->id_}, {"epoch", now_epoch}});
      s->lease_ = LeaseGrant{now_epoch, asked + s->core_.options.lease_ttl};
      s->lapsed_ = false;
    });
  });
}

void LiveSession::GiveUp() {
  AssertOnStrand();
  if (!live_.exchange(false)) return;
  ++hub_.leases_lost;
  Log(LogLevel::kWarn, "session given up: another server holds its lease (its agent resumed there)",
      {{"session", id_}, {"epoch", lease_.epoch}});
  timer_.cancel();
  gather_timer_.cancel();
  pending_.clear();
  // Viewers reconnect (through the load balancer) and watch it relayed from its new owner.
  audience_.CloseAll(kGoingAway, "the session moved to another server; reconnect");
  num_viewers_ = 0;
  join_sub_.reset();
  viewer_sub_.reset();
  if (const std::shared_ptr<WsPeer> agent = agent_.lock()) agent->Close(kGoingAway, "the session moved; resume");
  agent_.reset();
  agent_conn_ = 0;
  // The new owner records from what this one made durable; nothing here is published or stored.
  recorder_->Abandon();
  hub_.Forget(id_, this);
}

void LiveSession::Tick() {
  timer_.expires_after(std::chrono::seconds(1));
  timer_.async_wait([self = shared_from_this()](boost::system::error_code ec) {
    if (ec || !self->live_) return;
    // An agent gone past the resume window: the session is closed, nothing recorded is lost.
    if (self->agent_conn_ == 0 && Clock::now() - self->agent_gone_since_ > self->core_.options.resume_window) {
      Log(LogLevel::kInfo, "session closed: its agent did not come back", {{"session", self->id_}});
      return self->End("interrupted", "the agent did not come back");
    }
    self->RenewLease();
    // The open chunk to the file, made durable; then the agent may forget every tick before this one.
    const uint64_t stored = self->next_tick_;
    self->recorder_->Flush([w = std::weak_ptr<LiveSession>(self), stored](bool ok) {
      if (auto s = w.lock(); s && ok) {
        asio::post(s->strand_, [s, stored] {
          if (!s->live_ || !s->Owns()) return;
          v1::Envelope ack;
          ack.mutable_ack()->set_next_tick(stored);
          s->SendToAgent(ack);
        });
      }
    });
    self->Persist();
    self->Tick();
  });
}

void LiveSession::Record(std::shared_ptr<const v1::Envelope> envelope) {
  // On the session's clock (a frame without a time of its own: the session's latest); the
  // publish time is when the server got it. Times were checked at the door (finite, in range).
  double t_s = FrameTimeS(*envelope);
  if (!(t_s > 0)) t_s = std::max(summary_.last_time_s, 0.0);
  const uint64_t log_ns = epoch_ns_ + static_cast<uint64_t>(std::llround(t_s * 1e9));
  recorder_->Write(std::move(envelope), log_ns, UnixNs());
}

void LiveSession::RecordEvent(v1::SessionEvent::Kind kind, const std::string& message, const std::string& peer) {
  auto e = std::make_shared<v1::Envelope>();
  v1::SessionEvent* ev = e->mutable_session_event();
  ev->set_kind(kind);
  ev->set_message(message);
  ev->set_peer(peer);
  ev->set_tick(next_tick_);
  ev->set_time_s(summary_.last_time_s);
  const auto bytes = Serialized(*e);
  Broadcast(bytes, FrameKind::kOther);
  if (kind != v1::SessionEvent::KIND_VIEWER_JOINED && kind != v1::SessionEvent::KIND_VIEWER_LEFT)
    audience_.Remember(bytes);
  Record(std::move(e));
}

void LiveSession::SendToAgent(const v1::Envelope& e) {
  if (auto agent = agent_.lock()) agent->Send(Serialized(e), true);
}

void LiveSession::Broadcast(const std::shared_ptr<const std::string>& bytes, FrameKind kind) {
  if (pending_.empty()) pending_since_ = Clock::now();
  pending_.emplace_back(bytes, kind);
  if (kind != FrameKind::kSamples) return Flush();
  ArmGatherTimer();
}

void LiveSession::ArmGatherTimer() {
  if (gather_armed_) return;
  gather_armed_ = true;
  gather_timer_.expires_at(pending_since_ + kGatherTime);
  gather_timer_.async_wait([w = weak_from_this()](boost::system::error_code ec) {
    const auto self = w.lock();
    if (ec || !self) return;
    self->gather_armed_ = false;
    if (self->pending_.empty()) return;
    if (Clock::now() - self->pending_since_ >= kGatherTime) return self->Flush();
    self->ArmGatherTimer();  // gathered since the last flush: its own deadline
  });
}

void LiveSession::Flush() {
  AssertOnStrand();
  if (pending_.empty()) return;
  if (!Owns()) return pending_.clear();  // not this server's to publish
  Audience::Outgoing out;
  for (const auto& [bytes, kind] : pending_) {
    (kind == FrameKind::kDelta ? out.deltas : kind == FrameKind::kSamples ? out.samples : out.others) += 1;
  }
  // One frame alone goes as it came; several, as one Frames message.
  const auto gather = [](const auto& pending, bool deltas) -> std::shared_ptr<const std::string> {
    v1::Envelope e;
    v1::Frames* frames = e.mutable_frames();
    for (const auto& [bytes, kind] : pending) {
      if (deltas || kind != FrameKind::kDelta) frames->add_envelopes(*bytes);
    }
    if (frames->envelopes_size() == 0) return nullptr;
    if (frames->envelopes_size() == 1) return std::make_shared<const std::string>(frames->envelopes(0));
    return Serialized(e);
  };
  out.bytes = pending_.size() == 1 ? pending_.front().first : gather(pending_, true);
  if (out.deltas > 0 && out.samples + out.others > 0) {
    out.without_deltas_maker = [&] { return gather(pending_, false); };
  }
  audience_.Offer(out);
  Publish(out.bytes, out.deltas, "");
  pending_.clear();
}

// ---------------------------------------------------------------------------------------------
// The agent.

void LiveSession::AgentAttached(uint64_t conn, std::weak_ptr<WsPeer> agent, bool resumed,
                                const std::string& resume_token) {
  AssertOnStrand();
  const std::shared_ptr<WsPeer> peer = agent.lock();
  if (!peer) return;  // gone before it was attached: its close is on its way
  if (!live_ || !Owns()) {
    // Ended (or closing) since the hub let the Hello in, or this server's lease is in doubt: the
    // agent acts on the kind.
    const SessionRow row = Snapshot();
    v1::Envelope refusal = ErrorEvent("session " + id_ +
                                      (row.state == "ended" ? " has ended"
                                       : live_              ? ": this server is checking that it still owns it; retry"
                                                            : " is being closed; retry"));
    refusal.mutable_session_event()->set_kind(row.state == "ended" ? v1::SessionEvent::KIND_ENDED
                                                                   : v1::SessionEvent::KIND_RESUME_LATER);
    peer->Send(Serialized(refusal), true);
    peer->Close(kNormal, "session " + id_ + " is not live");
    return;
  }
  // A resume while the old connection is still open (or half-open): the old one is closed and
  // whatever it still says is ignored; the new one resends from next_tick_.
  if (agent_conn_ != 0 && agent_conn_ != conn) {
    if (auto old = agent_.lock()) old->Close(kPolicyError, "replaced by a resumed connection");
  }
  agent_ = std::move(agent);
  agent_conn_ = conn;
  v1::Envelope w;
  v1::Welcome* welcome = w.mutable_welcome();
  welcome->set_protocol_version(kProtocolVersion);
  welcome->set_role(v1::ROLE_AGENT);
  welcome->set_identity("idms-server");
  welcome->set_session_id(id_);
  welcome->set_resume_token(resume_token);
  welcome->set_next_tick(next_tick_);
  peer->Send(Serialized(w), true);
  RecordEvent(resumed ? v1::SessionEvent::KIND_AGENT_RESUMED : v1::SessionEvent::KIND_STARTED,
              resumed ? "the agent resumed" : "session started", peer->peer());
  Persist();
}

void LiveSession::Refuse(const std::string& what) {
  Log(LogLevel::kWarn, "agent frame refused", {{"session", id_}, {"error", what}});
  const std::shared_ptr<WsPeer> agent = agent_.lock();
  agent_.reset();
  agent_conn_ = 0;
  agent_gone_since_ = Clock::now();
  if (!agent) return;
  agent->Send(Serialized(ErrorEvent(what)), true);
  agent->Close(kPolicyError, what.substr(0, 120));
  RecordEvent(v1::SessionEvent::KIND_ERROR, what, agent->peer());
}

void LiveSession::AgentFrame(uint64_t conn, std::shared_ptr<const v1::Envelope> envelope,
                             std::shared_ptr<const std::string> bytes) {
  AssertOnStrand();
  // A replaced connection's frames: the new connection resends them from its Welcome's next_tick.
  // Without the lease: nothing is taken (the agent, sent away, resends it wherever it resumes).
  if (!live_ || conn != agent_conn_ || !Owns()) return;
  const v1::Envelope& e = *envelope;
  if (e.has_device_samples()) {
    const v1::DeviceSamples& ds = e.device_samples();
    // Ticks in order: the first at or after next_tick (after, when the agent's backlog dropped
    // some), consecutive within the batch. (Ticks are below 2^63: checked at the door.)
    for (int i = 0; i < ds.samples_size(); ++i) {
      const uint64_t tick = ds.samples(i).tick();
      if ((i == 0 && tick < next_tick_) || (i > 0 && tick != ds.samples(i - 1).tick() + 1)) {
        return Refuse("tick " + std::to_string(tick) + " out of order (expected " +
                      std::to_string(i == 0 ? next_tick_ : ds.samples(i - 1).tick() + 1) + ")");
      }
    }
    summary_.Add(ds);
    if (ds.samples_size() > 0) next_tick_ = ds.samples(ds.samples_size() - 1).tick() + 1;
    {
      std::lock_guard lock(row_mu_);
      row_.samples += ds.samples_size();
      row_.next_tick = next_tick_;
      row_.duration_s = summary_.first_time_s < 0 ? 0 : summary_.last_time_s - summary_.first_time_s;
      row_.summary_json = summary_.Json();
    }
    Broadcast(bytes, FrameKind::kSamples);
    return Record(std::move(envelope));
  }
  if (e.has_mesh_keyframe() || e.has_mesh_delta()) {
    std::string error;
    switch (mirror_.Apply(e, &error)) {
      case MirrorStatus::kOk:
        Broadcast(bytes, e.has_mesh_delta() ? FrameKind::kDelta : FrameKind::kOther);
        return Record(std::move(envelope));
      case MirrorStatus::kGap: {
        // A delta for a base the server does not hold: ask the agent for a keyframe.
        v1::Envelope ask;
        ask.mutable_command()->set_kind(v1::Command::KIND_KEYFRAME_REQUEST);
        return SendToAgent(ask);
      }
      case MirrorStatus::kInvalid:
        return Refuse("mesh frame refused: " + error);
    }
  }
  if (e.has_session_event() && !(e.session_event().time_s() > 0) && summary_.last_time_s > 0) {
    // An event without its session time (an older agent's ENDED): the time of the last sample.
    auto timed = std::make_shared<v1::Envelope>(e);
    timed->mutable_session_event()->set_time_s(summary_.last_time_s);
    bytes = Serialized(*timed);
    envelope = std::move(timed);
  }
  const v1::Envelope& event = *envelope;
  if (event.has_session_event() && event.session_event().kind() == v1::SessionEvent::KIND_ENDED) {
    // The agent ended the session: recorded, then finished; the agent hears it in a final Ack.
    Broadcast(bytes, FrameKind::kOther);
    Record(std::move(envelope));
    return End("ended", "the session ended");
  }
  if (event.has_session_event() || event.has_topology_event()) {
    Broadcast(bytes, FrameKind::kOther);
    audience_.Remember(bytes);
    return Record(std::move(envelope));
  }
  Refuse(std::string("unexpected ") + EnvelopeBodyName(event) + " from the agent");
}

void LiveSession::AgentDetached(uint64_t conn) {
  AssertOnStrand();
  // Only the current connection detaches the agent: a replaced one leaving changes nothing.
  if (conn != agent_conn_) return;
  agent_.reset();
  agent_conn_ = 0;
  agent_gone_since_ = Clock::now();
  if (!live_) return;
  RecordEvent(v1::SessionEvent::KIND_AGENT_DISCONNECTED, "the agent's connection dropped; it may resume", "");
  Persist();
}

// ---------------------------------------------------------------------------------------------
// The end of a session.

void LiveSession::End(const std::string& state, const std::string& why) {
  AssertOnStrand();
  if (!live_.exchange(false)) return;
  timer_.cancel();
  Flush();  // what the viewers were still owed
  gather_timer_.cancel();
  audience_.CloseAll(kNormal, why);
  num_viewers_ = 0;
  Publish(nullptr, 0, why);
  join_sub_.reset();
  viewer_sub_.reset();
  // Once the file is closed and published: the row stored, the hub told, the agent acknowledged.
  const bool ended = state == "ended";
  // The row says "ended" or "interrupted" only once its recording is there under that name: a
  // listing that reads the new state finds the file (until then it reads "live", and the live file).
  recorder_->Finish([self = shared_from_this(), ended, state, epoch = lease_.epoch](bool ok) {
    {
      std::lock_guard lock(self->row_mu_);
      self->row_.state = state;
      self->row_.recording = self->hub_.recordings().NameFor(self->id_, state);
    }
    self->Persist([self, epoch] {
      self->hub_.Forget(self->id_, self.get());
      // Stored: another server may take the session now (its agent resuming there).
      try {
        self->core_.leases->Release(self->id_, self->core_.options.node_id, epoch);
      } catch (const StoreUnavailable&) {  // it lapses by itself
      }
    });
    asio::post(self->strand_, [self, ended, ok] {
      const std::shared_ptr<WsPeer> agent = self->agent_.lock();
      if (!agent || !ended) return;
      if (ok) {
        v1::Envelope ack;
        ack.mutable_ack()->set_next_tick(self->next_tick_);
        ack.mutable_ack()->set_final(true);
        agent->Send(Serialized(ack), true);
        agent->Close(kNormal, "session ended");
      } else {
        agent->Send(Serialized(ErrorEvent("the recording could not be finished (see the server's log)")), true);
        agent->Close(1011, "recording failed");
      }
    });
  });
}

void LiveSession::Stop(const std::string& why) {
  AssertOnStrand();
  if (!live_) return;
  v1::Envelope bye;
  bye.mutable_session_event()->set_kind(v1::SessionEvent::KIND_RECORDING_STOPPED);
  bye.mutable_session_event()->set_message(why);
  const auto bytes = Serialized(bye);
  Flush();
  if (auto agent = agent_.lock()) agent->Send(bytes, true), agent->Close(kGoingAway, why);
  audience_.SendToAll(bytes);
  agent_.reset();
  agent_conn_ = 0;
  End("interrupted", why);
}

// ---------------------------------------------------------------------------------------------
// Viewers.

void LiveSession::ViewerAttached(uint64_t viewer, std::weak_ptr<WsPeer> peer_weak, bool admin,
                                 std::shared_ptr<std::atomic<bool>> drain_wanted) {
  AssertOnStrand();
  const std::shared_ptr<WsPeer> peer = peer_weak.lock();
  if (!peer) return;
  if (!live_) return peer->Close(kNormal, "the session has ended");
  // Welcome with the scene, then at once the surface from the mirror.
  v1::Envelope w;
  v1::Welcome* welcome = w.mutable_welcome();
  welcome->set_protocol_version(kProtocolVersion);
  welcome->set_role(admin ? v1::ROLE_ADMIN : v1::ROLE_OBSERVER);
  welcome->set_identity("idms-server");
  welcome->set_session_id(id_);
  *welcome->mutable_scene() = scene_;
  audience_.Add(viewer, std::move(peer_weak), admin, std::move(drain_wanted));
  audience_.Greet(viewer, Serialized(w), KeyframeOf(mirror_));
  num_viewers_ = static_cast<int>(audience_.size());
  RecordEvent(v1::SessionEvent::KIND_VIEWER_JOINED, "a viewer joined", peer->peer());
}

void LiveSession::ViewerDetached(uint64_t viewer) {
  AssertOnStrand();
  const bool was_here = audience_.Remove(viewer);
  num_viewers_ = static_cast<int>(audience_.size());
  if (was_here && live_) RecordEvent(v1::SessionEvent::KIND_VIEWER_LEFT, "a viewer left", "");
}

void LiveSession::ViewerDrained(uint64_t viewer) {
  AssertOnStrand();
  // Caught up after skipping: a keyframe from the session's mirror puts the viewer right.
  audience_.Drained(viewer, [this] { return KeyframeOf(mirror_); });
}

std::optional<v1::Annotation> LiveSession::ViewerAnnotation(const v1::Annotation& note, const std::string& peer) {
  AssertOnStrand();
  if (!live_) return std::nullopt;
  // Stamped here: who, which, and when (now, in session time, unless the viewer named a time).
  // The id counter is the summary's, so that it carries on across restarts and after the end.
  auto e = std::make_shared<v1::Envelope>();
  v1::Annotation* a = e->mutable_annotation();
  *a = note;
  a->set_author(peer);
  a->set_id(++summary_.notes);
  if (!(note.time_s() > 0)) a->set_time_s(summary_.last_time_s);
  {
    std::lock_guard lock(row_mu_);
    row_.summary_json = summary_.Json();
  }
  v1::Annotation stamped = *a;
  const auto bytes = Serialized(*e);
  Broadcast(bytes, FrameKind::kOther);
  audience_.Remember(bytes);
  Record(std::move(e));
  return stamped;
}

void LiveSession::ViewerCommand(const v1::Command& command, const std::string& peer) {
  AssertOnStrand();
  if (!live_ || agent_conn_ == 0) return;
  v1::Envelope e;
  *e.mutable_command() = command;
  SendToAgent(e);
  RecordEvent(v1::SessionEvent::KIND_COMMAND,
              "command " + v1::Command::Kind_Name(command.kind()) + " relayed to the agent", peer);
}

}  // namespace idms::server
