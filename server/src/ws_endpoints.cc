// The WebSocket endpoints and their routes: /ws/library (library events), /ws/agent (an agent
// publishing), /ws/session/{id} (a live viewer), /ws/replay/{id} (replay.cc). Each endpoint lives
// on its connection's strand, holds the connection weakly (ws_endpoint.h), checks what arrives at
// the door (frame_checks.h) and posts it to the session's strand.
#include <boost/asio/post.hpp>

#include "frame_checks.h"
#include "idms/protocol/envelope.h"
#include "sessions.h"
#include "ws_endpoint.h"

namespace idms::server {
namespace {

namespace asio = boost::asio;

constexpr uint16_t kPolicyError = 1008;

// /ws/library: library events as JSON text; a client message is a protocol violation.
class LibraryEndpoint : public WsEndpoint, public TextSink, public std::enable_shared_from_this<LibraryEndpoint> {
 public:
  explicit LibraryEndpoint(ServerCore& core) : core_(core) {}
  void OnOpen(std::weak_ptr<WsPeer> peer) override {
    peer_ = std::move(peer);
    core_.Subscribe(this, weak_from_this());
    Send(std::make_shared<const std::string>(R"({"event":"hello","endpoint":"/ws/library"})"));
  }
  void OnMessage(std::string_view, bool) override {
    if (auto p = peer_.lock()) p->Close(kPolicyError, "/ws/library accepts no messages");
  }
  void OnClose() override { core_.Unsubscribe(this); }
  // Any thread (ServerCore::Publish): peer_ is set once in OnOpen, before Subscribe.
  void Send(std::shared_ptr<const std::string> text) override {
    if (auto p = peer_.lock()) p->Send(std::move(text), false);
  }

 private:
  ServerCore& core_;
  std::weak_ptr<WsPeer> peer_;
};

// /ws/agent: a Hello first, then the session's frames, each checked here and posted in order to
// the session's strand (which ignores them once this connection is no longer its agent).
class AgentEndpoint : public WsEndpoint, public std::enable_shared_from_this<AgentEndpoint> {
 public:
  explicit AgentEndpoint(ServerCore& core) : core_(core), id_(core.next_endpoint_id++) {}
  int max_messages_per_s() const override { return 2000; }
  std::chrono::milliseconds idle_timeout() const override { return core_.options.agent_idle_timeout; }
  void OnOpen(std::weak_ptr<WsPeer> peer) override { peer_ = std::move(peer); }

  void OnMessage(std::string_view bytes, bool binary) override {
    auto e = std::make_shared<v1::Envelope>();
    std::string error;
    if (!binary || !ParseEnvelope(bytes, e.get(), &error, core_.options.max_ws_message_bytes)) {
      return Refuse(ErrorEvent(binary ? "malformed frame: " + error : "frames must be binary Envelopes"));
    }
    if (!session_) {
      if (refused_) return;
      if (!e->has_hello()) return Refuse(ErrorEvent("the first frame must be a Hello"));
      const std::shared_ptr<WsPeer> peer = peer_.lock();
      AgentAdmission a = core_.hub->OpenForAgent(e->hello(), peer ? peer->peer() : "?");
      if (!a.session) {
        v1::Envelope refusal;
        *refusal.mutable_session_event() = a.refusal;
        return Refuse(refusal);
      }
      session_ = std::move(a.session);
      return asio::post(session_->strand(),
                        [s = session_, id = id_, p = peer_, resumed = a.resumed, token = std::move(a.resume_token)] {
                          s->AgentAttached(id, p, resumed, token);
                        });
    }
    if (!CheckAgentFrame(*e, &error)) return Refuse(ErrorEvent(error));
    auto raw = std::make_shared<const std::string>(bytes);
    asio::post(session_->strand(), [s = session_, id = id_, e, raw] { s->AgentFrame(id, e, raw); });
  }

  void OnClose() override {
    if (session_) asio::post(session_->strand(), [s = session_, id = id_] { s->AgentDetached(id); });
    session_.reset();
  }

 private:
  // Said to the agent, then the connection closes; an agent attached to a session is detached
  // by the close (AgentDetached), the session and its recording stay.
  void Refuse(const v1::Envelope& event) {
    refused_ = true;
    if (auto p = peer_.lock()) {
      p->Send(Serialized(event), true);
      const uint16_t code = event.session_event().kind() == v1::SessionEvent::KIND_ERROR ? kPolicyError : 1000;
      p->Close(code, event.session_event().message().substr(0, 120));
    }
  }

