// /ws/replay/{id}: a recording played back to one viewer, with play, pause, seek and speed
// (PlaybackControl), and PlaybackState before a seek's catch-up, after each control and once a
// second. Each replay viewer has its own reader, so many replays of one recording are independent.
// Reads run on the worker pool (disk), never on an I/O thread; a seek finds the latest keyframe
// through the chunk index and sends the device samples of the viewer's plot window with it.
#include <google/protobuf/text_format.h>

#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <cmath>

#include "frame_checks.h"
#include "idms/protocol/envelope.h"
#include "idms/protocol/mesh_mirror.h"
#include "idms/protocol/recording.h"
#include "idms/server/log.h"
#include "sessions.h"

namespace idms::server {

namespace asio = boost::asio;
using Clock = std::chrono::steady_clock;

namespace {

constexpr size_t kReplayQueueLimit = 256;  // frames queued for the viewer before playback waits
// A seek's catch-up carries the device samples of this long before the new time: the browser
// viewer's plot window (kWindowS in viewer-web/src/pages/session.js, LiveView's windowS), so that
// its plots are full at once, however far back the keyframe is.
constexpr uint64_t kPlotWindowNs = 5'000'000'000;
constexpr int kHistoryBatch = 1000;  // device samples per catch-up message at most

class ReplayEndpoint : public WsEndpoint, public std::enable_shared_from_this<ReplayEndpoint> {
 public:
  ReplayEndpoint(ServerCore& core, std::string path, std::string id)
      : strand_(asio::make_strand(core.workers)), timer_(strand_), path_(std::move(path)), id_(std::move(id)) {}

  void OnOpen(std::weak_ptr<WsPeer> peer) override {
    peer_ = std::move(peer);
    asio::post(strand_, [self = shared_from_this()] { self->Open(); });
  }

  void OnMessage(std::string_view bytes, bool binary) override {
    auto e = std::make_shared<v1::Envelope>();
    std::string error;
    if (!binary) return Error("frames must be binary Envelopes");
    if (!ParseEnvelope(bytes, e.get(), &error, 1 << 16) || !e->has_playback_control()) {
      return Error(error.empty() ? std::string("a replay takes PlaybackControl frames only")
                                 : "malformed frame: " + error);
    }
    if (!CheckPlaybackControl(e->playback_control(), &error)) return Error(error);
    asio::post(strand_, [self = shared_from_this(), e] { self->Control(e->playback_control()); });
  }

  void OnClose() override {
    asio::post(strand_, [self = shared_from_this()] {
      self->closed_ = true;
      self->timer_.cancel();
    });
  }

 private:
  void Error(const std::string& what) {
    v1::Envelope e;
    e.mutable_session_event()->set_kind(v1::SessionEvent::KIND_ERROR);
    e.mutable_session_event()->set_message(what);
    Send(e);
  }

  void Send(const v1::Envelope& e) {
    auto bytes = std::make_shared<std::string>();
    SerializeEnvelope(e, bytes.get());
    if (auto p = peer_.lock()) p->Send(std::move(bytes), true);
  }

  double TimeS(uint64_t ns) const { return ns <= reader_.start_ns() ? 0 : (ns - reader_.start_ns()) * 1e-9; }

  void Open() {
    std::string error;
    RecordingReaderOptions options;
    options.device_history_ns = kPlotWindowNs;
    if (!reader_.Open(path_, options, &error)) {
      Error("cannot read the recording: " + error);
      if (auto p = peer_.lock()) p->Close(1011, "cannot read the recording");
      return;
    }
    // Welcome with the recorded scene, then the surface at the start, paused.
    v1::Envelope w;
    w.mutable_welcome()->set_protocol_version(kProtocolVersion);
    w.mutable_welcome()->set_role(v1::ROLE_OBSERVER);
    w.mutable_welcome()->set_identity("idms-server replay");
    w.mutable_welcome()->set_session_id(id_);
    const auto scene = reader_.session().find("scene");
    if (scene != reader_.session().end()) {
      google::protobuf::TextFormat::ParseFromString(scene->second, w.mutable_welcome()->mutable_scene());
    }
    Send(w);
    if (!SeekTo(0)) SendState();  // SeekTo sent it when it could seek
    Heartbeat();
  }

