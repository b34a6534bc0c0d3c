// The uplink's WebSocket connection (connection.h): Beast's client example sequence, with the
// agent's token, timeouts and message limit.
#include "connection.h"

#include <boost/asio/error.hpp>
#include <boost/beast/http.hpp>
#include <chrono>

#include "idms/sim/check.h"

namespace idms::agent {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;

std::chrono::nanoseconds Seconds(double s) { return std::chrono::nanoseconds(static_cast<int64_t>(s * 1e9)); }

}  // namespace

Connection::Connection(asio::io_context& io, const ConnectionOptions& options, ConnectionHandler& handler)
    : options_(options), handler_(&handler), resolver_(io), ws_(io) {}

void Connection::Start() {
  thread_.Check("Connection::Start");
  resolver_.async_resolve(options_.host, options_.port,
                          beast::bind_front_handler(&Connection::OnResolve, shared_from_this()));
}

void Connection::OnResolve(const beast::error_code& ec, const tcp::resolver::results_type& results) {
  if (ec) return Fail(ec, "resolve");
  // The connect timeout covers TCP and the upgrade.
  beast::get_lowest_layer(ws_).expires_after(Seconds(options_.connect_timeout_s));
  beast::get_lowest_layer(ws_).async_connect(results,
                                             beast::bind_front_handler(&Connection::OnConnect, shared_from_this()));
}

void Connection::OnConnect(const beast::error_code& ec, const tcp::endpoint&) {
  if (ec) return Fail(ec, "connect");
  // The token travels on the upgrade request, so a bad one is refused before any frame.
  const std::string auth = "Bearer " + options_.token;
  ws_.set_option(websocket::stream_base::decorator([auth](websocket::request_type& req) {
    req.set(http::field::authorization, auth);
    req.set(http::field::user_agent, "idms-agent");
  }));
  ws_.async_handshake(response_, options_.host + ":" + options_.port, options_.target,
                      beast::bind_front_handler(&Connection::OnHandshake, shared_from_this()));
}

void Connection::OnHandshake(const beast::error_code& ec) {
  if (ec) return Fail(ec, "WebSocket upgrade");
  // From here the WebSocket's own timeouts apply: pings when idle, a dead peer detected.
  beast::get_lowest_layer(ws_).expires_never();
  ws_.set_option(
      websocket::stream_base::timeout{Seconds(options_.connect_timeout_s), Seconds(options_.idle_timeout_s), true});
  // The server's messages are small; a huge one is a broken or hostile peer, not a frame to buffer.
  ws_.read_message_max(options_.read_message_max);
  ws_.binary(true);
  DoRead();
  handler_->OnOpen();
}

void Connection::DoRead() {
  ws_.async_read(read_buffer_, beast::bind_front_handler(&Connection::OnRead, shared_from_this()));
}

void Connection::OnRead(const beast::error_code& ec, size_t) {
  // The server's close frame answering ours: not a failure; OnClose reports the end.
  if (closing_ && ec == websocket::error::closed) return;
  if (ec) return Fail(ec, "read");
  if (handler_ == nullptr) return;
  const std::string payload = beast::buffers_to_string(read_buffer_.data());
  read_buffer_.consume(read_buffer_.size());
  handler_->OnMessage(payload);
  // The handler may have abandoned the connection meanwhile.
  if (handler_ != nullptr) DoRead();
}

void Connection::Write(std::string& frame) {
  thread_.Check("Connection::Write");
  IDMS_CHECK(!writing_);
  writing_ = true;
  out_.swap(frame);
  ws_.async_write(asio::buffer(out_), beast::bind_front_handler(&Connection::OnWrite, shared_from_this()));
}

void Connection::OnWrite(const beast::error_code& ec, size_t) {
  writing_ = false;
  if (ec) return Fail(ec, "write");
  if (handler_ != nullptr) handler_->OnWritten();
}

void Connection::Close() {
  thread_.Check("Connection::Close");
  closing_ = true;
  ws_.async_close(websocket::close_code::normal, beast::bind_front_handler(&Connection::OnClose, shared_from_this()));
}

void Connection::OnClose(const beast::error_code& ec) {
  if (handler_ == nullptr) return;
  ConnectionHandler* handler = handler_;
  handler_ = nullptr;
  handler->OnClosed(ec);
}

void Connection::Abandon() {
  thread_.Check("Connection::Abandon");
  handler_ = nullptr;
  beast::error_code ignored;
  beast::get_lowest_layer(ws_).socket().close(ignored);
}

void Connection::Fail(const beast::error_code& ec, const char* what) {
  // Aborted = we cancelled it (Abandon); already failed or abandoned = nobody to tell.
  if (ec == asio::error::operation_aborted || handler_ == nullptr) return;
  ConnectionHandler* handler = handler_;
  Abandon();
  handler->OnFailed(ec, what, response_);
}

}  // namespace idms::agent
