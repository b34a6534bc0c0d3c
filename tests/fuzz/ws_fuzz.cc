// libFuzzer target: the server's handling of a WebSocket's first frames, on /ws/agent and on
// /ws/session/{id}, without the network. The input is a run of frames, each
// [1 byte: bit 0: from an admin viewer (else the agent); bit 1: a text frame; bit 2: first, the
// agent resumes on a new connection (bit 3: and its old one closes, else it lingers)]
// [2 bytes: length, little-endian][bytes];
// the endpoints (ws_endpoints.cc) take them as the connection would, and the session's strand work
// runs after each one. Whatever comes in, every frame the server sends back must be an Envelope,
// nothing crashes or leaks, and a closed connection is fed nothing more (as the real one).
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "server_world.h"

namespace {

using namespace idms;
using namespace idms::fuzz;

struct World : ServerWorld {
  World() : ServerWorld("idms-ws-fuzz") {}

  // Ends every session, waits for the recorder, forgets the rows and files: inputs are independent.
  void Reset() {
    hub->StopAll();
    RunPosted();
    for (const server::SessionRow& row : storage.sessions->List()) storage.sessions->Delete(row.id);
    std::error_code ec;
    std::filesystem::remove_all(dir + "/recordings", ec);
    std::filesystem::create_directories(dir + "/recordings", ec);
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static World* world = new World();
  FuzzConnection agent = OpenConnection(*world, "/ws/agent", {}, server::Role::kAgent), viewer;
  std::vector<FuzzConnection> lingering;  // replaced agent connections not yet closed
  size_t at = 0;
  while (at + 3 <= size) {
    const uint8_t to = data[at];
    const size_t length = std::min<size_t>(data[at + 1] | (data[at + 2] << 8), size - at - 3);
    const std::string_view frame(reinterpret_cast<const char*>(data + at + 3), length);
    at += 3 + length;
    // A viewer joins the agent's session once it has one.
    if ((to & 1) && !viewer.endpoint && agent.peer && !agent.peer->welcome_session.empty()) {
      viewer = OpenConnection(*world, "/ws/session/{id}", {agent.peer->welcome_session}, server::Role::kAdmin);
    }
    // The agent resumes on a new connection, its old one closed or lingering.
    if ((to & 4) && agent.peer && !agent.peer->welcome_session.empty()) {
      FuzzConnection resumed = OpenConnection(*world, "/ws/agent", {}, server::Role::kAgent);
      v1::Envelope hello;
      hello.mutable_hello()->set_protocol_version(kProtocolVersion);
      hello.mutable_hello()->set_role(v1::ROLE_AGENT);
      hello.mutable_hello()->set_session_id(agent.peer->welcome_session);
      hello.mutable_hello()->set_resume_token(agent.peer->welcome_token);
      resumed.endpoint->OnMessage(Frame(hello), true);
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
