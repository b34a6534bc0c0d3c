// What is spoken on a WebSocket, apart from how the bytes move: a WsEndpoint (library events, an
// agent publishing, a viewer watching, a replay) talks to its connection through WsPeer. The
// connection (connection.cc) owns the stream, the strand, the bounded send queue and the limits.
//
// Ownership: the connection owns its endpoint; the endpoint holds the connection only weakly
// (std::weak_ptr<WsPeer>), and so does everything the endpoint hands it to (a live session's
// viewers and agent). A closed connection is therefore freed however long a session lives, and
// a session never keeps a socket open (Beast's chat-multi holds its sessions the same way).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

namespace idms::server {

// The connection, as an endpoint sees it. Thread-safe: Send and Close post to the connection's
// strand; queued() and queued_bytes() are relaxed reads for back-pressure decisions.
class WsPeer {
 public:
  virtual ~WsPeer() = default;
  // Queues one message (the same immutable bytes may go to many peers). Beyond the queue's bound
  // (in messages and in bytes) the oldest queued message is dropped.
  virtual void Send(std::shared_ptr<const std::string> message, bool binary) = 0;
  // Sends a close frame with a reason once the queue has drained, then closes.
  virtual void Close(uint16_t code, std::string reason) = 0;
  virtual size_t queued() const = 0;            // messages waiting, the one being written included
  virtual size_t queued_bytes() const = 0;      // their bytes
  virtual const std::string& peer() const = 0;  // "ROLE ADDRESS:PORT", for logs and events
};

// One WebSocket protocol. Called on the connection's strand.
class WsEndpoint {
 public:
  virtual ~WsEndpoint() = default;
  virtual void OnOpen(std::weak_ptr<WsPeer> peer) = 0;
  virtual void OnMessage(std::string_view bytes, bool binary) = 0;
  virtual void OnDrained() {}  // the send queue became empty
  virtual void OnClose() = 0;  // the connection is gone (either side); called once
  // Messages per second a client may send before the connection is closed (policy error).
  virtual int max_messages_per_s() const { return 100; }
  // A peer silent this long is pinged at half of it and dropped at the end (a link that died
  // without a close, as a Wi-Fi drop leaves it).
  virtual std::chrono::milliseconds idle_timeout() const { return std::chrono::seconds(15); }
};

}  // namespace idms::server
