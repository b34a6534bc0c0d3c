// One HTTP session per connection, in the shape of Beast's advanced server: DoRead/OnRead and
// DoWrite/OnWrite on the connection's strand, one request at a time, one write in flight, the
// header admitted (route, auth, Origin, size) before any of the body is read, handlers run on the
// worker pool. A WebSocket upgrade hands the stream to a WebSocket session with a bounded
// send queue. The same code serves plain TCP and TLS (Stream = TcpStream or ssl_stream of it).
#include <boost/asio/dispatch.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/ssl/stream.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl.hpp>
#include <boost/beast/websocket.hpp>
#include <boost/beast/websocket/ssl.hpp>
#include <cmath>
#include <deque>

#include "idms/server/log.h"
#include "server_internal.h"
#include "ws_endpoint.h"

namespace idms::server {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using Clock = std::chrono::steady_clock;

constexpr uint64_t kLargeBody = 1 << 20;              // bodies above this take an upload slot
constexpr size_t kMaxQueuedMessages = 1024;           // per WebSocket; the oldest is dropped beyond (as Foxglove's SDK)
constexpr size_t kMaxQueuedBytes = size_t{32} << 20;  // likewise in bytes (a keyframe of 10^6 vertices fits)
// A WebSocket told to close that has not finished within this long (a peer that stopped reading,
// so neither its queue nor the close frame can go out) loses its TCP connection.
constexpr auto kCloseGrace = std::chrono::seconds(5);

// A TCP stream on the connection's strand (server_internal.h: why the executor's type is spelled out).
using TcpStream = beast::basic_stream<tcp, ConnectionStrand>;

template <class Stream>
constexpr bool kIsTls = !std::is_same_v<Stream, TcpStream>;

// Errors that mean "the peer went away or we closed it": not worth a warning. A browser tab
// closed while its socket reads ends with ENOTCONN (Beast's teardown after the peer's close frame
// or FIN raced the read), which is as normal as an EOF.
bool Quiet(const beast::error_code& ec) {
  return ec == asio::error::operation_aborted || ec == beast::error::timeout || ec == http::error::end_of_stream ||
         ec == asio::error::eof || ec == asio::error::connection_reset || ec == asio::error::broken_pipe ||
         ec == asio::error::not_connected || ec == asio::error::connection_aborted || ec == websocket::error::closed ||
         ec == asio::ssl::error::stream_truncated;
}

// ---------------------------------------------------------------------------------------------
// A WebSocket connection: the stream, a bounded send queue (one write in flight), a read loop with
// size and rate limits, and the endpoint (ws_endpoint.h) that gives the messages their meaning.
template <class Stream>
class WsSession : public Connection, public WsPeer, public std::enable_shared_from_this<WsSession<Stream>> {
 public:
  // `slot`: the connection's place, taken over from the HTTP session that upgraded.
  WsSession(ServerCore& core, ConnectionSlot slot, Stream&& stream, std::string peer,
            std::shared_ptr<WsEndpoint> endpoint)
      : core_(core),
        slot_(std::move(slot)),
        ws_(std::move(stream)),
        peer_(std::move(peer)),
        endpoint_(std::move(endpoint)) {
    ++core_.metrics.open_websockets;
  }
  ~WsSession() override {
    --core_.metrics.open_websockets;
    core_.Unregister(this);
  }

  void Run(http::request<http::string_body> req) {
    beast::get_lowest_layer(ws_).expires_never();  // the WebSocket's own timeouts from here on
    if (core_.options.ws_send_buffer_bytes > 0) {
      beast::error_code ignored;  // a refused size leaves the system's: not worth failing for
      beast::get_lowest_layer(ws_).socket().set_option(
          asio::socket_base::send_buffer_size(core_.options.ws_send_buffer_bytes), ignored);
    }
    // A peer silent for the endpoint's idle time is pinged at half of it and dropped at the end:
    // a link that died without a close (a Wi-Fi drop) is noticed, not held open for ever.
    ws_.set_option(websocket::stream_base::timeout{std::chrono::seconds(30), endpoint_->idle_timeout(), true});
    ws_.set_option(websocket::stream_base::decorator(
        [](websocket::response_type& res) { res.set(http::field::server, "idms-server"); }));
    ws_.read_message_max(static_cast<uint64_t>(core_.options.max_ws_message_bytes));
    ws_.async_accept(req, beast::bind_front_handler(&WsSession::OnAccept, this->shared_from_this()));
  }

