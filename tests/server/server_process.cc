// Server process and synchronous Beast clients for the integration tests.
#include "server_process.h"

#include <algorithm>
#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/ssl/rfc2818_verification.hpp>
#include <boost/asio/ssl/stream.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl.hpp>
#include <boost/beast/websocket.hpp>
#include <boost/beast/websocket/ssl.hpp>
#include <csignal>
#include <nlohmann/json.hpp>
#include <sstream>

namespace idms::test {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;

template <class Stream>
HttpReply Exchange(Stream& stream, uint16_t port, const HttpCall& call) {
  HttpReply reply;
  http::request<http::string_body> req{http::string_to_verb(call.method), call.target, 11};
  req.set(http::field::host, "127.0.0.1:" + std::to_string(port));
  for (const auto& [k, v] : call.headers) req.set(k, v);
  req.body() = call.body;
  req.prepare_payload();
  beast::error_code ec;
  http::write(stream, req, ec);
  if (ec) {
    reply.error = "write: " + ec.message();
    return reply;
  }
  beast::flat_buffer buffer;
  http::response_parser<http::string_body> parser;
  parser.body_limit(1ull << 32);
  http::read(stream, buffer, parser, ec);
  if (ec) {
    reply.error = "read: " + ec.message();
    return reply;
  }
  reply.status = parser.get().result_int();
  for (const auto& f : parser.get()) {
    std::string name(f.name_string());
    for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    reply.headers[name] = std::string(f.value());
  }
  reply.body = std::move(parser.get().body());
  return reply;
}

}  // namespace

ServerProcess::ServerProcess(const std::string& data_dir, const std::vector<std::string>& extra) : data_dir_(data_dir) {
  std::vector<std::string> args = {"--data", data_dir};
  if (std::find(extra.begin(), extra.end(), "--listen") == extra.end())
    args.insert(args.end(), {"--listen", "127.0.0.1:0"});
  args.insert(args.end(), extra.begin(), extra.end());
  process_ = std::make_unique<ChildProcess>(IDMS_SERVER_BIN, args, data_dir + ".log", true);
  // "idms-server listening on http://127.0.0.1:PORT"
  const auto line = process_->ReadLine(std::chrono::seconds(60));
  if (!line) return;
  const size_t colon = line->rfind(':');
  if (colon != std::string::npos) port_ = static_cast<uint16_t>(std::stoi(line->substr(colon + 1)));
}

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kSanitized = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif
#else
constexpr bool kSanitized = false;
#endif

ServerProcess::~ServerProcess() {
  // A graceful stop finishes requests in flight for up to 10 s; beyond 30 s the SIGKILL follows.
  if (kSanitized && process_ && process_->started()) {
    process_->Signal(SIGTERM);
    process_->Wait(std::chrono::seconds(30));
  }
}

std::string ServerProcess::Token(const std::string& role) const {
  std::istringstream in(ReadText(data_dir_ + "/tokens"));
  std::string r, t;
  while (in >> r) {
    if (r.front() == '#') {
      std::getline(in, t);
      continue;
    }
    in >> t;
    if (r == role) return t;
  }
  return {};
}

HttpReply Http(uint16_t port, const HttpCall& call, asio::ssl::context* tls) {
  asio::io_context io;
  beast::tcp_stream tcp_stream(io);
  tcp_stream.expires_after(std::chrono::seconds(120));
  beast::error_code ec;
  if (!call.from.empty()) {
    tcp_stream.socket().open(tcp::v4(), ec);
    if (!ec) tcp_stream.socket().bind(tcp::endpoint(asio::ip::make_address(call.from), 0), ec);
    if (ec) return HttpReply{0, {}, {}, "bind " + call.from + ": " + ec.message()};
  }
  tcp_stream.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port), ec);
  if (ec) return HttpReply{0, {}, {}, "connect: " + ec.message()};
  if (tls == nullptr) return Exchange(tcp_stream, port, call);
  beast::ssl_stream<beast::tcp_stream> stream(std::move(tcp_stream), *tls);
  stream.set_verify_mode(asio::ssl::verify_peer);
  stream.set_verify_callback(asio::ssl::rfc2818_verification("localhost"));
  stream.handshake(asio::ssl::stream_base::client, ec);
  if (ec) return HttpReply{0, {}, {}, "tls handshake: " + ec.message()};
  return Exchange(stream, port, call);
}

HttpReply Get(uint16_t port, const std::string& target, const std::string& token) {
  HttpCall call{"GET", target, {}, ""};
  if (!token.empty()) call.headers.push_back({"Authorization", "Bearer " + token});
  return Http(port, call);
}

std::string RawExchange(uint16_t port, const std::string& bytes, std::chrono::milliseconds timeout) {
  asio::io_context io;
  beast::tcp_stream stream(io);
  beast::error_code ec;
  stream.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port), ec);
  if (ec) return {};
  stream.expires_after(timeout);
  asio::write(stream, asio::buffer(bytes), ec);
  std::string out;
  char buf[4096];
  while (true) {
    const size_t n = stream.read_some(asio::buffer(buf), ec);
    out.append(buf, n);
    if (ec) break;
  }
  return out;
}

WsResult WsConnect(uint16_t port, const std::string& target,
                   const std::vector<std::pair<std::string, std::string>>& headers, asio::ssl::context* tls) {
  WsResult result;
  asio::io_context io;
  beast::tcp_stream tcp_stream(io);
  tcp_stream.expires_after(std::chrono::seconds(30));
  beast::error_code ec;
  tcp_stream.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port), ec);
  if (ec) return WsResult{0, {}, "connect: " + ec.message()};
  auto run = [&](auto& ws) {
    ws.set_option(websocket::stream_base::decorator([&](websocket::request_type& req) {
      for (const auto& [k, v] : headers) req.set(k, v);
    }));
    websocket::response_type res;
    ws.handshake(res, "127.0.0.1:" + std::to_string(port), target, ec);
    result.status = res.result_int();
    if (ec) {
      result.error = ec.message();
      // Beast 1.74 does not fill `res` on a declined upgrade: ask again as plain HTTP for the status.
      HttpCall call{"GET", target, headers, ""};
      call.headers.insert(call.headers.end(), {{"Connection", "Upgrade"},
                                               {"Upgrade", "websocket"},
                                               {"Sec-WebSocket-Version", "13"},
                                               {"Sec-WebSocket-Key", "dGhlIHNhbXBsZSBub25jZQ=="}});
      result.status = Http(port, call, tls).status;
      return;
    }
    beast::flat_buffer buffer;
    ws.read(buffer, ec);
    if (!ec) result.first_message = beast::buffers_to_string(buffer.data());
  };
  if (tls == nullptr) {
    websocket::stream<beast::tcp_stream> ws(std::move(tcp_stream));
    run(ws);
  } else {
    websocket::stream<beast::ssl_stream<beast::tcp_stream>> ws(std::move(tcp_stream), *tls);
    beast::get_lowest_layer(ws).expires_after(std::chrono::seconds(30));
    ws.next_layer().set_verify_mode(asio::ssl::verify_peer);
    ws.next_layer().set_verify_callback(asio::ssl::rfc2818_verification("localhost"));
    ws.next_layer().handshake(asio::ssl::stream_base::client, ec);
    if (ec) return WsResult{0, {}, "tls handshake: " + ec.message()};
    run(ws);
  }
  return result;
}

std::string JsonUpload(const std::string& fem, const std::string& plg, const std::string& description) {
  return nlohmann::json{{"fem", fem}, {"plg", plg}, {"description", description}}.dump();
}

}  // namespace idms::test