  // Positions at session time t_s and sends, at once: the PlaybackState at t_s, which tells the
  // viewer that what follows is the new time's (it restarts its plots there), then the catch-up
  // (RecordingReader::Seek): the device samples of the plot window before t_s, in log-time order,
  // and the surface at t_s as one keyframe: the recorded keyframe at or before t_s with the
  // deltas after it, applied here (a few hundred deltas at the default keyframe interval, tens
  // of thousands at a long one, would otherwise each be a frame to the viewer, past its queue's
  // limit). False (an error sent) when the recording is damaged there.
  bool SeekTo(double t_s) {
    const double duration = TimeS(reader_.end_ns());
    t_s = std::clamp(t_s, 0.0, duration);
    const uint64_t target = reader_.start_ns() + static_cast<uint64_t>(std::llround(t_s * 1e9));
    std::string error;
    pending_.reset();
    if (!reader_.Seek(target, &error)) {
      Error("seek: " + error);
      return false;
    }
    position_ns_ = target;
    SendState();
    // The catch-up goes at once; the first message at or after t waits in pending_.
    RecordedMessage m;
    bool surface = false;
    v1::Envelope history;  // the catch-up's device samples, in batches of up to kHistoryBatch
    while (reader_.Next(&m, &error)) {
      if (!m.catch_up) {
        pending_ = std::move(m);
        break;
      }
      if (m.topic == RecordingTopic::kDevice && m.envelope.has_device_samples()) {
        AddHistory(m.envelope.device_samples(), &history);
        continue;
      }
      if (m.topic != RecordingTopic::kMesh) {
        Send(m.envelope);
        continue;
      }
      // A frame the recording cannot apply (lost before it was written) leaves the surface at the
      // last one applied; the viewer then waits for the next keyframe, as it would have.
      std::string mesh_error;
      if (catch_up_.Apply(m.envelope, &mesh_error) == MirrorStatus::kOk) surface = true;
    }
    if (history.device_samples().samples_size() > 0) Send(history);
    if (!error.empty()) Error("recording: " + error);
    if (surface) {
      v1::Envelope keyframe;
      std::string mesh_error;
      if (catch_up_.MakeKeyframe(keyframe.mutable_mesh_keyframe(), &mesh_error)) {
        Send(keyframe);
      } else {
        Error("recording: " + mesh_error);
      }
    } else {
      SendFirstKeyframe();
    }
    Anchor();
    return true;
  }

  // A time before the recording's first keyframe (a replay opens at 0, and the agent's first
  // frame comes some milliseconds in) has no surface of its own: the viewer gets that first
  // keyframe now rather than an empty view until Play. (Play sends it again, in its place.)
  void SendFirstKeyframe() {
    RecordingReader first;
    RecordingReaderOptions options;
    options.device = options.events = options.annotations = false;
    std::string error;
    if (!first.Open(path_, options, &error)) return;
    RecordedMessage m;
    while (first.Next(&m, &error)) {
      if (m.envelope.has_mesh_keyframe()) return Send(m.envelope);
    }
  }

  // Appends a recorded batch to the catch-up's history: one message per kHistoryBatch samples,
  // not one per recorded batch (an agent that sends every sample alone, sample_batch 1, would
  // make a 5 s window 5,000 messages, past the viewer's queue). A batch that does not follow the
  // last sample's tick (samples lost before they were recorded) starts a new message, so that
  // each holds consecutive ticks; the statistics are the latest batch's.
  void AddHistory(const v1::DeviceSamples& batch, v1::Envelope* history) {
    v1::DeviceSamples* h = history->mutable_device_samples();
    if (h->samples_size() > 0 &&
        (h->samples_size() + batch.samples_size() > kHistoryBatch || batch.samples_size() == 0 ||
         batch.samples(0).tick() != h->samples(h->samples_size() - 1).tick() + 1)) {
      Send(*history);
      history->Clear();
      h = history->mutable_device_samples();
    }
    h->mutable_samples()->MergeFrom(batch.samples());
    *h->mutable_stats() = batch.stats();
    h->set_samples_dropped(batch.samples_dropped());
    h->set_sent_unix_ns(batch.sent_unix_ns());
  }