  void Send(std::shared_ptr<const std::string> message, bool binary) override {
    asio::post(ws_.get_executor(), [self = this->shared_from_this(), message = std::move(message), binary]() mutable {
      if (!self->open_ || self->close_pending_) return;
      // Bounded in messages and in bytes: the oldest queued messages (never the one being
      // written) go first.
      while (self->queue_.size() > 1 &&
             (self->queue_.size() >= kMaxQueuedMessages || self->queued_bytes_ + message->size() > kMaxQueuedBytes)) {
        self->queued_bytes_ -= self->queue_[1].bytes->size();
        self->queue_.erase(self->queue_.begin() + 1);
      }
      self->queued_bytes_ += message->size();
      self->queue_.push_back({std::move(message), binary});
      self->Published();
      if (self->queue_.size() == 1) self->DoWrite();
    });
  }

  void Close(uint16_t code, std::string reason) override {
    asio::post(ws_.get_executor(), [self = this->shared_from_this(), code, reason = std::move(reason)]() mutable {
      if (!self->open_ || self->close_pending_) return;
      self->close_pending_ = true;
      self->close_reason_ = websocket::close_reason(static_cast<websocket::close_code>(code), reason);
      self->close_timer_.expires_after(kCloseGrace);
      self->close_timer_.async_wait([self](beast::error_code ec) {
        if (ec || !self->open_) return;
        Log(LogLevel::kWarn, "websocket",
            {{"what", "close"}, {"error", "peer not reading; connection dropped"}, {"peer", self->peer_}});
        beast::get_lowest_layer(self->ws_).close();  // the pending write and close end with an error
      });
      if (self->queue_.empty()) self->DoClose();
    });
  }

  size_t queued() const override { return queued_.load(std::memory_order_relaxed); }
  size_t queued_bytes() const override { return queued_bytes_shared_.load(std::memory_order_relaxed); }
  const std::string& peer() const override { return peer_; }
  void Drain() override { Close(static_cast<uint16_t>(websocket::close_code::going_away), "server shutting down"); }

 private:
  struct Outgoing {
    std::shared_ptr<const std::string> bytes;
    bool binary;
  };

  void OnAccept(beast::error_code ec) {
    if (ec) return Fail(ec, "accept");
    open_ = true;
    core_.Register(this, this->weak_from_this());
    window_start_ = Clock::now();
    endpoint_->OnOpen(std::weak_ptr<WsPeer>(this->shared_from_this()));
    DoRead();
  }

  void DoRead() { ws_.async_read(buffer_, beast::bind_front_handler(&WsSession::OnRead, this->shared_from_this())); }

  void OnRead(beast::error_code ec, size_t bytes) {
    if (ec) return Fail(ec, "read");
    core_.metrics.AddBytesIn(bytes);
    // Rate limit: messages per one-second window.
    const Clock::time_point now = Clock::now();
    if (now - window_start_ >= std::chrono::seconds(1)) window_start_ = now, window_count_ = 0;
    if (++window_count_ > endpoint_->max_messages_per_s()) {
      Close(static_cast<uint16_t>(websocket::close_code::policy_error),
            "more than " + std::to_string(endpoint_->max_messages_per_s()) + " messages per second");
      return;
    }
    const auto data = buffer_.data();
    endpoint_->OnMessage(std::string_view(static_cast<const char*>(data.data()), data.size()), ws_.got_binary());
    buffer_.consume(buffer_.size());
    if (open_) DoRead();
  }

  void DoWrite() {
    if (!open_) return;
    ws_.binary(queue_.front().binary);
    ws_.async_write(asio::buffer(*queue_.front().bytes),
                    beast::bind_front_handler(&WsSession::OnWrite, this->shared_from_this()));
  }

  void OnWrite(beast::error_code ec, size_t bytes) {
    if (ec) return Fail(ec, "write");
    core_.metrics.AddBytesOut(bytes);
    queued_bytes_ -= queue_.front().bytes->size();
    queue_.erase(queue_.begin());
    Published();
    if (!queue_.empty()) return DoWrite();
    if (close_pending_) return DoClose();
    endpoint_->OnDrained();
  }

