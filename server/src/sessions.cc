// Live sessions: the agent's frames checked, mirrored, recorded and fanned out; viewers joined
// with a keyframe and resynchronised when slow; the recorder off the network threads; the index
// kept for lists and resumes, across a restart too.
#include "sessions.h"

#include <google/protobuf/text_format.h>
#include <openssl/crypto.h>
#include <openssl/rand.h>

#include <boost/asio/post.hpp>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>

#include "idms/protocol/digest.h"
#include "idms/protocol/envelope.h"
#include "idms/server/log.h"

namespace idms::server {

namespace asio = boost::asio;
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

constexpr size_t kViewerQueueLimit = 256;  // frames queued for a viewer before deltas are skipped
constexpr uint16_t kPolicyError = 1008;
constexpr uint16_t kGoingAway = 1001;

uint64_t UnixNs() {
  return static_cast<uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
}

// "2026-11-23T19:04:05Z" (as UtcNow writes it) as Unix ns; 0 when it does not parse.
uint64_t ParseUtcNs(const std::string& iso) {
  std::tm tm{};
  const char* end = strptime(iso.c_str(), "%Y-%m-%dT%H:%M:%SZ", &tm);
  if (end == nullptr || *end != '\0') return 0;
  const time_t t = timegm(&tm);
  return t < 0 ? 0 : static_cast<uint64_t>(t) * 1000000000ull;
}

// The simulation time a frame speaks of, s; 0 when it carries none.
double FrameTimeS(const v1::Envelope& e) {
  switch (e.body_case()) {
    case v1::Envelope::kDeviceSamples: {
      const auto& s = e.device_samples().samples();
      return s.empty() ? 0 : s[s.size() - 1].time_s();
    }
    case v1::Envelope::kMeshKeyframe:
      return e.mesh_keyframe().time_s();
    case v1::Envelope::kMeshDelta:
      return e.mesh_delta().time_s();
    case v1::Envelope::kTopologyEvent:
      return e.topology_event().time_s();
    case v1::Envelope::kSessionEvent:
      return e.session_event().time_s();
    case v1::Envelope::kAnnotation:
      return e.annotation().time_s();
    default:
      return 0;
  }
}

std::string RandomHex(size_t bytes) {
  std::vector<unsigned char> raw(bytes);
  RAND_bytes(raw.data(), static_cast<int>(raw.size()));
  return HexEncode(raw);
}

std::shared_ptr<const std::string> Serialized(const v1::Envelope& e) {
  auto bytes = std::make_shared<std::string>();
  SerializeEnvelope(e, bytes.get());
  return bytes;
}

v1::Envelope ErrorEvent(const std::string& message) {
  v1::Envelope e;
  e.mutable_session_event()->set_kind(v1::SessionEvent::KIND_ERROR);
  e.mutable_session_event()->set_message(message);
  return e;
}

double Norm(const v1::Vec3& v) { return std::sqrt(v.x() * v.x() + v.y() * v.y() + v.z() * v.z()); }

// Reads every message of a recording (finished, or unfinished after a crash) into `writer`,
// counting the device samples and the last tick. False with *error on unreadable data.
struct CopyStats {
  int64_t samples = 0;
  bool any_tick = false;
  uint64_t last_tick = 0;
  double first_time_s = -1, last_time_s = 0;
};
bool CopyRecording(const std::string& path, RecordingWriter* writer, CopyStats* stats, std::string* error) {
  RecordingReader reader;
  if (!reader.Open(path, RecordingReaderOptions{}, error)) return false;
  RecordedMessage m;
  while (reader.Next(&m, error)) {
    if (m.envelope.has_device_samples()) {
      for (const v1::DeviceSample& s : m.envelope.device_samples().samples()) {
        ++stats->samples;
        stats->any_tick = true;
        stats->last_tick = s.tick();
        if (stats->first_time_s < 0) stats->first_time_s = s.time_s();
        stats->last_time_s = s.time_s();
      }
    }
    if (writer != nullptr && !writer->Write(m.envelope, m.log_time_ns, m.publish_time_ns, error)) return false;
  }
  return error->empty();
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// The recording of one session, on the recorder thread. Written to ID.live.mcap, renamed to
// ID.mcap when finished; a resume after a restart first copies the finished file back in.
class Recorder : public std::enable_shared_from_this<Recorder> {
 public:
  // `bytes` and `failures` are the hub's counters for /metrics.
  Recorder(asio::thread_pool& pool, std::string dir, std::string id, std::atomic<uint64_t>* bytes,
           std::atomic<uint64_t>* failures)
      : strand_(asio::make_strand(pool)),
        dir_(std::move(dir)),
        id_(std::move(id)),
        bytes_counter_(bytes),
        failures_counter_(failures) {}

  std::string live_path() const { return dir_ + "/" + id_ + ".live.mcap"; }
  std::string final_path() const { return dir_ + "/" + id_ + ".mcap"; }

  void Start(RecordingWriterOptions options, bool continue_finished) {
    asio::post(strand_, [self = shared_from_this(), options = std::move(options), continue_finished] {
      std::string error;
      if (!self->writer_.Open(self->live_path(), options, &error)) return self->Failed(error);
      self->open_ = true;
      if (continue_finished && fs::exists(self->final_path())) {
        CopyStats stats;
        if (!CopyRecording(self->final_path(), &self->writer_, &stats, &error)) return self->Failed(error);
      }
    });
  }

  void Write(std::shared_ptr<const v1::Envelope> envelope, uint64_t log_ns, uint64_t publish_ns) {
    asio::post(strand_, [self = shared_from_this(), envelope = std::move(envelope), log_ns, publish_ns] {
      std::string error;
      if (self->open_ && !self->writer_.Write(*envelope, log_ns, publish_ns, &error)) self->Failed(error);
      self->CountBytes();
    });
  }

  void Flush() {
    asio::post(strand_, [self = shared_from_this()] {
      std::string error;
      if (self->open_ && !self->writer_.Flush(UnixNs(), &error)) self->Failed(error);
      self->CountBytes();
    });
  }

  // Closes the file (summary, indexes) and renames it into place; `done` runs on the recorder.
  void Finish(std::function<void()> done = nullptr) {
    asio::post(strand_, [self = shared_from_this(), done = std::move(done)] {
      std::string error;
      if (self->open_) {
        self->open_ = false;
        std::error_code ec;
        if (!self->writer_.Close(&error)) {
          self->Failed(error);
        } else if (fs::rename(self->live_path(), self->final_path(), ec); ec) {
          // The finished file stays under its .live name; the next start-up repairs and indexes it.
          self->Failed("rename " + self->live_path() + " -> " + self->final_path() + ": " + ec.message());
        }
        self->CountBytes();
      }
      if (done) done();
    });
  }

 private:
  void Failed(const std::string& error) {
    open_ = false;
    ++*failures_counter_;
    Log(LogLevel::kError, "recording failed", {{"session", id_}, {"error", error}});
  }
  void CountBytes() {
    const uint64_t now = writer_.mcap().bytes_written();
    if (now > bytes_counted_) *bytes_counter_ += now - bytes_counted_;
    bytes_counted_ = now;
  }

  asio::strand<asio::thread_pool::executor_type> strand_;
  std::string dir_, id_;
  RecordingWriter writer_;
  bool open_ = false;
  std::atomic<uint64_t>* bytes_counter_;
  std::atomic<uint64_t>* failures_counter_;
  uint64_t bytes_counted_ = 0;
};

void SessionSummary::Add(const v1::DeviceSamples& ds) {
  for (const v1::DeviceSample& s : ds.samples()) {
    const double f = Norm(s.force());
    peak_force = std::max(peak_force, f);
    const double dt = have_last ? s.time_s() - last_time_s : 0;
    if (s.contact()) force_sum_in_contact += f, ++contact_samples, contact_time_s += dt;
    const double p[3] = {s.tool_pos().x(), s.tool_pos().y(), s.tool_pos().z()};
    if (have_last) path_length += std::hypot(p[0] - last_pos[0], p[1] - last_pos[1], p[2] - last_pos[2]);
    std::copy(p, p + 3, last_pos);
    have_last = true;
    if (first_time_s < 0) first_time_s = s.time_s();
    last_time_s = s.time_s();
    warnings += s.warnings();
  }
  overruns = ds.stats().overruns();
  tick_p99_us = ds.stats().compute_p99_us();
  samples_dropped = ds.samples_dropped();
}

std::string SessionSummary::Json() const {
  return json{{"peak_force", peak_force},
              {"mean_contact_force", contact_samples > 0 ? force_sum_in_contact / contact_samples : 0.0},
              {"contact_time_s", contact_time_s},
              {"path_length", path_length},
              {"warnings", warnings},
              {"overruns", overruns},
              {"tick_p99_us", tick_p99_us},
              {"samples_dropped", samples_dropped}}
      .dump();
}

// ---------------------------------------------------------------------------------------------
// A viewer of a live session (/ws/session/{id}).
class ViewerEndpoint : public WsEndpoint, public std::enable_shared_from_this<ViewerEndpoint> {
 public:
  ViewerEndpoint(SessionHub& hub, std::shared_ptr<LiveSession> session, Role role)
      : hub_(hub), session_(std::move(session)), role_(role) {}

  void OnOpen(std::shared_ptr<WsPeer> peer) override {
    peer_ = std::move(peer);
    asio::post(session_->strand(), [s = session_, self = shared_from_this()] { s->ViewerAttached(self); });
  }

  void OnMessage(std::string_view bytes, bool) override {
    v1::Envelope e;
    std::string error;
    if (!ParseEnvelope(bytes, &e, &error, 1 << 20)) {
      peer_->Send(Serialized(ErrorEvent("malformed frame: " + error)), true);
      return peer_->Close(kPolicyError, "malformed frame");
    }
    if (e.has_hello()) return;  // optional: the URL names the session
    if (e.has_annotation()) {
      const std::string& text = e.annotation().text();
      if (text.empty() || text.size() > 1000) {
        peer_->Send(Serialized(ErrorEvent("an annotation's text must have 1 to 1000 bytes")), true);
        return;
      }
      return asio::post(session_->strand(),
                        [s = session_, a = e.annotation(), p = peer_->peer()] { s->ViewerAnnotation(a, p); });
    }
    if (e.has_command()) {
      if (role_ != Role::kAdmin) {
        peer_->Send(Serialized(ErrorEvent("command refused: only an admin may send commands to the agent")), true);
        return;
      }
      return asio::post(session_->strand(),
                        [s = session_, c = e.command(), p = peer_->peer()] { s->ViewerCommand(c, p); });
    }
    peer_->Send(Serialized(ErrorEvent(std::string("unexpected ") + EnvelopeBodyName(e) + " from a viewer")), true);
  }

  void OnDrained() override {
    // Caught up after skipping: a keyframe from the session's mirror puts the viewer right.
    if (skipping_.load() && !resync_requested_.exchange(true)) {
      asio::post(session_->strand(), [s = session_, self = shared_from_this()] { s->KeyframeFor(self); });
    }
  }

  void OnClose() override {
    asio::post(session_->strand(), [s = session_, self = shared_from_this()] { s->ViewerDetached(self.get()); });
  }

  // On the session's strand. Deltas are skipped while the viewer is behind (until a keyframe);
  // sample batches are dropped and counted; nothing waits.
  void Offer(const std::shared_ptr<const std::string>& bytes, bool is_delta, bool is_samples) {
    if (!peer_) return;
    if (is_delta && skipping_.load()) return void(++hub_.deltas_skipped);
    if (peer_->queued() >= kViewerQueueLimit) {
      // Behind: a viewer stalled past the limit is closed; until then it loses deltas (and is
      // resynchronised with a keyframe once it drains) and sample batches (counted).
      const auto now = std::chrono::steady_clock::now();
      if (!behind_since_) behind_since_ = now;
      const std::chrono::seconds limit = hub_.core().options.viewer_stall_timeout;
      if (now - *behind_since_ > limit) {
        ++hub_.stalled_closed;
        peer_->Close(kPolicyError, "viewer stalled: more than " + std::to_string(kViewerQueueLimit) +
                                       " frames behind for " + std::to_string(limit.count()) + " s");
        peer_.reset();
        return;
      }
      if (is_delta) {
        ++hub_.deltas_skipped;
        skipping_ = true;
        return;
      }
      if (is_samples) return void(++hub_.samples_dropped);
    } else {
      behind_since_.reset();
    }
    Send(bytes);
  }
  void OfferKeyframe(const std::shared_ptr<const std::string>& bytes) {
    if (!peer_) return;
    skipping_ = false;
    resync_requested_ = false;
    ++hub_.resyncs;
    Send(bytes);
  }
  void Send(const std::shared_ptr<const std::string>& bytes) {
    if (!peer_) return;
    ++hub_.viewer_frames;
    hub_.viewer_bytes += bytes->size();
    peer_->Send(bytes, true);
  }
  void Close(uint16_t code, const std::string& reason) {
    if (peer_) peer_->Close(code, reason);
  }
  Role role() const { return role_; }
  std::string peer() const { return peer_ ? peer_->peer() : std::string("?"); }

 private:
  SessionHub& hub_;
  std::optional<std::chrono::steady_clock::time_point> behind_since_;  // on the session's strand
  std::shared_ptr<LiveSession> session_;
  Role role_;
  std::shared_ptr<WsPeer> peer_;
  std::atomic<bool> skipping_{false};
  std::atomic<bool> resync_requested_{false};
};

// ---------------------------------------------------------------------------------------------
LiveSession::LiveSession(ServerCore& core, SessionRow row, v1::Scene scene, std::shared_ptr<Recorder> recorder)
    : core_(core),
      id_(row.id),
      scene_(std::move(scene)),
      strand_(asio::make_strand(core.ioc)),
      timer_(strand_),
      recorder_(std::move(recorder)),
      next_tick_(row.next_tick),
      row_(std::move(row)) {
  epoch_ns_ = ParseUtcNs(row_.started);
  if (epoch_ns_ == 0) epoch_ns_ = UnixNs();
}

void LiveSession::Start() {
  asio::post(strand_, [self = shared_from_this()] { self->Tick(); });
}

LiveSession::~LiveSession() = default;

SessionRow LiveSession::Snapshot() const {
  std::lock_guard lock(row_mu_);
  SessionRow r = row_;
  return r;
}

void LiveSession::Persist() {
  std::string error;
  const SessionRow r = Snapshot();
  if (!core_.hub->index().Put(r, &error)) Log(LogLevel::kError, "session index", {{"error", error}});
}

void LiveSession::Tick() {
  timer_.expires_after(std::chrono::seconds(1));
  timer_.async_wait([self = shared_from_this()](boost::system::error_code ec) {
    if (ec || !self->live_) return;
    // An agent gone past the resume window: the session is closed, nothing recorded is lost.
    if (!self->agent_ &&
        std::chrono::steady_clock::now() - self->agent_gone_since_ > self->core_.options.resume_window) {
      Log(LogLevel::kInfo, "session closed: its agent did not come back", {{"session", self->id_}});
      self->FinishRecording("interrupted");
      for (const auto& v : self->viewers_) v->Close(1000, "the agent did not come back");
      self->viewers_.clear();
      self->num_viewers_ = 0;
      self->core_.hub->Forget(self->id_);
      return;
    }
    self->recorder_->Flush();
    self->Persist();
    self->Tick();
  });
}

void LiveSession::Record(std::shared_ptr<const v1::Envelope> envelope) {
  // On the session's clock (a frame without a time of its own: the session's latest); the
  // publish time is when the server got it.
  double t_s = FrameTimeS(*envelope);
  if (!(t_s > 0) || !std::isfinite(t_s)) t_s = std::max(summary_.last_time_s, 0.0);
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
  Broadcast(Serialized(*e), false, false);
  Record(std::move(e));
}

void LiveSession::Broadcast(std::shared_ptr<const std::string> bytes, bool is_delta, bool is_samples) {
  for (const auto& v : viewers_) v->Offer(bytes, is_delta, is_samples);
}

void LiveSession::AgentAttached(std::shared_ptr<WsPeer> agent, bool resumed) {
  if (agent_ && agent_ != agent) agent_->Close(kPolicyError, "replaced by a resumed connection");
  agent_ = std::move(agent);
  RecordEvent(resumed ? v1::SessionEvent::KIND_AGENT_RESUMED : v1::SessionEvent::KIND_STARTED,
              resumed ? "the agent resumed" : "session started", agent_->peer());
  Persist();
}

void LiveSession::Refuse(const std::string& what) {
  Log(LogLevel::kWarn, "agent frame refused", {{"session", id_}, {"error", what}});
  if (!agent_) return;
  agent_->Send(Serialized(ErrorEvent(what)), true);
  agent_->Close(kPolicyError, what.substr(0, 120));
  RecordEvent(v1::SessionEvent::KIND_ERROR, what, agent_->peer());
  agent_.reset();
}

void LiveSession::AgentFrame(std::shared_ptr<const v1::Envelope> envelope, std::shared_ptr<const std::string> bytes) {
  if (!live_ || !agent_) return;
  const v1::Envelope& e = *envelope;
  if (e.has_device_samples()) {
    const v1::DeviceSamples& ds = e.device_samples();
    // Ticks in order: the first at or after next_tick (after, when the agent's backlog dropped
    // some), consecutive within the batch.
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
    Broadcast(bytes, false, true);
    return Record(std::move(envelope));
  }
  if (e.has_mesh_keyframe() || e.has_mesh_delta()) {
    std::string error;
    switch (mirror_.Apply(e, &error)) {
      case MirrorStatus::kOk:
        Broadcast(bytes, e.has_mesh_delta(), false);
        return Record(std::move(envelope));
      case MirrorStatus::kGap: {
        // A delta for a base the server does not hold: ask the agent for a keyframe.
        v1::Envelope ask;
        ask.mutable_command()->set_kind(v1::Command::KIND_KEYFRAME_REQUEST);
        agent_->Send(Serialized(ask), true);
        return;
      }
      case MirrorStatus::kInvalid:
        return Refuse("mesh frame refused: " + error);
    }
  }
  if (e.has_session_event() || e.has_topology_event()) {
    Broadcast(bytes, false, false);
    return Record(std::move(envelope));
  }
  Refuse(std::string("unexpected ") + EnvelopeBodyName(e) + " from the agent");
}

void LiveSession::AgentDetached(bool ended_cleanly) {
  if (!live_) return;
  agent_.reset();
  agent_gone_since_ = std::chrono::steady_clock::now();
  if (!ended_cleanly) {
    RecordEvent(v1::SessionEvent::KIND_AGENT_DISCONNECTED, "the agent's connection dropped; it may resume", "");
    return Persist();
  }
  // The agent ended the session: finish the recording, tell the viewers, forget it.
  FinishRecording("ended");
  for (const auto& v : viewers_) v->Close(1000, "the session ended");
  viewers_.clear();
  num_viewers_ = 0;
  core_.hub->Forget(id_);
}

void LiveSession::FinishRecording(const std::string& state) {
  live_ = false;
  timer_.cancel();
  {
    std::lock_guard lock(row_mu_);
    row_.state = state;
    row_.recording = id_ + ".mcap";
  }
  // The row is stored once the file is closed and renamed.
  recorder_->Finish([self = shared_from_this()] { self->Persist(); });
}

void LiveSession::Stop(const std::string& why) {
  if (!live_) return;
  FinishRecording("interrupted");
  v1::Envelope bye;
  bye.mutable_session_event()->set_kind(v1::SessionEvent::KIND_RECORDING_STOPPED);
  bye.mutable_session_event()->set_message(why);
  const auto bytes = Serialized(bye);
  if (agent_) agent_->Send(bytes, true), agent_->Close(kGoingAway, why);
  for (const auto& v : viewers_) v->Send(bytes), v->Close(kGoingAway, why);
  agent_.reset();
  viewers_.clear();
}

void LiveSession::ViewerAttached(std::shared_ptr<ViewerEndpoint> viewer) {
  // Welcome with the scene, then at once the surface from the mirror.
  v1::Envelope w;
  v1::Welcome* welcome = w.mutable_welcome();
  welcome->set_protocol_version(kProtocolVersion);
  welcome->set_role(viewer->role() == Role::kAdmin ? v1::ROLE_ADMIN : v1::ROLE_OBSERVER);
  welcome->set_identity("idms-server");
  welcome->set_session_id(id_);
  *welcome->mutable_scene() = scene_;
  viewer->Send(Serialized(w));
  if (mirror_.has_keyframe()) KeyframeFor(viewer);
  viewers_.push_back(viewer);
  num_viewers_ = static_cast<int>(viewers_.size());
  RecordEvent(v1::SessionEvent::KIND_VIEWER_JOINED, "a viewer joined", viewer->peer());
}

void LiveSession::ViewerDetached(ViewerEndpoint* viewer) {
  const size_t before = viewers_.size();
  std::erase_if(viewers_, [&](const auto& v) { return v.get() == viewer; });
  num_viewers_ = static_cast<int>(viewers_.size());
  if (viewers_.size() != before && live_) RecordEvent(v1::SessionEvent::KIND_VIEWER_LEFT, "a viewer left", "");
}

void LiveSession::KeyframeFor(std::shared_ptr<ViewerEndpoint> viewer) {
  v1::Envelope e;
  std::string error;
  if (!mirror_.MakeKeyframe(e.mutable_mesh_keyframe(), &error)) return;
  viewer->OfferKeyframe(Serialized(e));
}

void LiveSession::ViewerAnnotation(const v1::Annotation& note, const std::string& peer) {
  // Stamped here: who, which, and when (now, in session time, unless the viewer named a time).
  auto e = std::make_shared<v1::Envelope>();
  v1::Annotation* a = e->mutable_annotation();
  *a = note;
  a->set_author(peer);
  a->set_id(++annotations_);
  if (!(note.time_s() > 0)) a->set_time_s(summary_.last_time_s);
  Broadcast(Serialized(*e), false, false);
  Record(std::move(e));
}

void LiveSession::ViewerCommand(const v1::Command& command, const std::string& peer) {
  if (!agent_) return;
  auto e = std::make_shared<v1::Envelope>();
  *e->mutable_command() = command;
  agent_->Send(Serialized(*e), true);
  RecordEvent(v1::SessionEvent::KIND_COMMAND,
              "command " + v1::Command::Kind_Name(command.kind()) + " relayed to the agent", peer);
}

// ---------------------------------------------------------------------------------------------
SessionHub::SessionHub(ServerCore& core, SessionIndex* index, std::string recordings_dir)
    : core_(core), index_(index), recordings_dir_(std::move(recordings_dir)) {
  std::error_code ec;
  fs::create_directories(recordings_dir_, ec);
}

void SessionHub::RecoverInterrupted() {
  for (SessionRow row : index_->List()) {
    if (row.state != "live") continue;
    const std::string live = recordings_dir_ + "/" + row.id + ".live.mcap";
    const std::string final_path = recordings_dir_ + "/" + row.id + ".mcap";
    std::string error;
    // Repair: read what the crash left (the reader recovers by a scan), write a finished file.
    if (fs::exists(live)) {
      RecordingReader probe;
      std::map<std::string, std::string> meta;
      if (probe.Open(live, RecordingReaderOptions{}, &error)) meta = probe.session();
      RecordingWriter writer;
      RecordingWriterOptions options;
      options.session = meta;
      CopyStats stats;
      const std::string tmp = final_path + ".repair";
      error.clear();
      if (writer.Open(tmp, options, &error) && CopyRecording(live, &writer, &stats, &error) && writer.Close(&error)) {
        std::error_code ec;
        fs::rename(tmp, final_path, ec);
        fs::remove(live, ec);
        row.samples = stats.samples;
        row.next_tick = stats.any_tick ? stats.last_tick + 1 : 0;
        row.duration_s = stats.first_time_s < 0 ? 0 : stats.last_time_s - stats.first_time_s;
      } else {
        Log(LogLevel::kError, "recording not repaired", {{"session", row.id}, {"error", error}});
      }
    }
    row.state = "interrupted";
    row.recording = row.id + ".mcap";
    index_->Put(row, &error);
    Log(LogLevel::kInfo, "session interrupted by the last stop; recording repaired",
        {{"session", row.id}, {"samples", row.samples}, {"next_tick", row.next_tick}});
  }
}

std::shared_ptr<LiveSession> SessionHub::OpenForAgent(const v1::Hello& hello, const std::string& peer,
                                                      v1::Welcome* welcome, std::string* error) {
  if (hello.protocol_version() != kProtocolVersion) {
    *error = "protocol version " + std::to_string(hello.protocol_version()) + " is not this server's " +
             std::to_string(kProtocolVersion);
    return nullptr;
  }
  if (hello.role() != v1::ROLE_AGENT) {
    *error = "/ws/agent expects Hello.role ROLE_AGENT";
    return nullptr;
  }
  welcome->set_protocol_version(kProtocolVersion);
  welcome->set_role(v1::ROLE_AGENT);
  welcome->set_identity("idms-server");
  std::lock_guard lock(mu_);
  if (!hello.session_id().empty()) {
    // A resume: the session live here, or interrupted by a restart.
    const std::string digest = Sha256Hex(hello.resume_token());
    std::shared_ptr<LiveSession> s;
    SessionRow row;
    if (auto it = live_.find(hello.session_id()); it != live_.end()) {
      s = it->second;
      row = s->Snapshot();
    } else if (auto r = index_->Get(hello.session_id()); r && r->state != "ended") {
      row = *r;
    } else {
      *error = "unknown or ended session " + hello.session_id();
      return nullptr;
    }
    if (row.resume_sha256.size() != digest.size() ||
        CRYPTO_memcmp(row.resume_sha256.data(), digest.data(), digest.size()) != 0) {
      *error = "bad resume token for session " + hello.session_id();
      return nullptr;
    }
    if (!s) {
      row.state = "live";
      row.recording = row.id + ".live.mcap";
      v1::Scene scene;
      google::protobuf::TextFormat::ParseFromString(row.scene_text, &scene);
      s = StartSession(row, scene, /*continue_finished=*/true);
    }
    welcome->set_session_id(row.id);
    welcome->set_resume_token(hello.resume_token());
    welcome->set_next_tick(row.next_tick);
    return s;
  }
  // A new session.
  SessionRow row;
  row.id = UtcNow().substr(0, 10) + "-" + RandomHex(6);
  row.state = "live";
  row.model = !hello.scene().model().empty() ? hello.scene().model() : hello.scene().model_file();
  row.identity = hello.identity();
  row.device = hello.device();
  row.started = UtcNow();
  row.recording = row.id + ".live.mcap";
  google::protobuf::TextFormat::PrintToString(hello.scene(), &row.scene_text);
  const std::string resume_token = RandomHex(32);
  row.resume_sha256 = Sha256Hex(resume_token);
  auto s = StartSession(row, hello.scene(), /*continue_finished=*/false);
  index_->Put(row, error);
  welcome->set_session_id(row.id);
  welcome->set_resume_token(resume_token);
  welcome->set_next_tick(0);
  Log(LogLevel::kInfo, "session started", {{"session", row.id}, {"model", row.model}, {"peer", peer}});
  return s;
}

std::shared_ptr<LiveSession> SessionHub::StartSession(const SessionRow& row, const v1::Scene& scene,
                                                      bool continue_finished) {
  // Its recording (with the session's id, model and scene as metadata), then the session itself.
  auto recorder =
      std::make_shared<Recorder>(core_.recorder, recordings_dir_, row.id, &recording_bytes, &recording_failures);
  RecordingWriterOptions options;
  options.session = {{"session_id", row.id}, {"model", row.model}, {"scene", row.scene_text}};
  recorder->Start(options, continue_finished);
  auto s = std::make_shared<LiveSession>(core_, row, scene, recorder);
  s->Start();
  live_[row.id] = s;
  return s;
}

std::shared_ptr<LiveSession> SessionHub::FindLive(const std::string& id) {
  std::lock_guard lock(mu_);
  const auto it = live_.find(id);
  return it == live_.end() ? nullptr : it->second;
}

void SessionHub::Forget(const std::string& id) {
  std::lock_guard lock(mu_);
  live_.erase(id);
}

int SessionHub::live_count() {
  std::lock_guard lock(mu_);
  return static_cast<int>(live_.size());
}

namespace {
std::string Counter(const char* name, const char* help, const std::atomic<uint64_t>& value) {
  return std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " counter\n" + name + " " +
         std::to_string(value.load()) + "\n";
}
}  // namespace

std::string SessionHub::MetricsText() {
  std::vector<std::shared_ptr<LiveSession>> all;
  {
    std::lock_guard lock(mu_);
    for (auto& [id, s] : live_) all.push_back(s);
  }
  // One group of lines per metric family, as the text format requires.
  int viewers = 0;
  std::string samples, watching, p99, overruns;
  for (const auto& s : all) {
    viewers += s->viewers();
    const SessionRow r = s->Snapshot();
    const json summary = json::parse(r.summary_json.empty() ? "{}" : r.summary_json, nullptr, false);
    const std::string label = "{session=\"" + r.id + "\"} ";
    samples += "idms_session_samples" + label + std::to_string(r.samples) + "\n";
    watching += "idms_session_viewers" + label + std::to_string(s->viewers()) + "\n";
    if (summary.is_object() && summary.contains("tick_p99_us")) {
      p99 += "idms_session_tick_p99_us" + label + summary["tick_p99_us"].dump() + "\n";
      overruns += "idms_session_overruns" + label + summary["overruns"].dump() + "\n";
    }
  }
  return "# HELP idms_live_sessions Live sessions (an agent publishing, or gone and able to resume).\n"
         "# TYPE idms_live_sessions gauge\nidms_live_sessions " +
         std::to_string(all.size()) +
         "\n# HELP idms_viewers Viewers of live sessions.\n# TYPE idms_viewers gauge\nidms_viewers " +
         std::to_string(viewers) + "\n" +
         Counter("idms_viewer_frames_total", "Frames queued to live viewers.", viewer_frames) +
         Counter("idms_viewer_bytes_total", "Bytes queued to live viewers.", viewer_bytes) +
         Counter("idms_viewer_deltas_skipped_total", "Mesh deltas slow viewers skipped.", deltas_skipped) +
         Counter("idms_viewer_samples_dropped_total", "Sample batches slow viewers did not get.", samples_dropped) +
         Counter("idms_viewer_resyncs_total", "Keyframes sent to put a slow viewer right.", resyncs) +
         Counter("idms_recording_bytes_total", "Bytes written to session recordings (MCAP files).", recording_bytes) +
         Counter("idms_recording_failures_total", "Recordings that stopped on an error (see the log).",
                 recording_failures) +
         Counter("idms_viewer_stalled_closed_total", "Viewers closed for staying stalled.", stalled_closed) +
         "# HELP idms_session_samples Device samples received, per live session.\n"
         "# TYPE idms_session_samples gauge\n" +
         samples + "# HELP idms_session_viewers Viewers, per live session.\n# TYPE idms_session_viewers gauge\n" +
         watching +
         "# HELP idms_session_tick_p99_us The agent's tick compute time p99, per live session.\n"
         "# TYPE idms_session_tick_p99_us gauge\n" +
         p99 +
         "# HELP idms_session_overruns The agent's loop overruns, per live session.\n"
         "# TYPE idms_session_overruns gauge\n" +
         overruns;
}

std::vector<SessionRow> SessionHub::List() {
  std::map<std::string, SessionRow> live_rows;
  {
    std::lock_guard lock(mu_);
    for (const auto& [id, s] : live_) live_rows[id] = s->Snapshot();
  }
  std::vector<SessionRow> out;
  for (SessionRow& r : index_->List()) {
    const auto it = live_rows.find(r.id);
    out.push_back(it != live_rows.end() ? it->second : r);
  }
  return out;
}

std::optional<SessionRow> SessionHub::Get(const std::string& id) {
  if (auto s = FindLive(id)) return s->Snapshot();
  return index_->Get(id);
}

bool SessionHub::Delete(const std::string& id, std::string* error) {
  if (FindLive(id)) {
    *error = "session " + id + " is live";
    return false;
  }
  const std::optional<SessionRow> row = index_->Get(id);
  if (!row) {
    *error = "no session " + id;
    return false;
  }
  std::error_code ec;
  fs::remove(RecordingPath(*row), ec);
  return index_->Delete(id);
}

void SessionHub::StopAll() {
  std::vector<std::shared_ptr<LiveSession>> all;
  {
    std::lock_guard lock(mu_);
    for (auto& [id, s] : live_) all.push_back(s);
    live_.clear();
  }
  for (auto& s : all) asio::post(s->strand(), [s] { s->Stop("the server is shutting down"); });
}

// ---------------------------------------------------------------------------------------------
namespace {

// /ws/library: library events as JSON text; a client message is a protocol violation.
class LibraryEndpoint : public WsEndpoint, public TextSink, public std::enable_shared_from_this<LibraryEndpoint> {
 public:
  explicit LibraryEndpoint(ServerCore& core) : core_(core) {}
  void OnOpen(std::shared_ptr<WsPeer> peer) override {
    peer_ = std::move(peer);
    core_.Subscribe(this, weak_from_this());
    peer_->Send(std::make_shared<const std::string>(R"({"event":"hello","endpoint":"/ws/library"})"), false);
  }
  void OnMessage(std::string_view, bool) override { peer_->Close(kPolicyError, "/ws/library accepts no messages"); }
  void OnClose() override {
    core_.Unsubscribe(this);
    peer_.reset();
  }
  void Send(std::shared_ptr<const std::string> text) override {
    if (auto p = peer_) p->Send(std::move(text), false);
  }

 private:
  ServerCore& core_;
  std::shared_ptr<WsPeer> peer_;
};

// /ws/agent: Hello first, then the session's frames.
class AgentEndpoint : public WsEndpoint, public std::enable_shared_from_this<AgentEndpoint> {
 public:
  explicit AgentEndpoint(ServerCore& core) : core_(core) {}
  int max_messages_per_s() const override { return 2000; }
  void OnOpen(std::shared_ptr<WsPeer> peer) override { peer_ = std::move(peer); }

  void OnMessage(std::string_view bytes, bool binary) override {
    auto e = std::make_shared<v1::Envelope>();
    std::string error;
    if (!binary || !ParseEnvelope(bytes, e.get(), &error, core_.options.max_ws_message_bytes)) {
      return Refuse(binary ? "malformed frame: " + error : "frames must be binary Envelopes");
    }
    if (!session_) {
      if (!e->has_hello()) return Refuse("the first frame must be a Hello");
      v1::Envelope reply;
      session_ = core_.hub->OpenForAgent(e->hello(), peer_->peer(), reply.mutable_welcome(), &error);
      if (!session_) return Refuse(error);
      peer_->Send(Serialized(reply), true);
      const bool resumed = !e->hello().session_id().empty();
      return asio::post(session_->strand(), [s = session_, p = peer_, resumed] { s->AgentAttached(p, resumed); });
    }
    if (e->has_session_event() && e->session_event().kind() == v1::SessionEvent::KIND_ENDED) ended_ = true;
    auto raw = std::make_shared<const std::string>(bytes);
    asio::post(session_->strand(), [s = session_, e, raw] { s->AgentFrame(e, raw); });
  }

  void OnClose() override {
    if (session_) asio::post(session_->strand(), [s = session_, ended = ended_] { s->AgentDetached(ended); });
    peer_.reset();
  }

 private:
  void Refuse(const std::string& what) {
    peer_->Send(Serialized(ErrorEvent(what)), true);
    peer_->Close(kPolicyError, what.substr(0, 120));
  }

  ServerCore& core_;
  std::shared_ptr<WsPeer> peer_;
  std::shared_ptr<LiveSession> session_;
  bool ended_ = false;
};

}  // namespace

std::shared_ptr<WsEndpoint> MakeEndpoint(ServerCore& core, const ApiRequest& req, std::string* refusal) {
  if (req.path == "/ws/library") return std::make_shared<LibraryEndpoint>(core);
  if (req.path == "/ws/agent") return std::make_shared<AgentEndpoint>(core);
  if (req.params.size() == 1 && req.path.rfind("/ws/session/", 0) == 0) {
    auto s = core.hub->FindLive(req.params[0]);
    if (!s) {
      *refusal = "no live session " + req.params[0];
      return nullptr;
    }
    return std::make_shared<ViewerEndpoint>(*core.hub, s, req.role);
  }
  if (req.params.size() == 1 && req.path.rfind("/ws/replay/", 0) == 0)
    return MakeReplayEndpoint(core, req.params[0], refusal);
  *refusal = "no WebSocket endpoint " + req.path;
  return nullptr;
}

}  // namespace idms::server
