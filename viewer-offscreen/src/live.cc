// The live viewer: Beast's synchronous WebSocket client, one thread, a read timeout per frame.
#include "idms/render/live.h"

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>

#include "idms/protocol/cli.h"
#include "idms/protocol/envelope.h"

namespace idms::render {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace websocket = beast::websocket;

namespace {

// Beast 1.74 does not fill the response of a declined upgrade: the same request as plain HTTP
// says why ("HTTP 401: {\"error\": \"unknown token\"}").
std::string DeclinedReason(const asio::ip::tcp::resolver::results_type& endpoints, const std::string& host,
                           const std::string& target, const std::string& token) {
  asio::io_context io;
  beast::tcp_stream stream(io);
  stream.expires_after(std::chrono::seconds(10));
  beast::error_code ec;
  stream.connect(endpoints, ec);
  namespace http = beast::http;
  http::request<http::empty_body> req{http::verb::get, target, 11};
  req.set(http::field::host, host);
  req.set(http::field::connection, "Upgrade");
  req.set(http::field::upgrade, "websocket");
  req.set(http::field::sec_websocket_version, "13");
  req.set(http::field::sec_websocket_key, "dGhlIHNhbXBsZSBub25jZQ==");
  if (!token.empty()) req.set(http::field::authorization, "Bearer " + token);
  http::response<http::string_body> res;
  beast::flat_buffer buffer;
  if (!ec) http::write(stream, req, ec);
  if (!ec) http::read(stream, buffer, res, ec);
  if (ec) return "";
  return " (HTTP " + std::to_string(res.result_int()) + ": " + res.body().substr(0, 300) + ")";
}

}  // namespace

bool WatchLive(const LiveOptions& o, ViewerState* state, const std::function<bool(const ViewerState&)>& on_update,
               std::string* error) {
  ServerUrl url;
  if (!ParseServerUrl(o.url, "--server", &url, error)) return false;
  const std::string &host = url.host, &port = url.port;
  asio::io_context io;
  websocket::stream<beast::tcp_stream> ws(io);
  beast::error_code ec;
  const auto timeout = std::chrono::milliseconds(static_cast<int64_t>(o.timeout_s * 1000));
  // Connect and hand-shake as a viewer of the session.
  asio::ip::tcp::resolver resolver(io);
  const auto endpoints = resolver.resolve(host, port, ec);
  if (ec) return *error = "cannot resolve " + host + ": " + ec.message(), false;
  beast::get_lowest_layer(ws).expires_after(timeout);
  beast::get_lowest_layer(ws).connect(endpoints, ec);
  if (ec) return *error = "cannot connect to " + host + ":" + port + ": " + ec.message(), false;
  const std::string token = o.token;
  ws.set_option(websocket::stream_base::decorator([token](websocket::request_type& req) {
    if (!token.empty()) req.set(beast::http::field::authorization, "Bearer " + token);
  }));
  websocket::response_type response;
  ws.handshake(response, host + ":" + port, "/ws/session/" + o.session, ec);
  if (ec) {
    *error = "the server refused /ws/session/" + o.session + ": " + ec.message() +
             DeclinedReason(endpoints, host + ":" + port, "/ws/session/" + o.session, o.token);
    return false;
  }
  beast::get_lowest_layer(ws).expires_never();
  ws.set_option(websocket::stream_base::timeout{timeout, timeout, false});
  // Frames until the session ends or the caller has what it wanted.
  beast::flat_buffer buffer;
  std::vector<v1::Envelope> frames;
  for (bool more = true; more;) {
    buffer.consume(buffer.size());
    ws.read(buffer, ec);
    if (ec == websocket::error::closed) return true;
    if (ec) return *error = "reading the session: " + ec.message(), false;
    const auto data = buffer.data();
    frames.clear();
    if (!ParseFrames(std::string_view(static_cast<const char*>(data.data()), data.size()), &frames, error))
      return false;
    for (const v1::Envelope& e : frames) {
      if (e.has_welcome()) state->SetScene(e.welcome().scene());
      if (e.has_session_event() && e.session_event().kind() == v1::SessionEvent::KIND_ERROR)
        return *error = "the server: " + e.session_event().message(), false;
      if (!state->Apply(e, error)) return false;
      const bool mesh = e.has_mesh_keyframe() || e.has_mesh_delta();
      if (mesh && state->mirror.has_keyframe() && !on_update(*state)) {
        more = false;
        break;
      }
    }
  }
  ws.close(websocket::close_code::normal, ec);
  return true;
}

}  // namespace idms::render