  void DoClose() {
    ws_.async_close(close_reason_, [self = this->shared_from_this()](beast::error_code) { self->Closed(); });
  }

  // The queue's size for other threads' back-pressure decisions.
  void Published() {
    queued_.store(queue_.size(), std::memory_order_relaxed);
    queued_bytes_shared_.store(queued_bytes_, std::memory_order_relaxed);
  }

  void Fail(beast::error_code ec, const char* what) {
    if (!Quiet(ec) && ec != websocket::error::message_too_big)
      Log(LogLevel::kWarn, "websocket", {{"what", what}, {"error", ec.message()}, {"peer", peer_}});
    Closed();
  }

  // Once, whichever side ended it: the endpoint lets go of this connection.
  void Closed() {
    close_timer_.cancel();
    queue_.clear();
    queued_bytes_ = 0;
    Published();
    if (!open_) return;
    open_ = false;
    endpoint_->OnClose();
  }

  ServerCore& core_;
  ConnectionSlot slot_;
  websocket::stream<Stream> ws_;
  beast::flat_buffer buffer_;
  std::deque<Outgoing> queue_;
  size_t queued_bytes_ = 0;  // of queue_
  std::atomic<size_t> queued_{0}, queued_bytes_shared_{0};
  std::string peer_;
  std::shared_ptr<WsEndpoint> endpoint_;
  bool open_ = false;
  bool close_pending_ = false;
  websocket::close_reason close_reason_;
  asio::steady_timer close_timer_{ws_.get_executor()};
  Clock::time_point window_start_;
  int window_count_ = 0;
};

// ---------------------------------------------------------------------------------------------
template <class Stream>
class HttpSession : public Connection, public std::enable_shared_from_this<HttpSession<Stream>> {
 public:
  template <class... Args>
  HttpSession(ServerCore& core, ConnectionSlot slot, std::string peer, Args&&... stream_args)
      : core_(core), slot_(std::move(slot)), stream_(std::forward<Args>(stream_args)...), peer_(std::move(peer)) {}
  ~HttpSession() override {
    ReleaseUploadSlot();
    core_.Unregister(this);
  }

  void Run() {
    core_.Register(this, this->weak_from_this());
    asio::dispatch(stream_.get_executor(), [self = this->shared_from_this()] {
      if constexpr (kIsTls<Stream>) {
        beast::get_lowest_layer(self->stream_).expires_after(self->core_.options.header_timeout);
        self->stream_.async_handshake(asio::ssl::stream_base::server,
                                      beast::bind_front_handler(&HttpSession::OnHandshake, self));
      } else {
        self->DoRead();
      }
    });
  }

  void Drain() override {
    asio::post(stream_.get_executor(), [self = this->shared_from_this()] {
      // Idle (waiting for a request): close now; busy: the response says Connection: close.
      if (!self->busy_) beast::get_lowest_layer(self->stream_).socket().cancel();
    });
  }

 private:
  void OnHandshake(beast::error_code ec) {
    if (ec) return Fail(ec, "tls handshake");
    DoRead();
  }

  void DoRead() {
    busy_ = false;
    if (core_.draining) return DoClose();
    parser_.emplace();
    parser_->header_limit(core_.options.max_header_bytes);
    // Beast checks Content-Length against this as the header is parsed; admission then applies
    // the route's own limit (413 before any of the body is read).
    parser_->body_limit(
        static_cast<uint64_t>(std::max(core_.options.max_upload_bytes, core_.options.max_small_body_bytes)));
    // One deadline for the whole header: a client sending a byte a second is cut off.
    beast::get_lowest_layer(stream_).expires_after(core_.options.header_timeout);
    http::async_read_header(stream_, buffer_, *parser_,
                            beast::bind_front_handler(&HttpSession::OnReadHeader, this->shared_from_this()));
  }

