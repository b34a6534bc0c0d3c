// The I/O thread: one io_context, one Connection at a time (a new one per attempt), a poll timer
// that drains the loop's rings into the Backlog, one write in flight, and a pull model for what
// to send next (FrameOrder: session events, then the newest surface, then sample batches).
#include "idms/agent/uplink.h"

#include <algorithm>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <deque>
#include <optional>
#include <random>
#include <thread>

#include "backlog.h"
#include "connection.h"
#include "frame_order.h"
#include "idms/agent/thread_owner.h"
#include "idms/protocol/envelope.h"
#include "idms/protocol/mesh_codec.h"

namespace idms::agent {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
using Clock = std::chrono::steady_clock;

std::chrono::nanoseconds Seconds(double s) { return std::chrono::nanoseconds(static_cast<int64_t>(s * 1e9)); }

enum class Phase { kIdle, kConnecting, kHello, kOnline, kClosing, kDone };

ConnectionOptions MakeConnectionOptions(const UplinkOptions& o) {
  ConnectionOptions c;
  c.host = o.host;
  c.port = o.port;
  c.target = o.target;
  c.token = o.token;
  c.connect_timeout_s = o.connect_timeout_s;
  c.idle_timeout_s = o.idle_timeout_s;
  return c;
}

}  // namespace

struct Uplink::Impl final : ConnectionHandler {
  Impl(Loop& loop_in, const UplinkOptions& options_in)
      : loop(loop_in),
        opt(options_in),
        connection_options(MakeConnectionOptions(options_in)),
        signals(io, SIGINT, SIGTERM),
        poll_timer(io),
        retry_timer(io),
        hello_timer(io),
        rng(std::random_device{}()),
        backlog(options_in.backlog_samples),
        order(options_in.scene.sample_batch()),
        encoder(MakeEncoderOptions(options_in.scene)) {
    backoff_s = opt.backoff_initial_s;
    // The surface triangles as the loop starts with them.
    const Model& model = loop.model();
    encoder.SetTopology(model.topology_version, SurfaceTriangles(model));
  }

  static EncoderOptions MakeEncoderOptions(const v1::Scene& scene) {
    EncoderOptions e;
    if (scene.has_quant_step()) e.quant_step = scene.quant_step();
    if (scene.has_keyframe_interval_s()) e.keyframe_interval_s = scene.keyframe_interval_s();
    return e;
  }

  // ------------------------------------------------------------------------------------------
  // Start, poll, finish.

