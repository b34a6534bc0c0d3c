// libFuzzer target: the server's handling of a WebSocket's first frames, on /ws/agent and on
// /ws/session/{id}, without the network. The input is a run of frames, each
// [1 byte: bit 0: from an admin viewer (else the agent); bit 1: a text frame; bit 2: first, the
// agent resumes on a new connection (bit 3: and its old one closes, else it lingers)]
// [2 bytes: length, little-endian][bytes];
// the endpoints (sessions.cc) take them as the connection would, and the session's strand work
// runs after each one. Whatever comes in, every frame the server sends back must be an Envelope,
// nothing crashes or leaks, and a closed connection is fed nothing more (as the real one).
#include <boost/asio/post.hpp>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <future>
#include <string>
#include <vector>

#include "../../server/src/server_internal.h"
#include "../../server/src/sessions.h"
#include "../../server/src/ws_endpoint.h"
#include "idms/protocol/envelope.h"
#include "idms/server/library.h"
#include "idms/server/storage.h"

namespace {

using namespace idms;
using namespace idms::server;
namespace fs = std::filesystem;

class FuzzPeer final : public WsPeer {
 public:
  explicit FuzzPeer(std::string name) : name_(std::move(name)) {}
  void Send(std::shared_ptr<const std::string> message, bool binary) override {
    v1::Envelope e;
    std::string error;
    if (!binary || !ParseEnvelope(*message, &e, &error)) __builtin_trap();  // the server speaks Envelopes
    if (e.has_welcome()) {
      welcome_session = e.welcome().session_id();
      if (!e.welcome().resume_token().empty()) welcome_token = e.welcome().resume_token();
    }
  }
  void Close(uint16_t, std::string) override { closed = true; }
  size_t queued() const override { return 0; }
  size_t queued_bytes() const override { return 0; }
  const std::string& peer() const override { return name_; }

  bool closed = false;
  std::string welcome_session, welcome_token;

 private:
  std::string name_;
};

struct World {
  std::string dir = (fs::temp_directory_path() / ("idms-ws-fuzz-" + std::to_string(::getpid()))).string();
  Storage storage;
  std::unique_ptr<Library> library;
  ServerCore core{ServerOptions{}, 1, 1};
  std::unique_ptr<SessionHub> hub;
  std::vector<Route> routes;

  World() {
    fs::remove_all(dir);
    std::string error;
    if (!OpenStorage(dir, &storage, &error)) __builtin_trap();
    library = std::make_unique<Library>(storage.blobs.get(), storage.models.get());
    core.ctx.options = &core.options;
    core.ctx.library = library.get();
    core.ctx.metrics = &core.metrics;
    hub = std::make_unique<SessionHub>(core, storage.sessions.get(), storage.recordings.get());
    core.hub = hub.get();
    AppendWebSocketRoutes(core, &routes);
  }

  // The sessions' strands, then the recorder's and the index's work, until nothing is left.
  void RunPosted() {
    for (int round = 0; round < 4; ++round) {
      core.ioc.restart();
      core.ioc.poll();
      std::promise<void> recorded, indexed;
      boost::asio::post(core.recorder, [&] { recorded.set_value(); });
      recorded.get_future().wait();
      boost::asio::post(core.workers, [&] { indexed.set_value(); });
      indexed.get_future().wait();
    }
  }

  // Ends every session, waits for the recorder, forgets the rows and files: inputs are independent.
  void Reset() {
    hub->StopAll();
    RunPosted();
    for (const SessionRow& row : storage.sessions->List()) storage.sessions->Delete(row.id);
    std::error_code ec;
    fs::remove_all(dir + "/recordings", ec);
    fs::create_directories(dir + "/recordings", ec);
  }
};

struct FuzzConnection {
  std::shared_ptr<FuzzPeer> peer;
  std::shared_ptr<WsEndpoint> endpoint;
  void Close() {
    if (endpoint) endpoint->OnClose();
    endpoint.reset();
  }
};

FuzzConnection Open(World& world, const std::string& pattern, std::vector<std::string> params, Role role) {
  ApiRequest req;
  req.path = pattern;
  req.params = std::move(params);
  req.role = role;
  std::string refusal;
  FuzzConnection c;
  for (const Route& r : world.routes) {
    if (r.pattern == pattern) c.endpoint = r.open_websocket(req, &refusal);
  }
  if (!c.endpoint) return c;
  c.peer = std::make_shared<FuzzPeer>(pattern);
  c.endpoint->OnOpen(c.peer);
  return c;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static World* world = new World();
  FuzzConnection agent = Open(*world, "/ws/agent", {}, Role::kAgent), viewer;
  std::vector<FuzzConnection> lingering;  // replaced agent connections not yet closed
  size_t at = 0;
  while (at + 3 <= size) {
    const uint8_t to = data[at];
    const size_t length = std::min<size_t>(data[at + 1] | (data[at + 2] << 8), size - at - 3);
    const std::string_view frame(reinterpret_cast<const char*>(data + at + 3), length);
    at += 3 + length;
    // A viewer joins the agent's session once it has one.
    if ((to & 1) && !viewer.endpoint && agent.peer && !agent.peer->welcome_session.empty()) {
      viewer = Open(*world, "/ws/session/{id}", {agent.peer->welcome_session}, Role::kAdmin);
    }
    // The agent resumes on a new connection, its old one closed or lingering.
    if ((to & 4) && agent.peer && !agent.peer->welcome_session.empty()) {
      FuzzConnection resumed = Open(*world, "/ws/agent", {}, Role::kAgent);
      v1::Envelope hello;
      hello.mutable_hello()->set_protocol_version(kProtocolVersion);
      hello.mutable_hello()->set_role(v1::ROLE_AGENT);
      hello.mutable_hello()->set_session_id(agent.peer->welcome_session);
      hello.mutable_hello()->set_resume_token(agent.peer->welcome_token);
      std::string bytes;
      SerializeEnvelope(hello, &bytes);
      resumed.endpoint->OnMessage(bytes, true);
      world->RunPosted();
      if (to & 8) agent.Close();
      lingering.push_back(std::move(agent));
      agent = std::move(resumed);
    }
    FuzzConnection& c = (to & 1) ? viewer : agent;
    if (!c.endpoint) continue;
    c.endpoint->OnMessage(frame, (to & 2) == 0);  // bit 1: a text frame
    if (c.peer->closed) c.Close();
    world->RunPosted();
  }
  viewer.Close();
  agent.Close();
  for (FuzzConnection& c : lingering) c.Close();
  world->RunPosted();
  world->Reset();
  return 0;
}
