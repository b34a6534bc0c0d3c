// The agent tests' stand-in server: Beast HTTP + WebSocket on one loopback port, one io_context
// thread, a session object per connection; every received Envelope is recorded under a lock.
#include "test_endpoint.h"

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <deque>

#include "idms/protocol/envelope.h"

namespace idms::test {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;

constexpr const char* kSessionId = "session-1";
constexpr const char* kResumeToken = "resume-7f3a";

}  // namespace

struct TestEndpoint::Impl : std::enable_shared_from_this<TestEndpoint::Impl> {
  explicit Impl(EndpointOptions o) : options(std::move(o)), acceptor(io) {}

  EndpointOptions options;
  asio::io_context io;
  tcp::acceptor acceptor;

  // Shared with the test thread.
  std::mutex mu;
  std::condition_variable cv;
  std::vector<ConnectionRecord> connections;
  int64_t samples = 0;
  int64_t next_tick = 0;  // the first tick not received yet (for Welcome.next_tick on resume)
  bool dropped_once = false;

  // A connection: HTTP request first, then maybe a WebSocket.
  struct Session : std::enable_shared_from_this<Session> {
    Session(Impl& impl_in, tcp::socket socket) : impl(impl_in), stream(std::move(socket)) {}
    Impl& impl;
    beast::tcp_stream stream;
    std::unique_ptr<websocket::stream<beast::tcp_stream>> ws;
    beast::flat_buffer buffer;
    http::request<http::string_body> request;
    std::deque<std::string> out;
    bool writing = false;
    int record = -1;  // index into impl.connections

    void Start() {
      http::async_read(stream, buffer, request, [self = shared_from_this()](beast::error_code ec, size_t) {
        if (!ec) self->OnRequest();
      });
    }

    bool Authorized() const { return request[http::field::authorization] == "Bearer " + impl.options.token; }

    void Respond(http::status status, std::string body) {
      auto res = std::make_shared<http::response<http::string_body>>(status, 11);
      res->set(http::field::content_type, "text/plain");
      res->body() = std::move(body);
      res->keep_alive(false);
      res->prepare_payload();
      http::async_write(stream, *res, [self = shared_from_this(), res](beast::error_code, size_t) {
        beast::error_code ignored;
        self->stream.socket().shutdown(tcp::socket::shutdown_send, ignored);
      });
    }

    void OnRequest() {
      const std::string target(request.target());
      // WebSocket only: the token on the upgrade request, then Hello.
      if (!websocket::is_upgrade(request) || target != "/ws/agent") {
        return Respond(http::status::not_found, "no such endpoint");
      }
      if (!Authorized()) return Respond(http::status::unauthorized, "bad token");
      ws = std::make_unique<websocket::stream<beast::tcp_stream>>(std::move(stream));
      ws->binary(true);
      ws->async_accept(request, [self = shared_from_this()](beast::error_code ec) {
        if (ec) return;
        self->ws->async_read(self->buffer, [self](beast::error_code ec2, size_t) {
          if (!ec2) self->OnHello();
        });
      });
    }

    void OnHello() {
      v1::Envelope in;
      std::string error;
      const bool ok = ParseEnvelope(beast::buffers_to_string(buffer.data()), &in, &error) && in.has_hello();
      buffer.consume(buffer.size());
      if (!ok) return;
      // New session, or a resume with the right token.
      v1::Envelope reply;
      {
        std::lock_guard lock(impl.mu);
        const v1::Hello& hello = in.hello();
        if (!hello.session_id().empty() && (hello.session_id() != kSessionId || hello.resume_token() != kResumeToken)) {
          v1::SessionEvent* event = reply.mutable_session_event();
          event->set_kind(v1::SessionEvent::KIND_ERROR);
          event->set_message("unknown session or bad resume token");
        } else {
          v1::Welcome* w = reply.mutable_welcome();
          w->set_protocol_version(kProtocolVersion);
          w->set_role(v1::ROLE_AGENT);
          w->set_identity("test-endpoint");
          w->set_session_id(kSessionId);
          w->set_resume_token(kResumeToken);
          w->set_next_tick(static_cast<uint64_t>(impl.next_tick));
        }
        ConnectionRecord r;
        r.hello = hello;
        if (reply.has_welcome()) r.welcome = reply.welcome();
        record = static_cast<int>(impl.connections.size());
        impl.connections.push_back(std::move(r));
      }
      impl.cv.notify_all();
      std::string bytes;
      SerializeEnvelope(reply, &bytes);
      Send(std::move(bytes));
      DoRead();
    }