  bool Run() {
    io_thread.Check("Uplink::Run");
    // Signals stop the loop; the uplink then flushes and closes.
    WaitSignal();
    Poll();
    if (!opt.offline) Connect();
    io.run();
    SyncStats();
    if (!loop.finished()) {
      loop.RequestStop();
      while (!loop.finished()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    loop.CollectResets();
    return stats.fatal_error.empty();
  }

  void WaitSignal() {
    signals.async_wait([this](const beast::error_code& ec, int signal) {
      if (ec) return;
      std::fprintf(stderr, "idms-agent: %s: stopping after the current tick\n",
                   signal == SIGINT ? "SIGINT" : "SIGTERM");
      loop.RequestStop();
      WaitSignal();
    });
  }

  void Poll() {
    io_thread.Check("Uplink poll");
    Drain();
    const auto now = Clock::now();
    if (!loop_finished && loop.finished()) {
      loop_finished = true;
      finish_time = now;
      Drain();  // everything the loop published before it finished
    }
    if (loop_finished) {
      if (!stats.fatal_error.empty() || opt.offline) return Done();
      if (now - finish_time > Seconds(opt.flush_timeout_s)) {
        std::fprintf(stderr, "idms-agent: gave up delivering to the server after %.1f s\n", opt.flush_timeout_s);
        return Done();
      }
    }
    MaybeWrite();
    poll_timer.expires_after(Seconds(opt.poll_interval_s));
    poll_timer.async_wait([this](const beast::error_code& ec) {
      if (!ec && phase != Phase::kDone) Poll();
    });
  }

  void Done() {
    if (phase == Phase::kDone) return;
    phase = Phase::kDone;
    SyncStats();
    if (pending_mesh >= 0) loop.ReleaseMeshSlot(pending_mesh), pending_mesh = -1;
    io.stop();
  }

  // The backlog's counts into the stats.
  void SyncStats() {
    stats.samples_sent = backlog.num_sent();
    stats.samples_resent = backlog.num_resent();
    stats.samples_dropped = backlog.num_dropped();
    stats.samples_unsent = backlog.num_unsent();
  }

  void Fatal(const std::string& message) {
    stats.fatal_error = message;
    std::fprintf(stderr, "idms-agent: error: %s\n", message.c_str());
    DropConnection();
    loop.RequestStop();
    phase = Phase::kIdle;  // Poll ends the run once the loop has finished
  }

  // ------------------------------------------------------------------------------------------
  // Rings -> backlog and the pending surface.

  void Drain() {
    loop.samples().consume_all([this](const TickSample& s) { Accept(s); });
    loop.CollectResets();  // sets replaced by resets are freed here, not on the loop
    int32_t index = -1;
    while (loop.PopMeshSlot(&index)) {
      const MeshSlot& slot = loop.slot(index);
      // A topology change must reach the encoder even when its frame is skipped.
      if (slot.num_tris >= 0) {
        encoder.SetTopology(slot.topology_version,
                            std::span<const int32_t>(slot.tri_verts.data(), 3 * static_cast<size_t>(slot.num_tris)));
      }
      // Latest wins: an older surface not yet sent is replaced by the newer one.
      if (pending_mesh >= 0) loop.ReleaseMeshSlot(pending_mesh);
      pending_mesh = index;
      if (opt.offline) loop.ReleaseMeshSlot(index), pending_mesh = -1;
    }
  }

  void Accept(const TickSample& s) {
    ++stats.samples_received;
    // The loop's own histograms stay on its thread; these mirror them from every sample.
    if (s.period_us > 0) period_hist.Add(s.period_us);
    compute_hist.Add(s.compute_us);
    if (s.overrun) ++overruns;
    last_tick = s.tick;
    last_time_s = s.time_s;
    if (opt.offline) return;
    // Numerical warnings become a session event, at most one a second with the count since.
    warnings_unreported += s.warnings;
    if (warnings_unreported > 0 && (!has_warned || s.time_s - warned_time_s >= 1.0) && control.size() < 64) {
      v1::Envelope envelope;
      v1::SessionEvent* event = envelope.mutable_session_event();
      event->set_kind(v1::SessionEvent::KIND_WARNING);
      event->set_tick(s.tick);
      event->set_time_s(s.time_s);
      event->set_count(warnings_unreported);
      event->set_message("numerical warnings in the step (non-finite input or state, rollback, clamp or zeroed force)");
      control.push_back(std::move(envelope));
      warnings_unreported = 0;
      warned_time_s = s.time_s;
      has_warned = true;
    }
    // The device force at its limit: an event when it gets there, at most one per 0.5 s (a hand
    // held at the limit clamps every tick), counting the clamped ticks since the last event.
    if (s.force_limited) {
      ++limited_unreported;
      if ((!has_limited_event || s.time_s - limited_event_time_s >= 0.5) && control.size() < 64) {
        v1::Envelope envelope;
        v1::SessionEvent* event = envelope.mutable_session_event();
        event->set_kind(v1::SessionEvent::KIND_FORCE_LIMIT);
        event->set_tick(s.tick);
        event->set_time_s(s.time_s);
        event->set_count(limited_unreported);
        char text[96];
        std::snprintf(text, sizeof text, "the device force reached its limit (%g) and was clamped",
                      opt.scene.device().max_force());
        event->set_message(text);
        control.push_back(std::move(envelope));
        limited_unreported = 0;
        limited_event_time_s = s.time_s;
        has_limited_event = true;
      }
    }
    // A reset (an admin's command, applied by the loop) and the tweezers taking and letting go of
    // an atom are events at their tick, for the event list and the replay's timeline.
    if (s.reset)
      Event(s, v1::SessionEvent::KIND_RESET, "the model was reset to rest (the device force eases to the new contact)");
    if (s.grasp != grasping) {
      Event(s, s.grasp ? v1::SessionEvent::KIND_GRASP : v1::SessionEvent::KIND_RELEASE,
            s.grasp ? "the tweezers took hold of an atom" : "the tweezers let go");
      grasping = s.grasp;
    }
    if (s.needle_punctured != needle_in) {
      Event(s, s.needle_punctured ? v1::SessionEvent::KIND_NEEDLE_IN : v1::SessionEvent::KIND_NEEDLE_OUT,
            s.needle_punctured ? "the needle punctured the surface and went in" : "the needle came out");
      needle_in = s.needle_punctured;
    }
    // Through the far side, the thread drawn through a point, a knot, a break.
    if (s.needle_exited && !needle_out)
      Event(s, v1::SessionEvent::KIND_NEEDLE_EXIT, "the needle's tip came out through the far side");
    needle_out = s.needle_exited;
    if (s.suture_new_punctures > 0) {
      Event(s, v1::SessionEvent::KIND_THREAD_PUNCTURE, "the needle drew its thread through", s.suture_punctures);
    }
    if (s.suture_tied) Event(s, v1::SessionEvent::KIND_TIE, "a knot was tied on the stitch", s.suture_ties);
    if (s.suture_tie_refused) {
      Event(s, v1::SessionEvent::KIND_TIE, "no knot: the thread has not passed through two points since the last knot",
            s.suture_ties);
    }
    if (s.suture_broke) Event(s, v1::SessionEvent::KIND_THREAD_BREAK, "the suture thread parted above its strength");
    // Bounded: the oldest goes; one the server never got is a drop, counted and reported.
    backlog.Accept(s);
  }

  // An event from the loop's sample at its tick and time (the control queue is bounded: beyond 64
  // waiting, it is dropped).
  void Event(const TickSample& s, v1::SessionEvent::Kind kind, const char* message, uint64_t count = 0) {
    if (control.size() >= 64) return;
    v1::Envelope envelope;
    v1::SessionEvent* event = envelope.mutable_session_event();
    event->set_kind(kind);
    event->set_tick(s.tick);
    event->set_time_s(s.time_s);
    event->set_message(message);
    if (count > 0) event->set_count(count);
    control.push_back(std::move(envelope));
  }

  // ------------------------------------------------------------------------------------------
  // Connecting: the Connection resolves, connects and upgrades with the token; then Hello -> Welcome.

  void Connect() {
    phase = Phase::kConnecting;
    conn = std::make_shared<Connection>(io, connection_options, *this);
    conn->Start();
  }

  void OnOpen() override {
    io_thread.Check("Uplink::OnOpen");
    phase = Phase::kHello;
    v1::Envelope envelope;
    v1::Hello* hello = envelope.mutable_hello();
    hello->set_protocol_version(kProtocolVersion);
    hello->set_role(v1::ROLE_AGENT);
    hello->set_identity(opt.identity);
    hello->set_trainee(opt.trainee);
    hello->set_device(opt.device);
    hello->set_session_id(session_id);
    hello->set_resume_token(resume_token);
    *hello->mutable_scene() = opt.scene;
    SerializeEnvelope(envelope, &frame);
    // The Welcome must come within the connect timeout.
    hello_timer.expires_after(Seconds(opt.connect_timeout_s));
    hello_timer.async_wait([this, c = conn.get()](const beast::error_code& ec) {
      if (!ec && c == conn.get() && phase == Phase::kHello) Retry(asio::error::timed_out, "waiting for Welcome");
    });
    StartWrite();
  }

  void OnMessage(std::string_view payload) override {
    io_thread.Check("Uplink::OnMessage");
    if (phase == Phase::kHello) return OnWelcomeFrame(payload);
    v1::Envelope envelope;
    std::string error;
    if (ParseEnvelope(payload, &envelope, &error)) {
      OnServerFrame(envelope);
    } else {
      std::fprintf(stderr, "idms-agent: ignored a malformed frame from the server: %s\n", error.c_str());
    }
  }

  void OnWelcomeFrame(std::string_view payload) {
    hello_timer.cancel();
    v1::Envelope envelope;
    std::string error;
    if (!ParseEnvelope(payload, &envelope, &error)) {
      return Fatal("the server's answer to Hello is not an Envelope: " + error);
    }
    const v1::SessionEvent::Kind refusal =
        envelope.has_session_event() ? envelope.session_event().kind() : v1::SessionEvent::KIND_UNSPECIFIED;
    if (refusal == v1::SessionEvent::KIND_RESUME_LATER) {
      // The session is being closed on the server (its recording finishing): ask again shortly.
      // When the server says when to ask again (another server's lease lapsing), then.
      const uint32_t after_ms = envelope.session_event().retry_after_ms();
      return Retry(asio::error::try_again, "resume (" + envelope.session_event().message() + ")",
                   after_ms > 0 ? std::optional<double>(std::min(1e-3 * after_ms, opt.backoff_max_s)) : std::nullopt);
    }
    if (refusal == v1::SessionEvent::KIND_ENDED) {
      // The session is complete. After our ENDED that is the final word we were waiting for (its
      // Ack was lost with the connection); otherwise it ended without us: start a new one.
      if (ended_sent) {
        stats.ended_cleanly = true;
        DropConnection();
        return Done();
      }
      std::fprintf(stderr, "idms-agent: session %s has ended on the server; starting a new session\n",
                   session_id.c_str());
      session_id.clear();
      resume_token.clear();
      return Retry(asio::error::connection_refused, "resume");
    }
    if (refusal == v1::SessionEvent::KIND_ERROR) {
      // A refused resume (the server lost the session): start a new one; a refused new session is final.
      if (!session_id.empty()) {
        std::fprintf(stderr, "idms-agent: the server refused to resume session %s (%s); starting a new session\n",
                     session_id.c_str(), envelope.session_event().message().c_str());
        session_id.clear();
        resume_token.clear();
        return Retry(asio::error::connection_refused, "resume");
      }
      return Fatal("the server refused the session: " + envelope.session_event().message());
    }
    if (!envelope.has_welcome()) {
      return Fatal(std::string("expected Welcome after Hello, got ") + EnvelopeBodyName(envelope));
    }
    OnWelcome(envelope.welcome());
    phase = Phase::kOnline;
    backoff_s = opt.backoff_initial_s;
    MaybeWrite();
  }

  void OnWelcome(const v1::Welcome& welcome) {
    const bool resumed = !session_id.empty() && welcome.session_id() == session_id;
    if (resumed) {
      // Resend from the first tick the server does not have.
      ++stats.reconnects;
      const uint64_t next = welcome.next_tick();
      backlog.ResumeAt(next);
      std::fprintf(stderr, "idms-agent: resumed session %s at tick %llu\n", session_id.c_str(),
                   static_cast<unsigned long long>(next));
    } else {
      if (!session_id.empty()) {
        std::fprintf(stderr, "idms-agent: the server could not resume session %s; continuing as session %s\n",
                     session_id.c_str(), welcome.session_id().c_str());
      }
      session_id = welcome.session_id();
      stats.session_id = session_id;
    }
    if (!welcome.resume_token().empty()) resume_token = welcome.resume_token();
    // Receivers of this connection start from a keyframe.
    encoder.RequestKeyframe();
    resend_surface = loop_finished && !last_surface.empty();
    ReportDrops();
  }

  void ReportDrops() {
    const uint64_t dropped = backlog.TakeUnreportedDrops();
    if (dropped == 0) return;
    v1::Envelope envelope;
    v1::SessionEvent* event = envelope.mutable_session_event();
    event->set_kind(v1::SessionEvent::KIND_SAMPLES_DROPPED);
    event->set_tick(backlog.empty() ? last_tick : backlog.front_tick());
    event->set_count(dropped);
    event->set_message("agent backlog overflowed while the server was unreachable; oldest samples dropped");
    control.push_back(std::move(envelope));
  }

  // The connection failed: a refusal of the token or of the upgrade is final, anything else is
  // retried.
  void OnFailed(const beast::error_code& ec, const char* what,
                const beast::websocket::response_type& upgrade) override {
    io_thread.Check("Uplink::OnFailed");
    const std::string step = what;
    const unsigned status = upgrade.result_int();
    if (step == "WebSocket upgrade") {
      if (status == 401 || status == 403) {
        return Fatal("the server refused the token (HTTP " + std::to_string(status) + " " +
                     std::string(upgrade.reason()) + " on " + opt.target + "): check --token");
      }
      if (status == 400 || status == 404) {
        return Fatal("the server refused the WebSocket upgrade on " + opt.target + " (HTTP " + std::to_string(status) +
                     "): is --server an idms-server?");
      }
      if (status != 0) return Retry(ec, step + " (HTTP " + std::to_string(status) + ")");
    }
    if (phase == Phase::kHello) return Retry(ec, step == "write" ? "send Hello" : "read Welcome");
    // The server closes after its final Ack: the session has ended cleanly.
    if (phase == Phase::kClosing && stats.ended_cleanly) {
      DropConnection();
      return Done();
    }
    Retry(ec, step);
  }

  // Drops the connection and schedules the next attempt after the backoff; a connection that
  // never got its Welcome counts as a connect failure.
  // `after_s`: the server named the time (the backoff starts again from its first step after it).
  void Retry(const beast::error_code& ec, const std::string& what, std::optional<double> after_s = std::nullopt) {
    const bool was_online = phase == Phase::kOnline || phase == Phase::kClosing;
    if (phase == Phase::kConnecting || phase == Phase::kHello) ++stats.connect_failures;
    DropConnection();
    phase = Phase::kIdle;
    const double wait_s = after_s.value_or(backoff_s);
    std::fprintf(stderr, "idms-agent: server %s:%s: %s%s: %s; retrying in %.2f s\n", opt.host.c_str(), opt.port.c_str(),
                 was_online ? "connection lost during " : "", what.c_str(), ec.message().c_str(), wait_s);
    std::uniform_real_distribution<double> jitter(0.8, 1.2);
    if (after_s) {
      // Not earlier than named (it would be refused again), a little later at most.
      retry_timer.expires_after(Seconds(wait_s + 0.05 * jitter(rng)));
      backoff_s = opt.backoff_initial_s;
    } else {
      retry_timer.expires_after(Seconds(backoff_s * jitter(rng)));
      backoff_s = std::min(2 * backoff_s, opt.backoff_max_s);
    }
    retry_timer.async_wait([this](const beast::error_code& e) {
      if (!e && phase == Phase::kIdle && stats.fatal_error.empty()) Connect();
    });
  }

  void DropConnection() {
    if (conn) {
      conn->Abandon();
      conn.reset();
    }
    write_in_flight = false;
    hello_timer.cancel();
  }

  // ------------------------------------------------------------------------------------------
  // Online: commands in, frames out.

  void OnServerFrame(const v1::Envelope& envelope) {
    if (envelope.has_ack()) return OnAck(envelope.ack());
    if (envelope.has_session_event() && envelope.session_event().kind() == v1::SessionEvent::KIND_ERROR) {
      std::fprintf(stderr, "idms-agent: server: %s\n", envelope.session_event().message().c_str());
      return;
    }
    if (!envelope.has_command()) return;
    const v1::Command& command = envelope.command();
    ++stats.commands;
    LoopCommand lc;
    lc.tool = command.tool();
    switch (command.kind()) {
      case v1::Command::KIND_TWEEZERS_CLOSE:
        lc.kind = LoopCommand::kTweezersClose;
        break;
      case v1::Command::KIND_TWEEZERS_OPEN:
        lc.kind = LoopCommand::kTweezersOpen;
        break;
      case v1::Command::KIND_RESET:
        lc.kind = LoopCommand::kReset;  // PushCommand copies the rest model here, on this thread
        break;
      case v1::Command::KIND_KEYFRAME_REQUEST:
        encoder.RequestKeyframe();
        return;
      default:
        return;
    }
    if (!loop.PushCommand(lc))
      std::fprintf(stderr, "idms-agent: command %llu dropped: the loop has not taken the previous ones yet\n",
                   static_cast<unsigned long long>(command.id()));
  }

  // The server has stored every tick before ack.next_tick(); a final Ack (after our ENDED) says
  // the recording is finished: the session has ended cleanly, and the close follows.
  void OnAck(const v1::Ack& ack) {
    stats.acked_next_tick = std::max(stats.acked_next_tick, ack.next_tick());
    if (!ack.final() || !ended_sent) return;
    stats.ended_cleanly = true;
    if (phase == Phase::kClosing && !write_in_flight) conn->Close();
  }

  // Sends the next frame FrameOrder picks, if any; ENDED when everything has been delivered.
  void MaybeWrite() {
    if (phase != Phase::kOnline || write_in_flight || !conn) return;
    for (;;) {
      ReportDrops();
      Waiting waiting;
      waiting.events = control.size();
      waiting.surface = pending_mesh >= 0 || resend_surface;
      waiting.samples = backlog.num_unsent();
      if (pending_mesh >= 0) {
        // At most a batch and one more are looked at: FrameOrder only needs to know whether
        // they fit in one batch.
        const uint64_t surface_tick = loop.slot(pending_mesh).tick;
        const size_t limit = std::min(waiting.samples, order.batch() + 1);
        while (waiting.samples_to_surface < limit && backlog.unsent(waiting.samples_to_surface).tick <= surface_tick)
          ++waiting.samples_to_surface;
      }
      waiting.loop_finished = loop_finished;
      const NextFrame next = order.Next(waiting);
      switch (next.kind) {
        case FrameKind::kNone:
          return;
        case FrameKind::kEvent:
          SerializeEnvelope(control.front(), &frame);
          control.pop_front();
          return StartWrite();
        case FrameKind::kSurface:
          if (!EncodeSurface()) continue;  // said on stderr; the samples go instead
          return StartWrite();
        case FrameKind::kSamples:
          EncodeSamples(next.num_samples);
          return StartWrite();
        case FrameKind::kEnded:
          return SendEnded();
      }
    }
  }

  // The newest surface into `frame`; after a reconnection with nothing newer coming (the loop has
  // ended), the last one again, so the server's mirror ends on the final surface.
  bool EncodeSurface() {
    if (pending_mesh >= 0) {
      const MeshSlot& slot = loop.slot(pending_mesh);
      last_surface.assign(slot.pos.begin(), slot.pos.end());
      last_surface_time_s = slot.time_s;
      last_suture.Clear();
      has_suture = slot.suture_nodes > 0;
      if (has_suture) {
        last_suture.mutable_nodes()->Add(slot.suture_pos.begin(), slot.suture_pos.begin() + 3 * slot.suture_nodes);
        last_suture.mutable_punctures()->Add(slot.suture_puncture_pos.begin(),
                                             slot.suture_puncture_pos.begin() + 3 * slot.suture_punctures);
        last_suture.set_ties(static_cast<uint32_t>(slot.suture_ties));
        last_suture.set_broken_segment(slot.suture_broken);
      }
      loop.ReleaseMeshSlot(pending_mesh);
      pending_mesh = -1;
    }
    resend_surface = false;
    std::string error;
    EncodeStats es;
    scratch.Clear();
    if (!encoder.Encode(last_surface_time_s, last_surface, &scratch, &error, &es)) {
      std::fprintf(stderr, "idms-agent: surface frame not sent: %s\n", error.c_str());
      return false;
    }
    if (has_suture) {
      *(scratch.has_mesh_keyframe() ? scratch.mutable_mesh_keyframe()->mutable_suture()
                                    : scratch.mutable_mesh_delta()->mutable_suture()) = last_suture;
    }
    ++stats.mesh_frames;
    stats.keyframes += es.keyframe ? 1 : 0;
    stats.mesh_bytes += static_cast<uint64_t>(es.payload_bytes);
    SerializeEnvelope(scratch, &frame);
    return true;
  }

  // The oldest n unsent samples into `frame` as one DeviceSamples.
  void EncodeSamples(size_t n) {
    scratch.Clear();
    v1::DeviceSamples* batch_msg = scratch.mutable_device_samples();
    for (size_t i = 0; i < n; ++i) AddSample(backlog.unsent(i), batch_msg->add_samples());
    backlog.MarkSent(n);
    FillStats(batch_msg->mutable_stats());
    batch_msg->set_samples_dropped(backlog.num_dropped());
    batch_msg->set_sent_unix_ns(static_cast<uint64_t>(
        std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
            .count()));
    SerializeEnvelope(scratch, &frame);
  }

  static void AddSample(const TickSample& s, v1::DeviceSample* out) {
    out->set_tick(s.tick);
    out->set_time_s(s.time_s);
    out->mutable_tool_pos()->set_x(s.tool_pos[0]);
    out->mutable_tool_pos()->set_y(s.tool_pos[1]);
    out->mutable_tool_pos()->set_z(s.tool_pos[2]);
    out->mutable_force()->set_x(s.force[0]);
    out->mutable_force()->set_y(s.force[1]);
    out->mutable_force()->set_z(s.force[2]);
    out->set_compute_us(s.compute_us);
    out->set_period_us(s.period_us);
    out->set_contact(s.contact);
    out->set_force_limited(s.force_limited);
    out->set_grasp(s.grasp);
    if (s.tie) out->set_tie(true);
    if (s.tool_index != 0) out->set_tool_index(s.tool_index);
    if (s.suture_ties != 0) out->set_suture_ties(s.suture_ties);
    if (s.incision_open > 0) out->set_incision_gap(s.incision_gap), out->set_incision_open(s.incision_open);
    out->set_substeps(s.substeps);
    out->set_warnings(s.warnings);
    out->set_num_contacts(s.num_contacts);
    if (s.friction != FrictionState::kNone) {
      out->mutable_friction_force()->set_x(s.friction_force[0]);
      out->mutable_friction_force()->set_y(s.friction_force[1]);
      out->mutable_friction_force()->set_z(s.friction_force[2]);
      out->set_normal_force(s.normal_force);
      out->set_friction(s.friction == FrictionState::kStick ? v1::FRICTION_STICK : v1::FRICTION_SLIP);
    }
    out->set_port_energy(s.port_energy);
    out->set_port_energy_window(s.port_energy_window);
    out->set_passivity_damping(s.passivity_damping);
    if (s.oriented) {
      v1::Quat* q = out->mutable_tool_orientation();
      q->set_w(s.orientation[0]), q->set_x(s.orientation[1]), q->set_y(s.orientation[2]), q->set_z(s.orientation[3]);
    }
    out->set_needle_punctured(s.needle_punctured);
    out->set_needle_inserted(s.needle_inserted);
  }

  void FillStats(v1::LoopStats* out) {
    // Percentiles walk the buckets: recomputed at most every 100 ms.
    const auto now = Clock::now();
    if (now - stats_time > std::chrono::milliseconds(100) || loop_finished) {
      period_summary = period_hist.Summary();
      compute_summary = compute_hist.Summary();
      stats_time = now;
    }
    out->set_ticks(stats.samples_received);
    out->set_overruns(overruns);
    out->set_period_p50_us(period_summary.p50_us);
    out->set_period_p99_us(period_summary.p99_us);
    out->set_period_p999_us(period_summary.p999_us);
    out->set_period_max_us(period_summary.max_us);
    out->set_compute_p50_us(compute_summary.p50_us);
    out->set_compute_p99_us(compute_summary.p99_us);
    out->set_compute_max_us(compute_summary.max_us);
    out->set_realtime(loop.realtime());
    out->set_passivity_ticks(loop.counters().passivity_ticks.load(std::memory_order_relaxed));
    out->set_passivity_dissipated(loop.counters().passivity_dissipated.load(std::memory_order_relaxed));
  }

  void StartWrite() {
    write_in_flight = true;
    conn->Write(frame);
  }

  void OnWritten() override {
    io_thread.Check("Uplink::OnWritten");
    write_in_flight = false;
    // ENDED went out: the close waits for the server's final Ack (the recording finished).
    if (phase == Phase::kClosing) {
      if (stats.ended_cleanly) conn->Close();
      return;
    }
    MaybeWrite();  // nothing while the Hello waits for its Welcome (phase kHello)
  }

  void SendEnded() {
    v1::Envelope envelope;
    v1::SessionEvent* event = envelope.mutable_session_event();
    event->set_kind(v1::SessionEvent::KIND_ENDED);
    event->set_tick(last_tick);
    event->set_time_s(last_time_s);
    event->set_message("the agent stopped");
    SerializeEnvelope(envelope, &frame);
    phase = Phase::kClosing;
    ended_sent = true;
    StartWrite();
  }

  void OnClosed(const beast::error_code& ec) override {
    io_thread.Check("Uplink::OnClosed");
    if (ec && !stats.ended_cleanly) std::fprintf(stderr, "idms-agent: closing the session: %s\n", ec.message().c_str());
    Done();
  }

  // ------------------------------------------------------------------------------------------
  // The thread that calls Run owns the uplink: its io_context, connection, backlog and encoder.
  // Off the 1 kHz loop, so a call from another thread aborts in every build.
  ThreadOwner io_thread{"the uplink", ThreadOwner::OnViolation::kAbort};
  Loop& loop;
  UplinkOptions opt;
  ConnectionOptions connection_options;
  UplinkStats stats;

  asio::io_context io;  // before the objects that use it, so it is destroyed after them
  asio::signal_set signals;
  asio::steady_timer poll_timer, retry_timer, hello_timer;
  std::shared_ptr<Connection> conn;
  Phase phase = Phase::kIdle;
  bool write_in_flight = false;
  double backoff_s = 0.1;
  std::minstd_rand rng;

  // Session.
  std::string session_id, resume_token;
  bool ended_sent = false;           // our ENDED went out (on some connection)
  std::deque<v1::Envelope> control;  // session events waiting to be sent
  v1::Envelope scratch;
  std::string frame;  // the next frame, serialized

  // Samples.
  Backlog backlog;
  FrameOrder order;
  uint64_t last_tick = 0;
  double last_time_s = 0;           // of the last sample, for ENDED
  uint64_t limited_unreported = 0;  // clamped ticks since the last KIND_FORCE_LIMIT event
  double limited_event_time_s = 0;
  bool has_limited_event = false;
  bool grasping = false;    // the tweezers held an atom in the last sample
  bool needle_in = false;   // the needle was in the tissue in the last sample
  bool needle_out = false;  // ... and out through the far side
  uint64_t warnings_unreported = 0;
  double warned_time_s = 0;
  bool has_warned = false;

  // Surface.
  MeshEncoder encoder;
  int32_t pending_mesh = -1;
  std::vector<double> last_surface;  // (num_external x 3): the last surface encoded
  double last_surface_time_s = 0;
  v1::SutureShape last_suture;  // the thread with the last surface, when it has one
  bool has_suture = false;
  bool resend_surface = false;

  // Loop statistics mirrored from the samples.
  LatencyHistogram period_hist, compute_hist;
  LatencySummary period_summary, compute_summary;
  uint64_t overruns = 0;
  Clock::time_point stats_time{}, finish_time{};
  bool loop_finished = false;
};

Uplink::Uplink(Loop& loop, const UplinkOptions& options) : impl_(std::make_unique<Impl>(loop, options)) {}
Uplink::~Uplink() = default;
bool Uplink::Run() { return impl_->Run(); }
const UplinkStats& Uplink::stats() const { return impl_->stats; }

}  // namespace idms::agent