  ServerCore& core_;
  const uint64_t id_;
  std::weak_ptr<WsPeer> peer_;
  std::shared_ptr<LiveSession> session_;
  bool refused_ = false;
};

// /ws/session/{id}: a live viewer. Its annotations and (admin) commands go to the session; the
// session holds its back-pressure state.
class ViewerEndpoint : public WsEndpoint, public std::enable_shared_from_this<ViewerEndpoint> {
 public:
  ViewerEndpoint(ServerCore& core, std::shared_ptr<WatchedSession> session, Role role)
      : session_(std::move(session)), admin_(role == Role::kAdmin), id_(core.next_endpoint_id++) {}

  void OnOpen(std::weak_ptr<WsPeer> peer) override {
    peer_ = peer;
    asio::post(session_->strand(), [s = session_, id = id_, peer = std::move(peer), admin = admin_,
                                    wanted = drain_wanted_] { s->ViewerAttached(id, peer, admin, wanted); });
  }

  void OnMessage(std::string_view bytes, bool binary) override {
    const std::shared_ptr<WsPeer> peer = peer_.lock();
    if (!peer) return;
    v1::Envelope e;
    std::string error;
    if (!binary || !ParseEnvelope(bytes, &e, &error, 1 << 20)) {
      peer->Send(Serialized(ErrorEvent(binary ? "malformed frame: " + error : "frames must be binary Envelopes")),
                 true);
      return peer->Close(kPolicyError, "malformed frame");
    }
    if (e.has_hello()) return;  // optional: the URL names the session
    if (e.has_annotation()) {
      if (!CheckAnnotation(e.annotation(), &error)) return peer->Send(Serialized(ErrorEvent(error)), true);
      return asio::post(session_->strand(),
                        [s = session_, a = e.annotation(), p = peer->peer()] { s->ViewerNote(a, p); });
    }
    if (e.has_command()) {
      if (!admin_) {
        peer->Send(Serialized(ErrorEvent("command refused: only an admin may send commands to the agent")), true);
        return;
      }
      return asio::post(session_->strand(),
                        [s = session_, c = e.command(), p = peer->peer()] { s->ViewerCommand(c, p); });
    }
    peer->Send(Serialized(ErrorEvent(std::string("unexpected ") + EnvelopeBodyName(e) + " from a viewer")), true);
  }

  void OnDrained() override {
    if (drain_wanted_->exchange(false)) {
      asio::post(session_->strand(), [s = session_, id = id_] { s->ViewerDrained(id); });
    }
  }

  void OnClose() override {
    asio::post(session_->strand(), [s = session_, id = id_] { s->ViewerDetached(id); });
  }

 private:
  std::shared_ptr<WatchedSession> session_;
  const bool admin_;
  const uint64_t id_;
  std::weak_ptr<WsPeer> peer_;
  const std::shared_ptr<std::atomic<bool>> drain_wanted_ = std::make_shared<std::atomic<bool>>(false);
};

}  // namespace

void AppendWebSocketRoutes(ServerCore& core, std::vector<Route>* routes) {
  using P = Permission;
  using V = http::verb;
  ServerCore* c = &core;
  const auto ws = [](const char* pattern, P permission, WsOpener open) {
    Route r{V::get, pattern, permission, false, true, nullptr};
    r.open_websocket = std::move(open);
    return r;
  };
  routes->push_back(ws("/ws/library", P::kRead,
                       [c](const ApiRequest&, std::string*) { return std::make_shared<LibraryEndpoint>(*c); }));
  routes->push_back(ws("/ws/agent", P::kPublish,
                       [c](const ApiRequest&, std::string*) { return std::make_shared<AgentEndpoint>(*c); }));
  routes->push_back(ws("/ws/session/{id}", P::kRead, [c](const ApiRequest& req, std::string* refusal) {
    std::shared_ptr<WatchedSession> s = c->hub->FindForViewer(req.params[0]);
    if (!s || !s->live()) {
      *refusal = "no live session " + req.params[0];
      return std::shared_ptr<WsEndpoint>();
    }
    return std::shared_ptr<WsEndpoint>(std::make_shared<ViewerEndpoint>(*c, std::move(s), req.role));
  }));
  routes->push_back(ws("/ws/replay/{id}", P::kRead, [c](const ApiRequest& req, std::string* refusal) {
    return MakeReplayEndpoint(*c, req.params[0], refusal);
  }));
}

}  // namespace idms::server