    void DoRead() {
      ws->async_read(buffer, [self = shared_from_this()](beast::error_code ec, size_t) { self->OnRead(ec); });
    }

    void OnRead(beast::error_code ec) {
      if (ec) {
        {
          std::lock_guard lock(impl.mu);
          ConnectionRecord& r = impl.connections[static_cast<size_t>(record)];
          r.close_frame = r.close_frame || ec == websocket::error::closed;
          r.ended = true;
        }
        impl.cv.notify_all();
        return;
      }
      v1::Envelope in;
      std::string error;
      const bool ok = ParseEnvelope(beast::buffers_to_string(buffer.data()), &in, &error);
      buffer.consume(buffer.size());
      bool drop = false;
      std::string final_ack;  // the answer to ENDED, as the server's: everything is stored
      {
        std::lock_guard lock(impl.mu);
        ConnectionRecord& r = impl.connections[static_cast<size_t>(record)];
        if (ok && in.has_session_event() && in.session_event().kind() == v1::SessionEvent::KIND_ENDED) {
          v1::Envelope ack;
          ack.mutable_ack()->set_next_tick(static_cast<uint64_t>(impl.next_tick));
          ack.mutable_ack()->set_final(true);
          SerializeEnvelope(ack, &final_ack);
        }
        if (ok) {
          if (in.has_device_samples()) {
            impl.samples += in.device_samples().samples_size();
            const int n = in.device_samples().samples_size();
            if (n > 0) impl.next_tick = static_cast<int64_t>(in.device_samples().samples(n - 1).tick()) + 1;
          }
          r.frames.push_back(std::move(in));
        }
        // The forced disconnect: no close frame, just a dead socket.
        if (!impl.dropped_once && impl.options.drop_after_samples >= 0 &&
            impl.samples >= impl.options.drop_after_samples) {
          impl.dropped_once = true;
          r.dropped_by_endpoint = true;
          r.ended = true;
          drop = true;
        }
      }
      impl.cv.notify_all();
      if (drop) {
        beast::error_code ignored;
        beast::get_lowest_layer(*ws).socket().shutdown(tcp::socket::shutdown_both, ignored);
        beast::get_lowest_layer(*ws).socket().close(ignored);
        return;
      }
      if (!final_ack.empty()) Send(std::move(final_ack));
      DoRead();
    }

    void Send(std::string bytes) {
      out.push_back(std::move(bytes));
      if (!writing) WriteNext();
    }

    void WriteNext() {
      if (out.empty()) {
        writing = false;
        return;
      }
      writing = true;
      ws->async_write(asio::buffer(out.front()), [self = shared_from_this()](beast::error_code ec, size_t) {
        self->out.pop_front();
        if (ec) {
          self->writing = false;
          return;
        }
        self->WriteNext();
      });
    }
  };

  std::vector<std::weak_ptr<Session>> sessions;  // to close at shutdown

  void Accept() {
    acceptor.async_accept([self = shared_from_this()](beast::error_code ec, tcp::socket socket) {
      if (ec) return;
      auto session = std::make_shared<Session>(*self, std::move(socket));
      self->sessions.push_back(session);
      session->Start();
      self->Accept();
    });
  }
};

TestEndpoint::TestEndpoint(EndpointOptions options) : impl_(std::make_shared<Impl>(std::move(options))) {
  const tcp::endpoint endpoint(asio::ip::make_address("127.0.0.1"), 0);
  impl_->acceptor.open(endpoint.protocol());
  impl_->acceptor.set_option(asio::socket_base::reuse_address(true));
  impl_->acceptor.bind(endpoint);
  impl_->acceptor.listen();
  port_ = impl_->acceptor.local_endpoint().port();
  impl_->Accept();
  thread_ = std::thread([impl = impl_] { impl->io.run(); });
}

TestEndpoint::~TestEndpoint() {
  // Close the acceptor and every socket on the io thread, so the aborted handlers run and release
  // the sessions and the endpoint they hold.
  asio::post(impl_->io, [impl = impl_] {
    beast::error_code ignored;
    impl->acceptor.close(ignored);
    for (const std::weak_ptr<Impl::Session>& weak : impl->sessions) {
      if (auto session = weak.lock()) {
        auto& socket = session->ws ? beast::get_lowest_layer(*session->ws).socket() : session->stream.socket();
        socket.close(ignored);
      }
    }
    impl->sessions.clear();
  });
  // With nothing left to do, the io thread's run() returns.
  thread_.join();
}

std::vector<ConnectionRecord> TestEndpoint::Connections() {
  std::lock_guard lock(impl_->mu);
  return impl_->connections;
}

}  // namespace idms::test