  void OnReadHeader(beast::error_code ec, size_t bytes) {
    if (ec == http::error::end_of_stream) return DoClose();
    if (ec == http::error::header_limit)
      return req_ = ApiRequest{}, Refuse(http::status::request_header_fields_too_large, "header too large");
    if (ec == http::error::body_limit)
      return req_ = ApiRequest{}, Refuse(http::status::payload_too_large, "body too large");
    if (ec) return Fail(ec, "read header");
    busy_ = true;
    started_ = Clock::now();
    bytes_in_ = bytes;
    req_ = ApiRequest{};
    req_.message = parser_->get();
    req_.tls = kIsTls<Stream>;
    req_.peer = peer_;
    admission_ = Admit(core_.ctx, core_.routes, req_);
    if (admission_.error) {
      // The body (if any) stays unread, so the connection cannot be reused.
      const bool has_body = req_.message.chunked() || parser_->content_length().value_or(0) > 0;
      return Write(std::move(*admission_.error), has_body);
    }
    if (admission_.route->websocket) return Upgrade();
    // Large bodies are bounded in number, so a burst of uploads cannot exhaust memory.
    // The parser's Content-Length (the message's payload_size() is its body's, still empty here).
    const uint64_t announced = parser_->content_length().value_or(req_.message.chunked() ? kLargeBody + 1 : 0);
    if (announced > kLargeBody) {
      if (++core_.uploads_in_flight > core_.options.max_concurrent_uploads) {
        --core_.uploads_in_flight;
        ApiResponse res = JsonError(req_, http::status::service_unavailable, "too many uploads in progress; retry");
        res.set(http::field::retry_after, "5");
        return Write(std::move(res), true);
      }
      holds_upload_slot_ = true;
    }
    parser_->body_limit(admission_.body_limit);
    // Beast reads into the buffer's free capacity (512 bytes at least): a large body read in
    // header-sized pieces is 40x slower than in 256 KiB ones (measured: 120 MB in 2.2 s).
    if (announced > kLargeBody) buffer_.reserve(256 << 10);
    beast::get_lowest_layer(stream_).expires_after(core_.options.body_timeout + std::chrono::seconds(announced >> 20));
    if (beast::iequals(req_.message[http::field::expect], "100-continue")) {
      continue_.emplace(http::status::continue_, req_.message.version());
      http::async_write(stream_, *continue_, [self = this->shared_from_this()](beast::error_code ec2, size_t) {
        if (ec2) return self->Fail(ec2, "write 100-continue");
        self->DoReadBody();
      });
      return;
    }
    DoReadBody();
  }

  void DoReadBody() {
    body_started_ = Clock::now();
    http::async_read(stream_, buffer_, *parser_,
                     beast::bind_front_handler(&HttpSession::OnReadBody, this->shared_from_this()));
  }

  void OnReadBody(beast::error_code ec, size_t bytes) {
    bytes_in_ += bytes;
    if (ec == http::error::body_limit)
      return Refuse(http::status::payload_too_large,
                    "body exceeds the limit of " + std::to_string(admission_.body_limit) + " bytes");
    if (ec) return Fail(ec, "read body");
    read_ms_ = std::chrono::duration<double, std::milli>(Clock::now() - body_started_).count();
    if (buffer_.capacity() > (64 << 10) && buffer_.size() == 0) buffer_.shrink_to_fit();
    req_.message = parser_->release();
    // Blocking handlers (parse, hash, file I/O, fsync) on a worker, never on an I/O thread; the
    // others here, on the strand.
    if (!admission_.route->blocking) return WriteReply(RunHandler());
    asio::post(core_.workers, [self = this->shared_from_this()] {
      HandlerResponse res = self->RunHandler();
      asio::post(self->stream_.get_executor(),
                 [self, res = std::move(res)]() mutable { self->WriteReply(std::move(res)); });
    });
  }

  HandlerResponse RunHandler() {
    try {
      return admission_.route->handler(core_.ctx, req_);
    } catch (const std::exception& e) {
      Log(LogLevel::kError, "handler threw", {{"route", admission_.route->pattern}, {"error", e.what()}});
      return JsonError(req_, http::status::internal_server_error, "internal error");
    }
  }

  void Upgrade() {
    std::string refusal;
    std::shared_ptr<WsEndpoint> endpoint = admission_.route->open_websocket(req_, &refusal);
    if (!endpoint) return Write(JsonError(req_, http::status::not_found, refusal), false);
    // The connection slot goes with the stream: a WebSocket counts against the limits until it closes.
    auto ws = std::make_shared<WsSession<Stream>>(core_, std::move(slot_), std::move(stream_),
                                                  std::string(RoleName(req_.role)) + " " + peer_, std::move(endpoint));
    AccessLog(101, 0);
    ws->Run(parser_->release());
  }

