// Bus on NATS (the C client, libnats): one connection per server, reconnecting forever; each
// subscription delivers on the client's own thread, and its closure lives until the client says
// the subscription is complete (no handler call can outlive it).
#include <nats/nats.h>

#include <mutex>
#include <sstream>
#include <vector>

#include "idms/server/bus.h"
#include "idms/server/log.h"

namespace idms::server {

namespace {

// What a subscription's callbacks need, owned by the client until it completes.
struct Delivery {
  Bus::Handler handler;
  Bus* bus = nullptr;
};

void OnMessage(natsConnection*, natsSubscription*, natsMsg* msg, void* closure) {
  auto* d = static_cast<Delivery*>(closure);
  const int n = natsMsg_GetDataLength(msg);
  d->bus->received_bytes += static_cast<uint64_t>(n);
  const char* reply = natsMsg_GetReply(msg);
  d->handler(std::string_view(natsMsg_GetData(msg), static_cast<size_t>(n)), reply != nullptr ? reply : "");
  natsMsg_Destroy(msg);
}

void OnComplete(void* closure) { delete static_cast<Delivery*>(closure); }

class NatsSubscription : public Bus::Subscription {
 public:
  explicit NatsSubscription(natsSubscription* sub) : sub_(sub) {}
  ~NatsSubscription() override {
    natsSubscription_Unsubscribe(sub_);
    natsSubscription_Destroy(sub_);
  }

 private:
  natsSubscription* sub_;
};

class NatsBus;

// What the connection's callbacks reach the bus through: the client calls them on its own
// thread, even after natsConnection_Close returned, until the closed callback, which frees this.
struct Callbacks {
  std::mutex mu;
  NatsBus* bus = nullptr;  // null once the bus is gone
};

class NatsBus : public Bus {
 public:
  NatsBus() : callbacks_(new Callbacks) { callbacks_->bus = this; }
  ~NatsBus() override {
    {
      std::lock_guard lock(callbacks_->mu);
      callbacks_->bus = nullptr;
    }
    if (nc_ != nullptr) {
      natsConnection_Close(nc_);  // the closed callback frees callbacks_
      natsConnection_Destroy(nc_);
    } else {
      delete callbacks_;  // never connected: no callback will come
    }
    if (opts_ != nullptr) natsOptions_Destroy(opts_);
  }

  bool Open(const std::string& urls, const std::string& name, std::string* error) {
    std::vector<std::string> list;
    for (std::stringstream ss(urls); ss.good();) {
      std::string url;
      std::getline(ss, url, ',');
      if (!url.empty()) list.push_back(url);
    }
    std::vector<const char*> servers;
    for (const auto& u : list) servers.push_back(u.c_str());
    natsStatus s = natsOptions_Create(&opts_);
    if (s == NATS_OK) s = natsOptions_SetServers(opts_, servers.data(), static_cast<int>(servers.size()));
    if (s == NATS_OK) s = natsOptions_SetName(opts_, name.c_str());
    if (s == NATS_OK) s = natsOptions_SetMaxReconnect(opts_, -1);  // forever
    if (s == NATS_OK) s = natsOptions_SetReconnectWait(opts_, 250);
    if (s == NATS_OK) s = natsOptions_SetReconnectJitter(opts_, 100, 100);
    if (s == NATS_OK)
      s = natsOptions_SetReconnectBufSize(opts_, 1 << 20);           // published while reconnecting; beyond: a gap
    if (s == NATS_OK) s = natsOptions_SetPingInterval(opts_, 1000);  // a dead link noticed in ~2 s
    if (s == NATS_OK) s = natsOptions_SetMaxPingsOut(opts_, 2);
    if (s == NATS_OK) s = natsOptions_SetTimeout(opts_, 2000);
    // Echo stays on: a server that takes a session over while it relays it to viewers of its own
    // hears its new LiveSession through the bus like any other owner (an owner subscribes to no
    // subject it publishes on, so echo costs nothing otherwise).
    if (s == NATS_OK) s = natsOptions_SetDisconnectedCB(opts_, &NatsBus::Disconnected, callbacks_);
    if (s == NATS_OK) s = natsOptions_SetReconnectedCB(opts_, &NatsBus::Reconnected, callbacks_);
    if (s == NATS_OK) s = natsOptions_SetErrorHandler(opts_, &NatsBus::Error, callbacks_);
    if (s == NATS_OK) s = natsOptions_SetClosedCB(opts_, &NatsBus::Closed, callbacks_);
    if (s == NATS_OK) s = natsConnection_Connect(&nc_, opts_);
    if (s != NATS_OK) {
      *error = "NATS at " + urls + ": " + natsStatus_GetText(s);
      return false;
    }
    connected = true;
    return true;
  }

