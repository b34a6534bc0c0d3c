// What the connections share with the server: the API context and routes, the worker pool,
// limits, the registry used to drain connections on shutdown, and the /ws/library fan-out.
#pragma once

#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/ssl/context.hpp>
#include <boost/asio/strand.hpp>
#include <boost/asio/thread_pool.hpp>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "connection_slots.h"
#include "idms/server/api.h"
#include "idms/server/storage.h"

namespace idms::server {

// A live connection, as the registry sees it. Drain() asks it to finish what is in flight and
// close; any thread (it posts to the connection's strand).
class Connection {
 public:
  virtual ~Connection() = default;
  virtual void Drain() = 0;
};

class SessionHub;

// A text message watcher of /ws/library; Send is thread-safe and never blocks.
class TextSink {
 public:
  virtual ~TextSink() = default;
  virtual void Send(std::shared_ptr<const std::string> text) = 0;
};

struct ServerCore {
  ServerOptions options;
  ApiContext ctx;
  std::vector<Route> routes;
  Metrics metrics;
  // Every open connection's slot, HTTP or WebSocket (sets metrics.open_connections).
  ConnectionSlots slots{options.max_connections, options.max_connections_per_address, &metrics.open_connections};
  std::optional<boost::asio::ssl::context> tls;  // set: every connection speaks TLS
  std::atomic<bool> draining{false};
  std::atomic<int> uploads_in_flight{0};
  std::atomic<uint64_t> next_endpoint_id{1};  // WebSocket endpoints' ids (a session tells its connections apart)
  SessionHub* hub = nullptr;                  // live sessions (sessions.cc)
  LeaseStore* leases = nullptr;               // session ownership (in memory, or PostgreSQL with --store)

  ServerCore(ServerOptions o, int io_threads, int worker_threads)
      : options(std::move(o)), workers(static_cast<size_t>(worker_threads)), ioc(io_threads) {}

  // Registry of connections (for Drain) and of /ws/library watchers.
  void Register(Connection* c, std::weak_ptr<Connection> w);
  void Unregister(Connection* c);
  void DrainAll();
  void Subscribe(TextSink* s, std::weak_ptr<TextSink> w);
  void Unsubscribe(TextSink* s);
  void Publish(const std::string& text);
  std::function<void()> on_last_connection_closed;  // while draining

 private:
  std::mutex mu_;
  std::unordered_map<Connection*, std::weak_ptr<Connection>> connections_;
  std::unordered_map<TextSink*, std::weak_ptr<TextSink>> sinks_;

 public:
  // Declared last, so destroyed first: the handlers still queued in the io_context (a session
  // posted to, a connection's write) are destroyed while everything they hold can still be let
  // go: the registry above, and the pools whose strands a session's recorder or a replay holds.
  // The pools are joined (empty) before; their strands outlive the io_context's handlers.
  boost::asio::thread_pool recorder{1};  // recordings' disk writes, off the network threads
  boost::asio::thread_pool workers;
  boost::asio::io_context ioc;
};

// The WebSocket routes (ws_endpoints.cc): /ws/library, /ws/agent, /ws/session/{id} and
// /ws/replay/{id}, each with the function that builds its endpoint.
void AppendWebSocketRoutes(ServerCore& core, std::vector<Route>* routes);

// Wall-clock helpers (clock.cc). Unix time in ns; "2026-11-23T19:04:05Z" as Unix ns (0 when it
// does not parse); `bytes` random bytes as hex.
uint64_t UnixNs();
uint64_t ParseUtcNs(const std::string& iso);
std::string RandomHex(size_t bytes);

// The sessions' REST routes (sessions_api.cc).
void AppendSessionRoutes(ServerCore& core, std::vector<Route>* routes);

// An accepted connection's socket on its own strand, the executor's type spelled out: the
// operations on it (Beast's included) then call the strand directly instead of through
// any_io_executor's type erasure, which a profile at 1,000 viewers showed on every message
// (any_executor copies, prefer and require calls).
using ConnectionStrand = boost::asio::strand<boost::asio::io_context::executor_type>;
using AcceptedSocket = boost::asio::basic_stream_socket<boost::asio::ip::tcp, ConnectionStrand>;

// Takes an accepted socket: takes its connection slot (else a 503 and close), then runs an HTTP
// session (plain or TLS) on its strand.
void Launch(ServerCore& core, AcceptedSocket socket);

}  // namespace idms::server