  // A response to a request whose body could not be read: sent, then the connection closes.
  void Refuse(http::status status, const std::string& message) {
    busy_ = true;
    Write(JsonError(req_, status, message), true);
  }

  void WriteReply(HandlerResponse res) {
    std::visit([this](auto& r) { this->Write(std::move(r), false); }, res);
  }

  // Any body: a string, or a file sent in pieces (FileRangeBody).
  template <class Body>
  void Write(http::response<Body> res, bool close_after) {
    res.set(http::field::server, "idms-server");
    res.keep_alive(!close_after && !core_.draining && req_.message.keep_alive());
    res.prepare_payload();
    // HEAD: the headers of the GET, Content-Length included, and no body.
    if constexpr (!std::is_same_v<Body, http::empty_body>) {
      if (req_.message.method() == http::verb::head) {
        const uint64_t length = res.payload_size().value_or(0);
        http::response<http::empty_body> head(std::move(res.base()));
        head.content_length(length);
        return Send(std::move(head));
      }
    }
    Send(std::move(res));
  }

  // A complete response, written as it is; one write in flight.
  template <class Body>
  void Send(http::response<Body> res) {
    auto response = std::make_shared<http::response<Body>>(std::move(res));
    response_status_ = response->result_int();
    response_keep_alive_ = response->keep_alive();
    response_ = response;
    beast::get_lowest_layer(stream_).expires_after(core_.options.body_timeout +
                                                   std::chrono::seconds(response->payload_size().value_or(0) >> 20));
    http::async_write(stream_, *response, beast::bind_front_handler(&HttpSession::OnWrite, this->shared_from_this()));
  }

  void OnWrite(beast::error_code ec, size_t bytes) {
    AccessLog(response_status_, bytes);
    ReleaseUploadSlot();
    response_.reset();  // a file's descriptor and piece go now
    if (ec) return Fail(ec, "write");
    if (!response_keep_alive_) return DoClose();
    DoRead();
  }

  void AccessLog(unsigned status, size_t bytes_out) {
    const double seconds = std::chrono::duration<double>(Clock::now() - started_).count();
    const std::string route = admission_.route != nullptr ? admission_.route->pattern : "(none)";
    const std::string method(req_.message.method_string());
    // Labels from the route table only, so that clients cannot grow /metrics.
    core_.metrics.CountRequest(std::string(MethodLabel(core_.routes, req_.message.method())), route,
                               static_cast<int>(status), seconds, bytes_in_, bytes_out);
    // The path only: no query string, no header, so no secret can reach the log.
    Log(LogLevel::kInfo, "request",
        {{"method", method},
         {"path", req_.path.empty() ? "?" : req_.path},
         {"route", route},
         {"status", status},
         {"bytes", bytes_out},
         {"ms", std::round(seconds * 1e4) / 10},
         {"peer", peer_}});
    if (read_ms_ >= 100) {
      Log(LogLevel::kInfo, "large body",
          {{"path", req_.path}, {"bytes_in", bytes_in_}, {"read_ms", std::round(read_ms_ * 10) / 10}});
    }
    admission_ = Admission{};
    read_ms_ = 0;
  }

  void ReleaseUploadSlot() {
    if (holds_upload_slot_) --core_.uploads_in_flight;
    holds_upload_slot_ = false;
  }

  void DoClose() {
    if constexpr (kIsTls<Stream>) {
      beast::get_lowest_layer(stream_).expires_after(std::chrono::seconds(5));
      stream_.async_shutdown([self = this->shared_from_this()](beast::error_code) {});
    } else {
      beast::error_code ignored;
      stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    }
  }

  void Fail(beast::error_code ec, const char* what) {
    if (Quiet(ec) || ec == http::error::partial_message) return;
    // Garbage on the socket: this connection closes, nobody else notices.
    Log(LogLevel::kWarn, "connection", {{"what", what}, {"error", ec.message()}, {"peer", peer_}});
  }