  bool Publish(const std::string& subject, std::string_view data, const std::string& reply) override {
    const natsStatus s = reply.empty()
                             ? natsConnection_Publish(nc_, subject.c_str(), data.data(), static_cast<int>(data.size()))
                             : natsConnection_PublishRequest(nc_, subject.c_str(), reply.c_str(), data.data(),
                                                             static_cast<int>(data.size()));
    if (s != NATS_OK) return ++publish_failures, false;
    published_bytes += data.size();
    return true;
  }

  std::unique_ptr<Subscription> Subscribe(const std::string& subject, Handler handler, std::string* error) override {
    auto* d = new Delivery{std::move(handler), this};
    natsSubscription* sub = nullptr;
    natsStatus s = natsConnection_Subscribe(&sub, nc_, subject.c_str(), &OnMessage, d);
    if (s != NATS_OK) {
      delete d;
      *error = std::string("subscribing to ") + subject + ": " + natsStatus_GetText(s);
      return nullptr;
    }
    natsSubscription_SetOnCompleteCB(sub, &OnComplete, d);
    // A live stream's subscriber that falls this far behind drops (and resynchronises) rather
    // than queueing seconds of stale frames.
    natsSubscription_SetPendingLimits(sub, 4096, 64 << 20);
    return std::make_unique<NatsSubscription>(sub);
  }

  std::string NewInbox() override {
    natsInbox* inbox = nullptr;
    if (natsInbox_Create(&inbox) != NATS_OK) return {};
    std::string out(inbox);
    natsInbox_Destroy(inbox);
    return out;
  }

 private:
  static void Disconnected(natsConnection*, void* closure) {
    auto* c = static_cast<Callbacks*>(closure);
    std::lock_guard lock(c->mu);
    if (c->bus == nullptr || !c->bus->connected.exchange(false)) return;
    ++c->bus->disconnects;
    Log(LogLevel::kWarn, "the bus (NATS) connection dropped; reconnecting", {});
  }
  static void Reconnected(natsConnection*, void* closure) {
    auto* c = static_cast<Callbacks*>(closure);
    std::lock_guard lock(c->mu);
    if (c->bus == nullptr) return;
    c->bus->connected = true;
    Log(LogLevel::kInfo, "the bus (NATS) connection is back", {});
    if (c->bus->on_reconnected) c->bus->on_reconnected();
  }
  static void Error(natsConnection*, natsSubscription*, natsStatus err, void* closure) {
    auto* c = static_cast<Callbacks*>(closure);
    std::lock_guard lock(c->mu);
    if (c->bus == nullptr) return;
    if (err == NATS_SLOW_CONSUMER) {
      // Messages dropped for us: the relays notice the gap in their sequence and resynchronise.
      if (c->bus->slow_consumer_errors++ == 0) {
        Log(LogLevel::kWarn, "the bus dropped messages for this server (slow consumer)", {});
      }
      return;
    }
    Log(LogLevel::kWarn, std::string("bus (NATS) error: ") + natsStatus_GetText(err), {});
  }
  static void Closed(natsConnection*, void* closure) { delete static_cast<Callbacks*>(closure); }

  Callbacks* callbacks_;
  natsOptions* opts_ = nullptr;
  natsConnection* nc_ = nullptr;
};

}  // namespace

void CloseBusLibrary() { nats_CloseAndWait(2000); }

std::unique_ptr<Bus> OpenNatsBus(const std::string& urls, const std::string& name, std::string* error) {
  auto bus = std::make_unique<NatsBus>();
  if (!bus->Open(urls, name, error)) return nullptr;
  return bus;
}

}  // namespace idms::server
