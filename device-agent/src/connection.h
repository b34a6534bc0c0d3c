// One WebSocket connection attempt of the uplink, shaped like Beast's asynchronous client
// examples: resolve, TCP connect, upgrade (with the bearer token), then a read always pending and
// at most one write in flight, every handler funnelling errors into one Fail. It knows nothing of
// the protocol: the uplink (its ConnectionHandler) does. I/O thread only; internal to the agent.
#pragma once

#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>
#include <cstddef>
#include <memory>
#include <string>
#include <string_view>

#include "idms/agent/thread_owner.h"

namespace idms::agent {

struct ConnectionOptions {
  std::string host, port;  // the server
  std::string target = "/ws/agent";
  std::string token;                  // "Authorization: Bearer TOKEN" on the upgrade request
  double connect_timeout_s = 5.0;     // resolve + connect + upgrade; then the close handshake
  double idle_timeout_s = 10.0;       // a silent server is pinged, then dropped after this
  size_t read_message_max = 1 << 20;  // bytes; the server sends Welcome, Commands and events
};

// What the connection reports, on the I/O thread. After OnFailed nothing more is reported.
class ConnectionHandler {
 public:
  virtual ~ConnectionHandler() = default;
  virtual void OnOpen() = 0;                                      // the upgrade succeeded
  virtual void OnMessage(std::string_view payload) = 0;           // one whole binary message
  virtual void OnWritten() = 0;                                   // the frame passed to Write went out
  virtual void OnClosed(const boost::beast::error_code& ec) = 0;  // our close handshake ended
  // A step failed: `what` names it ("resolve", "connect", "WebSocket upgrade", "read", "write");
  // upgrade is the server's answer to the upgrade request (status 0 when there was none).
  virtual void OnFailed(const boost::beast::error_code& ec, const char* what,
                        const boost::beast::websocket::response_type& upgrade) = 0;
};

class Connection : public std::enable_shared_from_this<Connection> {
 public:
  // handler must outlive the connection's reports (Abandon ends them).
  Connection(boost::asio::io_context& io, const ConnectionOptions& options, ConnectionHandler& handler);

  void Start();  // resolve; OnOpen or OnFailed follows
  // Sends frame (swapped into the connection's buffer: the caller gets the old one back, to
  // reuse its capacity). One write in flight: call again only after OnWritten.
  void Write(std::string& frame);
  void Close();    // the close handshake; OnClosed follows
  void Abandon();  // the handler is done with it: socket closed, nothing more reported

 private:
  void OnResolve(const boost::beast::error_code& ec, const boost::asio::ip::tcp::resolver::results_type& results);
  void OnConnect(const boost::beast::error_code& ec, const boost::asio::ip::tcp::endpoint& endpoint);
  void OnHandshake(const boost::beast::error_code& ec);
  void DoRead();
  void OnRead(const boost::beast::error_code& ec, size_t bytes);
  void OnWrite(const boost::beast::error_code& ec, size_t bytes);
  void OnClose(const boost::beast::error_code& ec);
  void Fail(const boost::beast::error_code& ec, const char* what);

  ConnectionOptions options_;
  ConnectionHandler* handler_;  // null once abandoned or failed
  boost::asio::ip::tcp::resolver resolver_;
  boost::beast::websocket::stream<boost::beast::tcp_stream> ws_;
  boost::beast::websocket::response_type response_;  // the upgrade's, for its status
  boost::beast::flat_buffer read_buffer_;
  std::string out_;  // the frame being written
  bool writing_ = false;
  bool closing_ = false;
  // The thread running its io_context; off the 1 kHz loop, so a call from another aborts.
  ThreadOwner thread_{"a connection of the uplink", ThreadOwner::OnViolation::kAbort};
};

}  // namespace idms::agent
