// Messages between the servers of one deployment (idms-server --bus): a live session's owner
// publishes what its viewers get, other servers relay it to theirs (relay.h). NATS in production
// (OpenNatsBus); core NATS, at most once: live frames are useless late, and a receiver that
// misses one resynchronises from a keyframe.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

namespace idms::server {

class Bus {
 public:
  // Called on the bus's own thread: copy what you need and post to your strand; never block.
  // `reply`: the subject to answer on (empty when none was asked).
  using Handler = std::function<void(std::string_view data, const std::string& reply)>;
  // Receives while it lives; destroying it unsubscribes (and no handler call runs after).
  class Subscription {
   public:
    virtual ~Subscription() = default;
  };

  virtual ~Bus() = default;
  // Queues a message (never waits for the network); false when the bus refused it (closed, or
  // its outgoing buffer is full while reconnecting).
  virtual bool Publish(const std::string& subject, std::string_view data, const std::string& reply = "") = 0;
  // Null with *error when the bus refused.
  virtual std::unique_ptr<Subscription> Subscribe(const std::string& subject, Handler handler, std::string* error) = 0;
  // A subject unique to this connection, for replies.
  virtual std::string NewInbox() = 0;
  // Runs (on the bus's thread) after the bus lost its connection and got it back: subscriptions
  // are restored, what was published in between is lost. Set before use.
  std::function<void()> on_reconnected;

  // For /metrics.
  std::atomic<uint64_t> published_bytes{0}, received_bytes{0}, publish_failures{0}, disconnects{0},
      slow_consumer_errors{0};
  std::atomic<bool> connected{false};
};

// A NATS connection to `urls` (comma-separated nats://host:port), named `name` (the server's
// node id, in the broker's monitoring). It reconnects forever (every 250 ms, to any listed or
// discovered server of the cluster); a first connection that fails is an error.
std::unique_ptr<Bus> OpenNatsBus(const std::string& urls, const std::string& name, std::string* error);
// Once every bus is gone, at the end of the process: waits (up to 2 s) for the NATS client's
// threads to finish and frees what it keeps (what LeakSanitizer would otherwise report).
void CloseBusLibrary();

}  // namespace idms::server