  void Anchor() {
    anchor_wall_ = Clock::now();
    anchor_ns_ = position_ns_;
  }

  void Control(const v1::PlaybackControl& c) {
    switch (c.action()) {
      case v1::PlaybackControl::ACTION_PLAY:
        if (!pending_ && position_ns_ >= reader_.end_ns()) SeekTo(0);  // play again from the start
        playing_ = true;
        Anchor();
        Pump();
        break;
      case v1::PlaybackControl::ACTION_PAUSE:
        playing_ = false;
        timer_.cancel();
        break;
      case v1::PlaybackControl::ACTION_SEEK:
        timer_.cancel();
        SeekTo(c.seek_time_s());
        if (playing_) Pump();
        break;
      case v1::PlaybackControl::ACTION_SET_SPEED:
        if (!(c.speed() >= 0.1 && c.speed() <= 10)) return Error("speed must be within 0.1 and 10");
        speed_ = c.speed();
        Anchor();
        if (playing_) Pump();
        break;
      default:
        return Error("unknown playback action");
    }
    SendState();
  }

  // Sends every message that is due, then waits for the next one (or for the viewer's queue).
  void Pump() {
    if (closed_ || !playing_) return;
    timer_.cancel();
    std::string error;
    while (true) {
      if (!pending_) {
        RecordedMessage m;
        if (!reader_.Next(&m, &error)) {
          if (!error.empty()) Error("recording: " + error);
          playing_ = false;
          position_ns_ = reader_.end_ns();
          SendState();
          return;
        }
        pending_ = std::move(m);
      }
      const double due_s =
          (static_cast<double>(pending_->log_time_ns) - static_cast<double>(anchor_ns_)) * 1e-9 / speed_;
      const auto due = anchor_wall_ + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(due_s));
      if (auto p = peer_.lock(); p && p->queued() >= kReplayQueueLimit)
        return Wait(Clock::now() + std::chrono::milliseconds(10));
      if (due > Clock::now()) return Wait(due);
      position_ns_ = pending_->log_time_ns;
      Send(pending_->envelope);
      pending_.reset();
    }
  }

  void Wait(Clock::time_point until) {
    timer_.expires_at(until);
    timer_.async_wait([self = shared_from_this()](boost::system::error_code ec) {
      if (!ec) self->Pump();
    });
  }

  void SendState() {
    v1::Envelope e;
    v1::PlaybackState* s = e.mutable_playback_state();
    s->set_recording_id(id_);
    s->set_playing(playing_);
    s->set_time_s(TimeS(position_ns_));
    s->set_duration_s(TimeS(reader_.end_ns()));
    s->set_speed(speed_);
    Send(e);
  }

  // PlaybackState once a second while the viewer is connected.
  void Heartbeat() {
    heartbeat_ = std::make_unique<asio::steady_timer>(strand_, std::chrono::seconds(1));
    heartbeat_->async_wait([self = shared_from_this()](boost::system::error_code ec) {
      if (ec || self->closed_) return;
      self->SendState();
      self->Heartbeat();
    });
  }

  asio::strand<asio::thread_pool::executor_type> strand_;
  asio::steady_timer timer_;
  std::unique_ptr<asio::steady_timer> heartbeat_;
  std::weak_ptr<WsPeer> peer_;  // set before Open is posted, then read on the replay's strand
  std::string path_, id_;
  RecordingReader reader_;
  std::optional<RecordedMessage> pending_;
  MeshMirror catch_up_;  // a seek's surface, sent as one keyframe
  bool playing_ = false, closed_ = false;
  double speed_ = 1;
  uint64_t position_ns_ = 0, anchor_ns_ = 0;
  Clock::time_point anchor_wall_;
};

}  // namespace

std::shared_ptr<WsEndpoint> MakeReplayEndpoint(ServerCore& core, const std::string& id, std::string* refusal) {
  // A live session replays what its recording holds when the replay opens (the file being written,
  // read by a scan: every second the agent was acknowledged for): an instructor rewinds it.
  const std::optional<SessionRow> row = core.hub->Get(id);
  if (!row) {
    *refusal = "no session " + id;
    return nullptr;
  }
  return std::make_shared<ReplayEndpoint>(core, core.hub->RecordingPath(*row), id);
}

}  // namespace idms::server
