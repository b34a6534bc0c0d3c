// The I/O thread: one io_context, one WebSocket connection at a time (recreated on every
// attempt), a poll timer that drains the loop's rings, one write in flight, and a pull model
// for what to send next (session events, then the newest surface, then sample batches).
#include "idms/agent/uplink.h"

#include <algorithm>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <deque>
#include <random>
#include <thread>

#include "idms/protocol/envelope.h"
#include "idms/protocol/mesh_codec.h"

namespace idms::agent {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using Clock = std::chrono::steady_clock;

std::chrono::nanoseconds Seconds(double s) { return std::chrono::nanoseconds(static_cast<int64_t>(s * 1e9)); }

// One connection attempt: the stream and its buffers. Handlers hold a shared_ptr, so a dropped
// connection lives until its last pending operation has completed.
struct Connection {
  explicit Connection(asio::io_context& io) : ws(io) {}
  websocket::stream<beast::tcp_stream> ws;
  beast::flat_buffer read_buffer;
  websocket::response_type response;
  std::string out;  // the frame being written
};

enum class Phase { kIdle, kConnecting, kHello, kOnline, kClosing, kDone };

}  // namespace

struct Uplink::Impl {
  Impl(Loop& loop_in, const UplinkOptions& options_in)
      : loop(loop_in),
        opt(options_in),
        signals(io, SIGINT, SIGTERM),
        poll_timer(io),
        retry_timer(io),
        hello_timer(io),
        resolver(io),
        rng(std::random_device{}()),
        encoder(MakeEncoderOptions(options_in.scene)) {
    batch = opt.scene.sample_batch() > 0 ? static_cast<size_t>(opt.scene.sample_batch()) : 20;
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
    // Signals stop the loop; the uplink then flushes and closes.
    WaitSignal();
    Poll();
    if (!opt.offline) Connect();
    io.run();
    if (!loop.finished()) {
      loop.RequestStop();
      while (!loop.finished()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
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
    stats.samples_unsent = backlog.size() - cursor;
    if (pending_mesh >= 0) loop.ReleaseMeshSlot(pending_mesh), pending_mesh = -1;
    io.stop();
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
    backlog.push_back(s);
    // Bounded: the oldest goes; one the server never got is a drop, counted and reported.
    if (static_cast<int64_t>(backlog.size()) > opt.backlog_samples) {
      if (cursor == 0) {
        ++stats.samples_dropped;
        ++dropped_unreported;
      } else {
        evicted_sent_max = backlog.front().tick;
        has_evicted_sent = true;
        --cursor;
      }
      backlog.pop_front();
    }
  }

  // ------------------------------------------------------------------------------------------
  // Connecting: resolve, TCP, WebSocket upgrade with the token, Hello -> Welcome.

  void Connect() {
    phase = Phase::kConnecting;
    auto c = std::make_shared<Connection>(io);
    conn = c;
    resolver.async_resolve(opt.host, opt.port,
                           [this, c](const beast::error_code& ec, tcp::resolver::results_type results) {
                             if (c != conn) return;
                             if (ec) return ConnectFailed(ec, "resolve " + opt.host);
                             beast::get_lowest_layer(c->ws).expires_after(Seconds(opt.connect_timeout_s));
                             beast::get_lowest_layer(c->ws).async_connect(
                                 results, [this, c](const beast::error_code& ec2, const tcp::endpoint&) {
                                   if (c != conn) return;
                                   if (ec2) return ConnectFailed(ec2, "connect");
                                   Upgrade(c);
                                 });
                           });
  }

  void Upgrade(const std::shared_ptr<Connection>& c) {
    // The token travels on the upgrade request, so a bad one is refused before any frame.
    const std::string auth = "Bearer " + opt.token;
    c->ws.set_option(websocket::stream_base::decorator([auth](websocket::request_type& req) {
      req.set(http::field::authorization, auth);
      req.set(http::field::user_agent, "idms-agent");
    }));
    c->ws.async_handshake(c->response, opt.host + ":" + opt.port, opt.target, [this, c](const beast::error_code& ec) {
      if (c != conn) return;
      if (ec) {
        const unsigned status = c->response.result_int();
        if (status == 401 || status == 403) {
          return Fatal("the server refused the token (HTTP " + std::to_string(status) + " " +
                       std::string(c->response.reason()) + " on " + opt.target + "): check --token");
        }
        if (status == 400 || status == 404) {
          return Fatal("the server refused the WebSocket upgrade on " + opt.target + " (HTTP " +
                       std::to_string(status) + "): is --server an idms-server?");
        }
        return ConnectFailed(ec, status != 0 ? "WebSocket upgrade (HTTP " + std::to_string(status) + ")"
                                             : std::string("WebSocket upgrade"));
      }
      // From here the WebSocket's own timeouts apply: pings when idle, a dead peer detected.
      beast::get_lowest_layer(c->ws).expires_never();
      websocket::stream_base::timeout timeouts{Seconds(opt.connect_timeout_s), std::chrono::seconds(10), true};
      c->ws.set_option(timeouts);
      c->ws.binary(true);
      SendHello(c);
    });
  }

  void SendHello(const std::shared_ptr<Connection>& c) {
    phase = Phase::kHello;
    v1::Envelope envelope;
    v1::Hello* hello = envelope.mutable_hello();
    hello->set_protocol_version(kProtocolVersion);
    hello->set_role(v1::ROLE_AGENT);
    hello->set_identity(opt.identity);
    hello->set_session_id(session_id);
    hello->set_resume_token(resume_token);
    *hello->mutable_scene() = opt.scene;
    SerializeEnvelope(envelope, &c->out);
    // The Welcome must come within the connect timeout.
    hello_timer.expires_after(Seconds(opt.connect_timeout_s));
    hello_timer.async_wait([this, c](const beast::error_code& ec) {
      if (!ec && c == conn && phase == Phase::kHello) ConnectFailed(asio::error::timed_out, "waiting for Welcome");
    });
    c->ws.async_write(asio::buffer(c->out), [this, c](const beast::error_code& ec, size_t) {
      if (c != conn) return;
      if (ec) return ConnectFailed(ec, "send Hello");
      c->ws.async_read(c->read_buffer, [this, c](const beast::error_code& ec2, size_t) {
        if (c != conn) return;
        if (ec2) return ConnectFailed(ec2, "read Welcome");
        OnWelcomeFrame(c);
      });
    });
  }

  void OnWelcomeFrame(const std::shared_ptr<Connection>& c) {
    hello_timer.cancel();
    v1::Envelope envelope;
    std::string error;
    const bool parsed = ParseEnvelope(beast::buffers_to_string(c->read_buffer.data()), &envelope, &error);
    c->read_buffer.consume(c->read_buffer.size());
    if (!parsed) return Fatal("the server's answer to Hello is not an Envelope: " + error);
    if (envelope.has_session_event() && envelope.session_event().kind() == v1::SessionEvent::KIND_ERROR) {
      // A refused resume (the server lost the session): start a new one; a refused new session is final.
      if (!session_id.empty()) {
        std::fprintf(stderr, "idms-agent: the server refused to resume session %s (%s); starting a new session\n",
                     session_id.c_str(), envelope.session_event().message().c_str());
        session_id.clear();
        resume_token.clear();
        return ConnectFailed(asio::error::connection_refused, "resume");
      }
      return Fatal("the server refused the session: " + envelope.session_event().message());
    }
    if (!envelope.has_welcome()) {
      return Fatal(std::string("expected Welcome after Hello, got ") + EnvelopeBodyName(envelope));
    }
    OnWelcome(envelope.welcome());
    phase = Phase::kOnline;
    backoff_s = opt.backoff_initial_s;
    DoRead(c);
    MaybeWrite();
  }

  void OnWelcome(const v1::Welcome& welcome) {
    const bool resumed = !session_id.empty() && welcome.session_id() == session_id;
    if (resumed) {
      // Resend from the first tick the server does not have.
      ++stats.reconnects;
      const uint64_t next = welcome.next_tick();
      if (!backlog.empty() && next < backlog.front().tick && has_evicted_sent) {
        // Sent before the drop, lost in flight, and no longer kept.
        const uint64_t lost =
            std::min(backlog.front().tick, evicted_sent_max + 1) - std::min(next, evicted_sent_max + 1);
        stats.samples_dropped += lost;
        dropped_unreported += lost;
      }
      const auto it = std::lower_bound(backlog.begin(), backlog.end(), next,
                                       [](const TickSample& s, uint64_t tick) { return s.tick < tick; });
      cursor = static_cast<size_t>(it - backlog.begin());
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
    if (dropped_unreported == 0) return;
    v1::Envelope envelope;
    v1::SessionEvent* event = envelope.mutable_session_event();
    event->set_kind(v1::SessionEvent::KIND_SAMPLES_DROPPED);
    event->set_tick(backlog.empty() ? last_tick : backlog.front().tick);
    event->set_count(dropped_unreported);
    event->set_message("agent backlog overflowed while the server was unreachable; oldest samples dropped");
    control.push_back(std::move(envelope));
    dropped_unreported = 0;
  }

  void ConnectFailed(const beast::error_code& ec, const std::string& what) {
    ++stats.connect_failures;
    LostConnection(ec, what);
  }

  // Drops the connection and schedules the next attempt after the backoff.
  void LostConnection(const beast::error_code& ec, const std::string& what) {
    const bool was_online = phase == Phase::kOnline || phase == Phase::kClosing;
    DropConnection();
    phase = Phase::kIdle;
    if (ec != asio::error::operation_aborted) {
      std::fprintf(stderr, "idms-agent: server %s:%s: %s%s: %s; retrying in %.2f s\n", opt.host.c_str(),
                   opt.port.c_str(), was_online ? "connection lost during " : "", what.c_str(), ec.message().c_str(),
                   backoff_s);
    }
    std::uniform_real_distribution<double> jitter(0.8, 1.2);
    retry_timer.expires_after(Seconds(backoff_s * jitter(rng)));
    backoff_s = std::min(2 * backoff_s, opt.backoff_max_s);
    retry_timer.async_wait([this](const beast::error_code& e) {
      if (!e && phase == Phase::kIdle && stats.fatal_error.empty()) Connect();
    });
  }

  void DropConnection() {
    if (conn) {
      beast::error_code ignored;
      beast::get_lowest_layer(conn->ws).socket().close(ignored);
      conn.reset();
    }
    write_in_flight = false;
    hello_timer.cancel();
  }

  // ------------------------------------------------------------------------------------------
  // Online: reading commands, writing frames.

  void DoRead(const std::shared_ptr<Connection>& c) {
    c->ws.async_read(c->read_buffer, [this, c](const beast::error_code& ec, size_t) {
      if (c != conn) return;
      if (ec) {
        // The server's close frame after ours: the session ended cleanly.
        if (phase == Phase::kClosing && ec == websocket::error::closed) return;
        return LostConnection(ec, "read");
      }
      v1::Envelope envelope;
      std::string error;
      const bool parsed = ParseEnvelope(beast::buffers_to_string(c->read_buffer.data()), &envelope, &error);
      c->read_buffer.consume(c->read_buffer.size());
      if (parsed)
        OnServerFrame(envelope);
      else
        std::fprintf(stderr, "idms-agent: ignored a malformed frame from the server: %s\n", error.c_str());
      DoRead(c);
    });
  }

  void OnServerFrame(const v1::Envelope& envelope) {
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
        lc.kind = LoopCommand::kReset;
        break;
      case v1::Command::KIND_KEYFRAME_REQUEST:
        encoder.RequestKeyframe();
        return;
      default:
        return;
    }
    if (!loop.PushCommand(lc))
      std::fprintf(stderr, "idms-agent: command %llu dropped: the loop's command ring is full\n",
                   static_cast<unsigned long long>(command.id()));
  }

  // Builds the next frame, if any, into conn->out. Order: events, surface, samples.
  bool NextFrame() {
    v1::Envelope& envelope = scratch;
    ReportDrops();
    if (!control.empty()) {
      SerializeEnvelope(control.front(), &conn->out);
      control.pop_front();
      return true;
    }
    // The newest surface; after a reconnection with nothing newer coming (the loop has ended),
    // the last one again, so the server's mirror ends on the final surface.
    if (pending_mesh >= 0 || resend_surface) {
      if (pending_mesh >= 0) {
        const MeshSlot& slot = loop.slot(pending_mesh);
        last_surface.assign(slot.pos.begin(), slot.pos.end());
        last_surface_time_s = slot.time_s;
        loop.ReleaseMeshSlot(pending_mesh);
        pending_mesh = -1;
      }
      resend_surface = false;
      std::string error;
      EncodeStats es;
      envelope.Clear();
      if (encoder.Encode(last_surface_time_s, last_surface, &envelope, &error, &es)) {
        ++stats.mesh_frames;
        stats.keyframes += es.keyframe ? 1 : 0;
        stats.mesh_bytes += static_cast<uint64_t>(es.payload_bytes);
        SerializeEnvelope(envelope, &conn->out);
        return true;
      }
      std::fprintf(stderr, "idms-agent: surface frame not sent: %s\n", error.c_str());
    }
    const size_t unsent = backlog.size() - cursor;
    if (unsent >= batch || (unsent > 0 && loop_finished)) {
      envelope.Clear();
      v1::DeviceSamples* batch_msg = envelope.mutable_device_samples();
      const size_t n = std::min(unsent, batch);
      for (size_t i = 0; i < n; ++i) AddSample(backlog[cursor + i], batch_msg->add_samples());
      cursor += n;
      FillStats(batch_msg->mutable_stats());
      batch_msg->set_samples_dropped(stats.samples_dropped);
      SerializeEnvelope(envelope, &conn->out);
      return true;
    }
    return false;
  }

  void AddSample(const TickSample& s, v1::DeviceSample* out) {
    if (!has_sent || s.tick > highest_sent) {
      ++stats.samples_sent;
      highest_sent = s.tick;
      has_sent = true;
    } else {
      ++stats.samples_resent;
    }
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
    out->set_grasp(s.grasp);
    out->set_substeps(s.substeps);
    out->set_warnings(s.warnings);
    out->set_num_contacts(s.num_contacts);
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
  }

  void MaybeWrite() {
    if (phase != Phase::kOnline || write_in_flight || !conn) return;
    if (!NextFrame()) {
      // Nothing left and the loop is done: say goodbye and close.
      if (loop_finished && pending_mesh < 0 && cursor == backlog.size()) SendEnded();
      return;
    }
    StartWrite();
  }

  void StartWrite() {
    write_in_flight = true;
    auto c = conn;
    c->ws.async_write(asio::buffer(c->out), [this, c](const beast::error_code& ec, size_t) {
      if (c != conn) return;
      write_in_flight = false;
      if (ec) return LostConnection(ec, "write");
      if (phase == Phase::kClosing) return Close(c);
      MaybeWrite();
    });
  }

  void SendEnded() {
    v1::Envelope envelope;
    v1::SessionEvent* event = envelope.mutable_session_event();
    event->set_kind(v1::SessionEvent::KIND_ENDED);
    event->set_tick(last_tick);
    event->set_message("the agent stopped");
    SerializeEnvelope(envelope, &conn->out);
    phase = Phase::kClosing;
    StartWrite();
  }

  void Close(const std::shared_ptr<Connection>& c) {
    c->ws.async_close(websocket::close_code::normal, [this, c](const beast::error_code& ec) {
      if (c != conn) return;
      stats.ended_cleanly = !ec;
      if (ec) std::fprintf(stderr, "idms-agent: closing the session: %s\n", ec.message().c_str());
      Done();
    });
  }

  // ------------------------------------------------------------------------------------------
  Loop& loop;
  UplinkOptions opt;
  UplinkStats stats;

  asio::io_context io;  // before the objects that use it, so it is destroyed after them
  asio::signal_set signals;
  asio::steady_timer poll_timer, retry_timer, hello_timer;
  tcp::resolver resolver;
  std::shared_ptr<Connection> conn;
  Phase phase = Phase::kIdle;
  bool write_in_flight = false;
  double backoff_s = 0.1;
  std::minstd_rand rng;

  // Session.
  std::string session_id, resume_token;
  std::deque<v1::Envelope> control;  // session events waiting to be sent
  v1::Envelope scratch;

  // Samples: the backlog holds sent and unsent ones; [cursor, end) are unsent.
  std::deque<TickSample> backlog;
  size_t cursor = 0;
  size_t batch = 20;
  uint64_t highest_sent = 0, evicted_sent_max = 0, last_tick = 0, dropped_unreported = 0;
  bool has_sent = false, has_evicted_sent = false;
  uint64_t warnings_unreported = 0;
  double warned_time_s = 0;
  bool has_warned = false;

  // Surface.
  MeshEncoder encoder;
  int32_t pending_mesh = -1;
  std::vector<double> last_surface;  // (num_external x 3): the last surface encoded
  double last_surface_time_s = 0;
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
