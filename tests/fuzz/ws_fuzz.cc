// libFuzzer target: the server's handling of a WebSocket's first frames, on /ws/agent and on
// /ws/session/{id}, without the network. The input is a run of frames, each
// [1 byte: 0 = from the agent, 1 = from an admin viewer][2 bytes: length, little-endian][bytes];
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
    if (e.has_welcome()) welcome_session = e.welcome().session_id();
  }
  void Close(uint16_t, std::string) override { closed = true; }
  size_t queued() const override { return 0; }
  const std::string& peer() const override { return name_; }

  bool closed = false;
  std::string welcome_session;

 private:
  std::string name_;
};

struct World {
  std::string dir = (fs::temp_directory_path() / ("idms-ws-fuzz-" + std::to_string(::getpid()))).string();
  Storage storage;
  std::unique_ptr<Library> library;
  ServerCore core{ServerOptions{}, 1, 1};
  std::unique_ptr<SessionHub> hub;

  World() {
    fs::remove_all(dir);
    std::string error;
    if (!OpenStorage(dir, &storage, &error)) __builtin_trap();
    library = std::make_unique<Library>(storage.blobs.get(), storage.models.get());
    core.ctx.options = &core.options;
    core.ctx.library = library.get();
    core.ctx.metrics = &core.metrics;
    hub = std::make_unique<SessionHub>(core, storage.sessions.get(), dir + "/recordings");
    core.hub = hub.get();
  }

  void RunPosted() {
    core.ioc.restart();
    core.ioc.poll();
  }

  // Ends every session, waits for the recorder, forgets the rows and files: inputs are independent.
  void Reset() {
    hub->StopAll();
    RunPosted();
    std::promise<void> done;
    boost::asio::post(core.recorder, [&] { done.set_value(); });
    done.get_future().wait();
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

FuzzConnection Open(ServerCore& core, const std::string& path, std::vector<std::string> params, Role role) {
  ApiRequest req;
  req.path = path;
  req.params = std::move(params);
  req.role = role;
  std::string refusal;
  FuzzConnection c;
  c.endpoint = MakeEndpoint(core, req, &refusal);
  if (!c.endpoint) return c;
  c.peer = std::make_shared<FuzzPeer>(path);
  c.endpoint->OnOpen(c.peer);
  return c;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static World* world = new World();
  FuzzConnection agent = Open(world->core, "/ws/agent", {}, Role::kAgent), viewer;
  size_t at = 0;
  while (at + 3 <= size) {
    const uint8_t to = data[at];
    const size_t length = std::min<size_t>(data[at + 1] | (data[at + 2] << 8), size - at - 3);
    const std::string_view frame(reinterpret_cast<const char*>(data + at + 3), length);
    at += 3 + length;
    // A viewer joins the agent's session once it has one.
    if ((to & 1) && !viewer.endpoint && agent.peer && !agent.peer->welcome_session.empty()) {
      viewer = Open(world->core, "/ws/session/{id}", {agent.peer->welcome_session}, Role::kAdmin);
    }
    FuzzConnection& c = (to & 1) ? viewer : agent;
    if (!c.endpoint) continue;
    c.endpoint->OnMessage(frame, (to & 2) == 0);  // bit 1: a text frame
    if (c.peer->closed) c.Close();
    world->RunPosted();
  }
  viewer.Close();
  agent.Close();
  world->RunPosted();
  world->Reset();
  return 0;
}
