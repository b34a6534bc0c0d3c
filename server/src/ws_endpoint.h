// What is spoken on a WebSocket, apart from how the bytes move: a WsEndpoint (library events, an
// agent publishing, a viewer watching) talks to its connection through WsPeer. The connection
// (connection.cc) owns the stream, the strand, the bounded send queue and the limits.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

namespace idms::server {

// The connection, as an endpoint sees it. Thread-safe: Send and Close post to the connection's
// strand; queued() is a relaxed read for back-pressure decisions.
class WsPeer {
 public:
  virtual ~WsPeer() = default;
  // Queues one message (the same immutable bytes may go to many peers). Beyond the queue's bound
  // the oldest queued message is dropped.
  virtual void Send(std::shared_ptr<const std::string> message, bool binary) = 0;
  // Sends a close frame with a reason once the queue has drained, then closes.
  virtual void Close(uint16_t code, std::string reason) = 0;
  virtual size_t queued() const = 0;
  virtual const std::string& peer() const = 0;  // "ROLE ADDRESS:PORT", for logs and events
};

// One WebSocket protocol. Called on the connection's strand.
class WsEndpoint {
 public:
  virtual ~WsEndpoint() = default;
  virtual void OnOpen(std::shared_ptr<WsPeer> peer) = 0;
  virtual void OnMessage(std::string_view bytes, bool binary) = 0;
  virtual void OnDrained() {}  // the send queue became empty
  virtual void OnClose() = 0;  // the connection is gone (either side); called once
  // Messages per second a client may send before the connection is closed (policy error).
  virtual int max_messages_per_s() const { return 100; }
};

}  // namespace idms::server
