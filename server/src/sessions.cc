// The hub of live sessions: agents' Hellos opened or resumed, the index kept on a worker strand,
// crashed sessions repaired at start-up, the list, deletes and the sessions' metrics.
#include "sessions.h"

#include <google/protobuf/text_format.h>
#include <openssl/crypto.h>

#include <boost/asio/post.hpp>
#include <filesystem>
#include <future>

#include "frame_checks.h"
#include "idms/protocol/digest.h"
#include "idms/protocol/envelope.h"
#include "idms/server/library.h"
#include "idms/server/log.h"
#include "recordings.h"

namespace idms::server {

namespace asio = boost::asio;
namespace fs = std::filesystem;
using json = nlohmann::json;

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

SessionHub::SessionHub(ServerCore& core, SessionIndex* index, RecordingStore* recordings)
    : core_(core), index_(index), recordings_(recordings), index_strand_(asio::make_strand(core.workers)) {}

void SessionHub::RecoverInterrupted() {
  for (SessionRow row : index_->List()) {
    if (row.state != "live") continue;
    // Several servers on one index: a session another server holds is live there, not ours.
    if (const std::optional<Lease> holder = core_.leases->Holder(row.id);
        holder && holder->holder != core_.options.node_id) {
      continue;
    }
    const std::string live = recordings_->LivePath(row.id);
    const std::string final_path = recordings_->FinishedPath(row.id);
    std::string error;
    // Repair: read what the crash left (the reader recovers by a scan), write a finished file.
    bool recovered = false;
    try {
      recovered = recordings_->Recover(row.id, &error);
    } catch (const StoreUnavailable& e) {
      // Its segments cannot be read now: the session stays live in the index, and the agent's
      // resume (a takeover) or the next start repairs it.
      Log(LogLevel::kWarn, "session left as live: the object store is unavailable",
          {{"session", row.id}, {"error", e.what()}});
      continue;
    }
    if (recovered) {
      RecordingReader probe;
      std::map<std::string, std::string> meta;
      if (probe.Open(live, RecordingReaderOptions{}, &error)) meta = probe.session();
      RecordingWriter writer;
      RecordingWriterOptions options;
      options.session = meta;
      CopyStats stats;
      const std::string tmp = final_path + ".repair";
      error.clear();
      // The repaired file replaces the live one and is published as a finished recording would
      // be (an object store uploads it and deletes the segments).
      if (writer.Open(tmp, options, &error) && CopyRecording(live, &writer, &stats, &error) && writer.Close(&error)) {
        std::error_code ec;
        fs::rename(tmp, live, ec);
        if (!recordings_->Publish(row.id, &error))
          Log(LogLevel::kError, "repaired recording not published", {{"session", row.id}, {"error", error}});
        row.samples = stats.samples;
        row.next_tick = stats.any_tick ? stats.last_tick + 1 : 0;
        // The figures of the whole recording: the row may have been stored a second before the
        // crash, or (a resumed session) hold only what followed an earlier restart.
        const SessionSummary& sum = stats.summary;
        row.duration_s = sum.first_time_s < 0 ? 0 : sum.last_time_s - sum.first_time_s;
        row.summary_json = sum.Json();
      } else {
        Log(LogLevel::kError, "recording not repaired", {{"session", row.id}, {"error", error}});
      }
    }
    row.state = "interrupted";
    row.recording = recordings_->NameFor(row.id, row.state);
    index_->Put(row, &error);
    Log(LogLevel::kInfo, "session interrupted by the last stop; recording repaired",
        {{"session", row.id}, {"samples", row.samples}, {"next_tick", row.next_tick}});
  }
}

namespace {

AgentAdmission Refused(v1::SessionEvent::Kind kind, const std::string& message) {
  AgentAdmission a;
  a.refusal.set_kind(kind);
  a.refusal.set_message(message);
  return a;
}

}  // namespace

AgentAdmission SessionHub::OpenForAgent(const v1::Hello& hello, const std::string& peer) {
  // A resume or a model's limits need the stores: while the database is down, the agent retries.
  try {
    return Admit(hello, peer);
  } catch (const StoreUnavailable& e) {
    return Refused(v1::SessionEvent::KIND_RESUME_LATER, std::string("a store is unavailable; retry: ") + e.what());
  }
}

AgentAdmission SessionHub::Admit(const v1::Hello& hello, const std::string& peer) {
  using K = v1::SessionEvent;
  if (hello.protocol_version() != kProtocolVersion) {
    return Refused(K::KIND_ERROR, "protocol version " + std::to_string(hello.protocol_version()) +
                                      " is not this server's " + std::to_string(kProtocolVersion));
  }
  if (hello.role() != v1::ROLE_AGENT) return Refused(K::KIND_ERROR, "/ws/agent expects Hello.role ROLE_AGENT");
  std::string error;
  if (!CheckAgentHello(hello, &error)) return Refused(K::KIND_ERROR, error);
  std::lock_guard lock(mu_);
  if (!hello.session_id().empty()) {
    // A resume: the session live here, or interrupted (by a restart, or its resume window).
    const std::string digest = Sha256Hex(hello.resume_token());
    std::shared_ptr<LiveSession> s;
    SessionRow row;
    if (auto it = live_.find(hello.session_id()); it != live_.end()) {
      s = it->second;
      row = s->Snapshot();
    } else if (auto r = index_->Get(hello.session_id())) {
      row = *r;
    } else {
      return Refused(K::KIND_ERROR, "unknown session " + hello.session_id());
    }
    if (row.resume_sha256.size() != digest.size() ||
        CRYPTO_memcmp(row.resume_sha256.data(), digest.data(), digest.size()) != 0) {
      return Refused(K::KIND_ERROR, "bad resume token for session " + hello.session_id());
    }
    // Ended: its recording is complete. Ending or closing (not yet stored): ask again shortly.
    if (row.state == "ended") return Refused(K::KIND_ENDED, "session " + row.id + " has ended");
    if (s && !s->live()) return Refused(K::KIND_RESUME_LATER, "session " + row.id + " is being closed; retry");
    if (!s) {
      // Interrupted (its recording finished), or live on another server: ours once its lease is.
      const std::optional<LeaseGrant> lease = TakeLease(row.id);
      if (!lease) {
        const std::optional<Lease> holder = core_.leases->Holder(row.id);
        AgentAdmission later =
            Refused(K::KIND_RESUME_LATER, "session " + row.id + " is live on " +
                                              (holder ? holder->holder : std::string("another server")) +
                                              "; retry (it is taken over once that server's lease lapses)");
        // Asked again just after the lease would lapse, not on the agent's doubling backoff.
        if (holder) later.refusal.set_retry_after_ms(static_cast<uint32_t>(holder->remaining.count()) + 50);
        return later;
      }
      RecordingStart from = RecordingStart::kContinueFinished;
      if (row.state == "live") {
        TakeOver(&row);
        from = RecordingStart::kContinueLive;
      } else if (!recordings_->Fetch(row.id, &error)) {
        // Continued from its finished recording, which may be in the object store only.
        Log(LogLevel::kWarn, "resuming without the recording so far: " + error, {{"session", row.id}});
      }
      row.state = "live";
      row.recording = recordings_->NameFor(row.id, row.state);
      v1::Scene scene;
      google::protobuf::TextFormat::ParseFromString(row.scene_text, &scene);
      s = StartSession(row, scene, from, *lease);
    }
    AgentAdmission a;
    a.session = std::move(s);
    a.resumed = true;
    a.resume_token = hello.resume_token();
    return a;
  }
  // A new session, within the server's bound.
  if (static_cast<int>(live_.size()) >= core_.options.max_live_sessions) {
    return Refused(K::KIND_ERROR, "the server holds its maximum of " + std::to_string(core_.options.max_live_sessions) +
                                      " live sessions (--max-live-sessions); end one, or try another server");
  }
  SessionRow row;
  row.id = UtcNow().substr(0, 10) + "-" + RandomHex(6);
  row.state = "live";
  row.model = !hello.scene().model().empty() ? hello.scene().model() : hello.scene().model_file();
  row.identity = hello.identity();
  row.trainee = hello.trainee();
  row.device = hello.device();
  row.started = UtcNowMs();
  row.recording = recordings_->NameFor(row.id, row.state);
  google::protobuf::TextFormat::PrintToString(hello.scene(), &row.scene_text);
  AgentAdmission a;
  a.resume_token = RandomHex(32);
  row.resume_sha256 = Sha256Hex(a.resume_token);
  const std::optional<LeaseGrant> lease = TakeLease(row.id);
  if (!lease) return Refused(K::KIND_ERROR, "session id " + row.id + " is taken; retry");  // 48 random bits
  a.session = StartSession(row, hello.scene(), RecordingStart::kNew, *lease);
  StoreRow(row);
  Log(LogLevel::kInfo, "session started", {{"session", row.id}, {"model", row.model}, {"peer", peer}});
  return a;
}

DecodeLimits SessionHub::LimitsFor(const v1::Scene& scene) {
  DecodeLimits limits;
  if (scene.model().empty() || core_.ctx.library == nullptr) return limits;
  // "NAME" or "NAME@VERSION".
  std::string name = scene.model();
  int64_t version = 0;
  if (const size_t at = name.find('@'); at != std::string::npos) {
    version = std::atoll(name.c_str() + at + 1);
    name.resize(at);
  }
  const std::optional<ModelVersion> m = core_.ctx.library->Find(name, version);
  if (!m || m->atoms <= 0) return limits;
  // A surface's vertices are atoms; cuts can expose inner atoms, and a surface of V vertices
  // has fewer than 2V triangles (Euler), beyond those the model starts with.
  limits.max_vertices = m->atoms;
  limits.max_triangles = m->triangles + 2 * m->atoms;
  limits.max_decompressed_bytes =
      std::min(limits.max_decompressed_bytes, int64_t{10} * 3 * (limits.max_vertices + limits.max_triangles) + 1024);
  return limits;
}

std::optional<LeaseGrant> SessionHub::TakeLease(const std::string& id) {
  // The lease runs from before it was asked for: this node's deadline is never later than the store's.
  const auto asked = std::chrono::steady_clock::now();
  const std::optional<int64_t> epoch = core_.leases->Acquire(id, core_.options.node_id, core_.options.lease_ttl);
  if (!epoch) return std::nullopt;
  ++leases_taken;
  return LeaseGrant{*epoch, asked + core_.options.lease_ttl};
}

void SessionHub::TakeOver(SessionRow* row) {
  ++takeovers;
  std::string error;
  CopyStats stats;
  if (!recordings_->Recover(row->id, &error) ||
      !CopyRecording(recordings_->LivePath(row->id), nullptr, &stats, &error)) {
    // Recordings in this server's own directory cannot be reached from here: the row's figures
    // (stored once a second by the old owner) stand, and the recording starts again.
    Log(LogLevel::kWarn, "taking over a session without its recording so far: " + error, {{"session", row->id}});
    return;
  }
  row->samples = stats.samples;
  row->next_tick = stats.any_tick ? stats.last_tick + 1 : 0;
  const SessionSummary& sum = stats.summary;
  row->duration_s = sum.first_time_s < 0 ? 0 : sum.last_time_s - sum.first_time_s;
  row->summary_json = sum.Json();
  Log(LogLevel::kInfo, "session taken over", {{"session", row->id}, {"next_tick", row->next_tick}});
}

std::shared_ptr<LiveSession> SessionHub::StartSession(const SessionRow& row, const v1::Scene& scene,
                                                      RecordingStart from, LeaseGrant lease) {
  // Its recording (with the session's id, model and scene as metadata), then the session itself.
  auto recorder =
      std::make_shared<Recorder>(core_.recorder, *recordings_, row.id, &recording_bytes, &recording_failures);
  RecordingWriterOptions options;
  options.session = {{"session_id", row.id}, {"model", row.model}, {"scene", row.scene_text}};
  recorder->Start(options, from);
  auto s = std::make_shared<LiveSession>(core_, *this, row, scene, recorder, LimitsFor(scene), lease);
  s->Start();
  live_[row.id] = s;
  return s;
}

void SessionHub::StoreRow(SessionRow row, std::function<void()> then) {
  asio::post(index_strand_, [this, row = std::move(row), then = std::move(then)] {
    std::string error;
    bool stored = false;
    try {
      stored = index_->Put(row, &error);
    } catch (const StoreUnavailable& e) {  // the database is down: the next update stores the row
      error = e.what();
    }
    if (!stored) Log(LogLevel::kError, "session index", {{"session", row.id}, {"error", error}});
    if (then) then();
  });
}

std::shared_ptr<LiveSession> SessionHub::FindLive(const std::string& id) {
  std::lock_guard lock(mu_);
  const auto it = live_.find(id);
  return it == live_.end() ? nullptr : it->second;
}

std::shared_ptr<WatchedSession> SessionHub::FindForViewer(const std::string& id) {
  if (auto s = FindLive(id)) return s;
  if (bus_ == nullptr) return nullptr;
  std::shared_ptr<RelayedSession> relayed;
  {
    std::lock_guard lock(mu_);
    if (auto it = relayed_.find(id); it != relayed_.end() && it->second->live()) return it->second;
    relayed = std::make_shared<RelayedSession>(core_, *this, *bus_, relay_, id, [this, id](RelayedSession* gone) {
      std::lock_guard l(mu_);
      if (auto it = relayed_.find(id); it != relayed_.end() && it->second.get() == gone) relayed_.erase(it);
    });
    relayed_[id] = relayed;
  }
  std::string error;
  if (!relayed->Start(&error)) {
    Log(LogLevel::kWarn, "cannot relay the session: " + error, {{"session", id}});
    asio::post(relayed->strand(), [relayed] { relayed->Close("the bus refused: cannot watch this session here"); });
    return nullptr;
  }
  return relayed;
}

void SessionHub::Forget(const std::string& id, const LiveSession* session) {
  std::lock_guard lock(mu_);
  if (auto it = live_.find(id); it != live_.end() && it->second.get() == session) live_.erase(it);
}

int SessionHub::live_count() {
  std::lock_guard lock(mu_);
  return static_cast<int>(live_.size());
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

bool SessionHub::SetTrainee(const std::string& id, const std::string& trainee, std::string* error) {
  if (const auto s = FindLive(id)) {
    s->SetTrainee(trainee);
    return true;
  }
  std::lock_guard lock(ended_rows_mu_);
  std::optional<SessionRow> row = index_->Get(id);
  if (!row) return *error = "no session " + id, false;
  row->trainee = trainee;
  return index_->Put(*row, error);
}

std::optional<SessionNote> SessionHub::AddNote(const std::string& id, double time_s, const std::string& text,
                                               const std::string& author, std::string* error, bool* not_found) {
  *not_found = false;
  if (const auto s = FindLive(id)) {
    v1::Annotation note;
    note.set_time_s(time_s);
    note.set_text(text);
    // The promise is shared: a server stopping under the wait never runs the handler.
    auto stamped = std::make_shared<std::promise<std::optional<v1::Annotation>>>();
    auto done = stamped->get_future();
    asio::post(s->strand(), [stamped, note, author, s] { stamped->set_value(s->ViewerAnnotation(note, author)); });
    if (done.wait_for(std::chrono::seconds(5)) != std::future_status::ready) {
      return *error = "session " + id + " did not take the note in 5 s (the server is stopping?)", std::nullopt;
    }
    const std::optional<v1::Annotation> a = done.get();
    if (!a) return *error = "session " + id + " is ending; add the note once it has ended", std::nullopt;
    return SessionNote{a->id(), a->time_s(), a->text(), a->author(), ""};
  }
  std::lock_guard lock(ended_rows_mu_);
  std::optional<SessionRow> row = index_->Get(id);
  if (!row) return *not_found = true, *error = "no session " + id, std::nullopt;
  if (index_->Notes(id).size() >= kMaxAddedNotes) {
    return *error = "session " + id + " has " + std::to_string(kMaxAddedNotes) +
                    " notes added since it ended, the most it keeps",
           std::nullopt;
  }
  SessionSummary summary = SessionSummary::FromJson(row->summary_json);
  const SessionNote note{++summary.notes, time_s, text, author, UtcNow()};
  row->summary_json = summary.Json();
  if (!index_->PutWithNote(*row, note, error)) return std::nullopt;
  return note;
}

std::string SessionHub::RecordingPath(const SessionRow& row) const {
  if (row.state == "live") {
    // Published since the row was read (the row's state follows the file): the finished one.
    std::error_code ec;
    const std::string live = recordings_->LivePath(row.id), finished = recordings_->FinishedPath(row.id);
    return !std::filesystem::exists(live, ec) && std::filesystem::exists(finished, ec) ? finished : live;
  }
  std::string error;
  if (!recordings_->Fetch(row.id, &error))
    Log(LogLevel::kWarn, "recording not fetched", {{"session", row.id}, {"error", error}});
  return recordings_->PathFor(row.id, row.state);
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
  recordings_->Remove(id);
  return index_->Delete(id);
}

void SessionHub::StopAll() {
  std::vector<std::shared_ptr<LiveSession>> all;
  {
    std::lock_guard lock(mu_);
    for (auto& [id, s] : live_) all.push_back(s);
  }
  for (auto& s : all) asio::post(s->strand(), [s] { s->Stop("the server is shutting down"); });
  std::vector<std::shared_ptr<RelayedSession>> relayed;
  {
    std::lock_guard lock(mu_);
    for (auto& [id, s] : relayed_) relayed.push_back(s);
  }
  for (auto& s : relayed) asio::post(s->strand(), [s] { s->Close("the server is shutting down"); });
}

namespace {
std::string Counter(const char* name, const char* help, const std::atomic<uint64_t>& value) {
  return std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " counter\n" + name + " " +
         std::to_string(value.load()) + "\n";
}
}  // namespace

// The relay's lines: only with a bus (a server alone has none of these).
std::string SessionHub::RelayMetrics() {
  if (bus_ == nullptr) return "";
  size_t relayed = 0;
  {
    std::lock_guard lock(mu_);
    relayed = relayed_.size();
  }
  const double lag_sum_s = static_cast<double>(relay_.lag_ns_sum.load()) / 1e9;
  return "# HELP idms_relay_sessions Sessions other servers own that this server relays to its viewers.\n"
         "# TYPE idms_relay_sessions gauge\nidms_relay_sessions " +
         std::to_string(relayed) +
         "\n# HELP idms_bus_connected Whether this server's bus (NATS) connection is up.\n"
         "# TYPE idms_bus_connected gauge\nidms_bus_connected " +
         std::string(bus_->connected ? "1" : "0") + "\n" +
         Counter("idms_bus_published_bytes_total", "Bytes this server published on the bus.", bus_->published_bytes) +
         Counter("idms_bus_received_bytes_total", "Bytes this server received from the bus.", bus_->received_bytes) +
         Counter("idms_bus_publish_failures_total", "Messages the bus refused (closed, or its buffer full).",
                 bus_->publish_failures) +
         Counter("idms_bus_disconnects_total", "Times the bus connection dropped.", bus_->disconnects) +
         Counter("idms_bus_slow_consumer_total", "Times the bus dropped messages for this server (slow consumer).",
                 bus_->slow_consumer_errors) +
         Counter("idms_relay_frames_published_total", "Messages this server published for the sessions it owns.",
                 relay_.frames_published) +
         Counter("idms_relay_frames_relayed_total", "Messages relayed from other servers to viewers here.",
                 relay_.frames_relayed) +
         Counter("idms_relay_gaps_total", "Gaps in a relayed stream (each followed by a resync).", relay_.gaps) +
         Counter("idms_relay_epoch_changes_total", "Relayed sessions that changed owner (a new epoch).",
                 relay_.epoch_changes) +
         Counter("idms_relay_joins_total", "Session states received from owners (a start or a resync).", relay_.joins) +
         "# HELP idms_relay_lag_seconds From the owner's publish to the relay here.\n"
         "# TYPE idms_relay_lag_seconds summary\nidms_relay_lag_seconds_sum " +
         json(lag_sum_s).dump() + "\nidms_relay_lag_seconds_count " + std::to_string(relay_.lag_count.load()) +
         "\n# HELP idms_relay_lag_max_seconds The largest relay lag seen.\n# TYPE idms_relay_lag_max_seconds gauge\n"
         "idms_relay_lag_max_seconds " +
         json(static_cast<double>(relay_.lag_ns_max.load()) / 1e9).dump() + "\n";
}

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
      // Base units (seconds), as Prometheus names want them (promtool check metrics).
      const double p99_s = summary["tick_p99_us"].is_number() ? summary["tick_p99_us"].get<double>() / 1e6 : 0.0;
      p99 += "idms_session_tick_p99_seconds" + label + json(p99_s).dump() + "\n";
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
         Counter("idms_viewer_events_dropped_total", "Events and annotations slow viewers did not get.",
                 events_dropped) +
         Counter("idms_viewer_resyncs_total", "Keyframes sent to put a slow viewer right.", resyncs) +
         Counter("idms_recording_bytes_total", "Bytes written to session recordings (MCAP files).", recording_bytes) +
         Counter("idms_recording_failures_total", "Recordings that stopped on an error (see the log).",
                 recording_failures) +
         Counter("idms_viewer_stalled_closed_total", "Viewers closed for staying stalled.", stalled_closed) +
         Counter("idms_leases_taken_total", "Session leases this server took (new sessions, resumes, takeovers).",
                 leases_taken) +
         Counter("idms_session_takeovers_total", "Live sessions this server took over from another.", takeovers) +
         Counter("idms_leases_lost_total", "Live sessions this server gave up on finding its lease lost (fenced).",
                 leases_lost) +
         RelayMetrics() + recordings_->MetricsText() +
         "# HELP idms_session_samples Device samples received, per live session.\n"
         "# TYPE idms_session_samples gauge\n" +
         samples + "# HELP idms_session_viewers Viewers, per live session.\n# TYPE idms_session_viewers gauge\n" +
         watching +
         "# HELP idms_session_tick_p99_seconds The agent's tick compute time p99, per live session.\n"
         "# TYPE idms_session_tick_p99_seconds gauge\n" +
         p99 +
         "# HELP idms_session_overruns The agent's loop overruns, per live session.\n"
         "# TYPE idms_session_overruns gauge\n" +
         overruns;
}

}  // namespace idms::server
