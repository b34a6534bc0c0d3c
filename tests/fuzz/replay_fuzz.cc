// libFuzzer target: a replay's controls on /ws/replay/{id}, without the network. A session is
// recorded once through the agent's endpoint (samples, ENDED); each input opens a replay of it and
// feeds it a run of frames, [1 byte: bit 0 a text frame][2 bytes: length, little-endian][bytes],
// as the connection would, letting the replay's strand (the worker pool) run after each. Whatever
// comes in, every frame the server sends back is an Envelope, and nothing crashes, hangs or leaks.
#include <cstddef>
#include <cstdint>
#include <string>

#include "server_world.h"

namespace {

using namespace idms;
using namespace idms::fuzz;

struct World : ServerWorld {
  std::string session;

  World() : ServerWorld("idms-replay-fuzz") { Record(); }

  // Two seconds of samples, then ENDED: the recording every input replays.
  void Record() {
    auto peer = std::make_shared<FuzzPeer>("agent");
    std::shared_ptr<server::WsEndpoint> agent = Open("/ws/agent", {}, server::Role::kAgent);
    agent->OnOpen(peer);
    v1::Envelope hello;
    hello.mutable_hello()->set_protocol_version(kProtocolVersion);
    hello.mutable_hello()->set_role(v1::ROLE_AGENT);
    agent->OnMessage(Frame(hello), true);
    RunPosted();
    session = peer->welcome_session;
    for (uint64_t batch = 0; batch < 100; ++batch) {
      v1::Envelope e;
      for (uint64_t i = 0; i < 20; ++i) {
        v1::DeviceSample* s = e.mutable_device_samples()->add_samples();
        s->set_tick(20 * batch + i);
        s->set_time_s(0.001 * static_cast<double>(20 * batch + i + 1));
        s->set_contact(i % 2 == 0);
      }
      agent->OnMessage(Frame(e), true);
    }
    v1::Envelope ended;
    ended.mutable_session_event()->set_kind(v1::SessionEvent::KIND_ENDED);
    ended.mutable_session_event()->set_time_s(2.0);
    agent->OnMessage(Frame(ended), true);
    RunPosted();
    agent->OnClose();
    RunPosted();
    const auto row = storage.sessions->Get(session);
    if (session.empty() || !row || row->state != "ended") __builtin_trap();
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static World* world = new World();
  std::shared_ptr<server::WsEndpoint> replay =
      world->Open("/ws/replay/{id}", {world->session}, server::Role::kObserver);
  if (!replay) __builtin_trap();
  auto peer = std::make_shared<FuzzPeer>("replay");
  replay->OnOpen(peer);
  size_t at = 0;
  while (at + 3 <= size && !peer->closed) {
    const bool text = data[at] & 1;
    const size_t length = std::min<size_t>(data[at + 1] | (data[at + 2] << 8), size - at - 3);
    replay->OnMessage(std::string_view(reinterpret_cast<const char*>(data + at + 3), length), !text);
    at += 3 + length;
    world->RunPosted();
  }
  replay->OnClose();
  world->RunPosted();
  return 0;
}
