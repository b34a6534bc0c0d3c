// libFuzzer target: what the server takes from the bus between servers (relay.cc, live_session.cc),
// without a broker. A viewer here watches a session another server owns (its RelayedSession
// subscribes to the session's frames and asks for its state on an inbox), and an agent here owns
// a session of its own (whose LiveSession takes relayed viewers' notes and commands). The input
// is a run of bus messages, each [1 byte: 0 a RelayFrame on the relayed session's subject, 1 a
// RelayJoin on the inbox its state was asked on, 2 a RelayViewerMessage to the owned session]
// [2 bytes: length, little-endian][bytes]. Whatever comes, every frame the server sends its
// viewers and its agent must be an Envelope, and nothing crashes or leaks.
#include <cstddef>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "../../server/src/relay.h"
#include "server_world.h"

namespace {

using namespace idms;
using namespace idms::fuzz;

// The bus in this process: subscriptions by subject, delivered to at once on the caller's thread.
class FuzzBus final : public server::Bus {
 public:
  class Sub final : public Subscription {
   public:
    Sub(FuzzBus* bus, uint64_t id) : bus_(bus), id_(id) {}
    ~Sub() override {
      std::lock_guard lock(bus_->mu_);
      bus_->subs_.erase(id_);
    }

   private:
    FuzzBus* bus_;
    uint64_t id_;
  };

  bool Publish(const std::string&, std::string_view, const std::string&) override { return true; }
  std::unique_ptr<Subscription> Subscribe(const std::string& subject, Handler handler, std::string*) override {
    std::lock_guard lock(mu_);
    subs_[++next_] = {subject, std::move(handler)};
    return std::make_unique<Sub>(this, next_);
  }
  std::string NewInbox() override { return "_INBOX.fuzz." + std::to_string(++inboxes_); }

  // To every subscriber of `subject` ("_INBOX." alone: the newest inbox).
  void Deliver(const std::string& subject, std::string_view data) {
    std::vector<Handler> to;
    {
      std::lock_guard lock(mu_);
      for (auto it = subs_.rbegin(); it != subs_.rend(); ++it) {
        const std::string& s = it->second.first;
        if (s == subject || (subject == "_INBOX." && s.rfind("_INBOX.", 0) == 0)) {
          to.push_back(it->second.second);
          if (subject == "_INBOX.") break;
        }
      }
    }
    for (const Handler& h : to) h(data, "");
  }

 private:
  std::mutex mu_;
  std::map<uint64_t, std::pair<std::string, Handler>> subs_;
  uint64_t next_ = 0, inboxes_ = 0;
};

struct World : ServerWorld {
  FuzzBus bus;
  World() : ServerWorld("idms-relay-fuzz") { hub->SetBus(&bus); }
  void Reset() {
    hub->StopAll();
    RunPosted();
    for (const server::SessionRow& row : storage.sessions->List()) storage.sessions->Delete(row.id);
  }
};

struct FuzzConnection {
  std::shared_ptr<FuzzPeer> peer;
  std::shared_ptr<server::WsEndpoint> endpoint;
  void Close() {
    if (endpoint) endpoint->OnClose();
    endpoint.reset();
  }
};

FuzzConnection Open(World& world, const std::string& pattern, std::vector<std::string> params, server::Role role) {
  FuzzConnection c;
  c.endpoint = world.Open(pattern, std::move(params), role);
  if (!c.endpoint) return c;
  c.peer = std::make_shared<FuzzPeer>(pattern);
  c.endpoint->OnOpen(c.peer);
  return c;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static World* world = new World();
  // A session owned here: an agent's Hello.
  FuzzConnection agent = Open(*world, "/ws/agent", {}, server::Role::kAgent);
  v1::Envelope hello;
  hello.mutable_hello()->set_protocol_version(kProtocolVersion);
  hello.mutable_hello()->set_role(v1::ROLE_AGENT);
  hello.mutable_hello()->mutable_scene()->set_model_file("fuzz");
  agent.endpoint->OnMessage(Frame(hello), true);
  world->RunPosted();
  const std::string owned = agent.peer->welcome_session;
  // A session owned elsewhere, watched here.
  const std::string relayed = "elsewhere";
  FuzzConnection viewer = Open(*world, "/ws/session/{id}", {relayed}, server::Role::kAdmin);
  world->RunPosted();
  size_t at = 0;
  while (at + 3 <= size) {
    const uint8_t to = data[at] % 3;
    const size_t length = std::min<size_t>(data[at + 1] | (data[at + 2] << 8), size - at - 3);
    const std::string_view message(reinterpret_cast<const char*>(data + at + 3), length);
    at += 3 + length;
    if (to == 0) world->bus.Deliver(server::LiveSubject(relayed), message);
    if (to == 1) world->bus.Deliver("_INBOX.", message);
    if (to == 2 && !owned.empty()) world->bus.Deliver(server::ViewerSubject(owned), message);
    world->RunPosted();
    if (viewer.peer && viewer.peer->closed) viewer.Close();
  }
  viewer.Close();
  agent.Close();
  world->RunPosted();
  world->Reset();
  return 0;
}