  ServerCore& core_;
  ConnectionSlot slot_;  // moved to the WebSocket session at an upgrade
  Stream stream_;
  beast::flat_buffer buffer_;
  std::string peer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  std::optional<http::response<http::empty_body>> continue_;
  ApiRequest req_;
  Admission admission_;
  std::shared_ptr<void> response_;  // the response being written, whatever its body
  unsigned response_status_ = 0;
  bool response_keep_alive_ = false;
  Clock::time_point started_ = Clock::now();
  Clock::time_point body_started_ = Clock::now();
  double read_ms_ = 0;  // the body's read time, for the log
  size_t bytes_in_ = 0;
  bool busy_ = false;
  bool holds_upload_slot_ = false;
};

// A whole 503 response with a JSON error, closing the connection.
std::string BusyResponse(const std::string& message) {
  const std::string body = "{\"error\":\"" + message + "\"}\n";
  return "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\nConnection: close\r\n"
         "Retry-After: 1\r\nContent-Length: " +
         std::to_string(body.size()) + "\r\n\r\n" + body;
}

// Beyond a connection limit: a canned 503 (plain) or a close (TLS), without a session.
void RejectBusy(ServerCore& core, AcceptedSocket socket, ConnectionSlots::Refusal refusal) {
  const bool per_address = refusal == ConnectionSlots::Refusal::kAddress;
  ++(per_address ? core.metrics.rejected_per_address : core.metrics.rejected_connections);
  if (core.tls) return;
  static const std::string kTotal = BusyResponse("too many connections; retry");
  static const std::string kAddress = BusyResponse("too many connections from your address; retry");
  auto s = std::make_shared<AcceptedSocket>(std::move(socket));
  asio::async_write(*s, asio::buffer(per_address ? kAddress : kTotal), [s](beast::error_code, size_t) {
    beast::error_code ignored;
    s->shutdown(tcp::socket::shutdown_both, ignored);
  });
}

}  // namespace

void Launch(ServerCore& core, AcceptedSocket socket) {
  beast::error_code ec;
  const tcp::endpoint remote = socket.remote_endpoint(ec);
  if (ec) return;  // gone already
  ConnectionSlots::Refusal refusal;
  ConnectionSlot slot = core.slots.Acquire(remote.address(), &refusal);
  if (!slot) return RejectBusy(core, std::move(socket), refusal);
  std::string peer = remote.address().to_string() + ":" + std::to_string(remote.port());
  if (core.tls) {
    std::make_shared<HttpSession<beast::ssl_stream<TcpStream>>>(core, std::move(slot), std::move(peer),
                                                                TcpStream(std::move(socket)), *core.tls)
        ->Run();
  } else {
    std::make_shared<HttpSession<TcpStream>>(core, std::move(slot), std::move(peer), std::move(socket))->Run();
  }
}

void ServerCore::Register(Connection* c, std::weak_ptr<Connection> w) {
  std::lock_guard lock(mu_);
  connections_[c] = std::move(w);
}

void ServerCore::Unregister(Connection* c) {
  std::function<void()> last;
  {
    std::lock_guard lock(mu_);
    if (connections_.erase(c) == 0) return;
    if (draining && connections_.empty()) last = on_last_connection_closed;
  }
  if (last) last();
}

void ServerCore::DrainAll() {
  std::vector<std::shared_ptr<Connection>> live;
  {
    std::lock_guard lock(mu_);
    for (auto& [ptr, weak] : connections_) {
      if (auto c = weak.lock()) live.push_back(std::move(c));
    }
    if (connections_.empty() && on_last_connection_closed) asio::post(ioc, on_last_connection_closed);
  }
  for (auto& c : live) c->Drain();
}

void ServerCore::Subscribe(TextSink* s, std::weak_ptr<TextSink> w) {
  std::lock_guard lock(mu_);
  sinks_[s] = std::move(w);
}

void ServerCore::Unsubscribe(TextSink* s) {
  std::lock_guard lock(mu_);
  sinks_.erase(s);
}

void ServerCore::Publish(const std::string& text) {
  // One immutable message shared by every watcher.
  auto message = std::make_shared<const std::string>(text);
  std::vector<std::shared_ptr<TextSink>> live;
  {
    std::lock_guard lock(mu_);
    for (auto& [ptr, weak] : sinks_) {
      if (auto s = weak.lock()) live.push_back(std::move(s));
    }
  }
  for (auto& s : live) s->Send(message);
}

}  // namespace idms::server
