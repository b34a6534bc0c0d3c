// libFuzzer target: a replay's controls on /ws/replay/{id}, without the network. A session is
// recorded once through the agent's endpoint (samples, annotations, ENDED); each input opens a
// replay of it and feeds it a run of frames, [1 byte: bit 0 a text frame][2 bytes: length,
// little-endian][bytes], as the connection would, letting the replay's strand (the worker pool)
// run after each. Whatever comes in, every frame the server sends back is an Envelope, and
// nothing crashes, hangs or leaks.
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
  void Send(std::shared_ptr<const std::string> message, bool binary) override {
    v1::Envelope e;
    std::string error;
    if (!binary || !ParseEnvelope(*message, &e, &error)) __builtin_trap();  // the server speaks Envelopes
    if (e.has_welcome()) {
      session = e.welcome().session_id();
      token = e.welcome().resume_token();
    }
  }
  void Close(uint16_t, std::string) override { closed = true; }
  size_t queued() const override { return 0; }
  size_t queued_bytes() const override { return 0; }
  const std::string& peer() const override { return name_; }

  std::atomic<bool> closed{false};
  std::string session, token;

 private:
  std::string name_ = "fuzz";
};

std::string Frame(const v1::Envelope& e) {
  std::string bytes;
  SerializeEnvelope(e, &bytes);
  return bytes;
}

struct World {
  std::string dir = (fs::temp_directory_path() / ("idms-replay-fuzz-" + std::to_string(::getpid()))).string();
  Storage storage;
  std::unique_ptr<Library> library;
  ServerCore core{ServerOptions{}, 1, 1};
  std::unique_ptr<SessionHub> hub;
  std::vector<Route> routes;
  std::string session;

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
    Record();
  }

  std::shared_ptr<WsEndpoint> Open(const std::string& pattern, const std::string& param) {
    ApiRequest req;
    req.path = pattern;
    req.params = {param};
    req.role = Role::kObserver;
    std::string refusal;
    for (const Route& r : routes) {
      if (r.pattern == pattern) return r.open_websocket(req, &refusal);
    }
    return nullptr;
  }

  // The sessions' strands, the recorder and the workers, until what was posted has run.
  void RunPosted() {
    for (int round = 0; round < 4; ++round) {
      core.ioc.restart();
      core.ioc.poll();
      std::promise<void> recorded, worked;
      boost::asio::post(core.recorder, [&] { recorded.set_value(); });
      recorded.get_future().wait();
      boost::asio::post(core.workers, [&] { worked.set_value(); });
      worked.get_future().wait();
    }
  }

  // Two seconds of samples with annotations, then ENDED: the recording every input replays.
  void Record() {
    auto peer = std::make_shared<FuzzPeer>();
    std::shared_ptr<WsEndpoint> agent = Open("/ws/agent", "");
    agent->OnOpen(peer);
    v1::Envelope hello;
    hello.mutable_hello()->set_protocol_version(kProtocolVersion);
    hello.mutable_hello()->set_role(v1::ROLE_AGENT);
    agent->OnMessage(Frame(hello), true);
    RunPosted();
    session = peer->session;
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
    if (session.empty() || !storage.sessions->Get(session) || storage.sessions->Get(session)->state != "ended") {
      __builtin_trap();
    }
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static World* world = new World();
  std::shared_ptr<WsEndpoint> replay = world->Open("/ws/replay/{id}", world->session);
  if (!replay) __builtin_trap();
  auto peer = std::make_shared<FuzzPeer>();
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
