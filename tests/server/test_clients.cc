// Test clients for real use (test_clients.h).
#include "test_clients.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <boost/beast/core/buffers_to_string.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/http/read.hpp>
#include <boost/beast/http/string_body.hpp>
#include <boost/beast/http/write.hpp>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "idms/protocol/envelope.h"

namespace idms::test {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;

FakeAgent::FakeAgent(uint16_t port, const std::string& token, const std::string& target) {
  beast::error_code ec;
  beast::get_lowest_layer(ws_).connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port), ec);
  if (ec) return;
  ws_.set_option(websocket::stream_base::decorator(
      [token](websocket::request_type& req) { req.set(beast::http::field::authorization, "Bearer " + token); }));
  ws_.handshake("127.0.0.1:" + std::to_string(port), target, ec);
  connected_ = !ec;
  ws_.binary(true);
}

std::optional<v1::Envelope> FakeAgent::Hello(const std::string& session_id, const std::string& resume_token,
                                             const std::string& identity, const std::string& model) {
  v1::Envelope e;
  v1::Hello* h = e.mutable_hello();
  h->set_protocol_version(kProtocolVersion);
  h->set_role(v1::ROLE_AGENT);
  h->set_identity(identity);
  h->set_device("fake");
  h->set_session_id(session_id);
  h->set_resume_token(resume_token);
  h->mutable_scene()->set_model(model.empty() ? "hex_4x5_home" : model);
  if (!Send(e)) return std::nullopt;
  return ReadUntil([](const v1::Envelope& r) { return r.has_welcome() || r.has_session_event(); });
}

bool FakeAgent::Send(const v1::Envelope& e) {
  std::string bytes;
  SerializeEnvelope(e, &bytes);
  beast::error_code ec;
  ws_.binary(true);
  ws_.write(asio::buffer(bytes), ec);
  return !ec;
}

bool FakeAgent::SendText(const std::string& text) {
  beast::error_code ec;
  ws_.text(true);
  ws_.write(asio::buffer(text), ec);
  ws_.binary(true);
  return !ec;
}

bool FakeAgent::SendSamples(uint64_t first_tick, int n, double dt_s) {
  v1::Envelope e;
  for (int i = 0; i < n; ++i) {
    v1::DeviceSample* s = e.mutable_device_samples()->add_samples();
    s->set_tick(first_tick + static_cast<uint64_t>(i));
    s->set_time_s(static_cast<double>(first_tick + static_cast<uint64_t>(i) + 1) * dt_s);
  }
  return Send(e);
}

std::optional<v1::Envelope> FakeAgent::End(uint64_t last_tick, double time_s) {
  v1::Envelope ended;
  ended.mutable_session_event()->set_kind(v1::SessionEvent::KIND_ENDED);
  ended.mutable_session_event()->set_tick(last_tick);
  if (time_s > 0) ended.mutable_session_event()->set_time_s(time_s);
  if (!Send(ended)) return std::nullopt;
  return ReadUntil([](const v1::Envelope& e) { return e.has_ack() && e.ack().final(); });
}

std::optional<v1::Envelope> FakeAgent::Read(std::chrono::milliseconds timeout) {
  if (!unread_.empty()) {
    v1::Envelope e = std::move(unread_.front());
    unread_.pop_front();
    return e;
  }
  if (closed_) return std::nullopt;
  // A synchronous read would ignore the stream's expiry and wait forever for a frame that never
  // comes; an asynchronous one runs for `timeout` at most and stays pending after it.
  if (!reading_) {
    reading_ = true;
    read_done_ = false;
    read_buffer_.clear();
    ws_.async_read(read_buffer_, [this](beast::error_code ec, size_t) {
      read_ec_ = ec;
      read_done_ = true;
      reading_ = false;
    });
  }
  io_.restart();
  io_.run_for(timeout);
  if (!read_done_) return std::nullopt;
  read_done_ = false;
  if (read_ec_) {
    closed_ = true;
    return std::nullopt;
  }
  std::vector<v1::Envelope> frames;
  std::string error;
  if (!ParseFrames(beast::buffers_to_string(read_buffer_.data()), &frames, &error) || frames.empty())
    return std::nullopt;
  unread_.insert(unread_.end(), std::make_move_iterator(frames.begin() + 1), std::make_move_iterator(frames.end()));
  return std::move(frames.front());
}

void FakeAgent::Close() {
  beast::error_code ec;
  if (reading_) {
    // The pending read takes the server's close frame.
    ws_.async_close(websocket::close_code::normal, [](beast::error_code) {});
    io_.restart();
    io_.run_for(std::chrono::seconds(5));
  } else {
    ws_.close(websocket::close_code::normal, ec);
  }
  closed_ = true;
}

void FakeAgent::Drop() {
  beast::error_code ec;
  beast::get_lowest_layer(ws_).socket().close(ec);
  closed_ = true;
}

// ---------------------------------------------------------------------------------------------
struct SilenceProxy::Link {
  int client = -1, server = -1;
  std::atomic<bool> silent{false};
  std::thread thread;
  ~Link() {
    if (thread.joinable()) thread.join();
    if (client >= 0) ::close(client);
    if (server >= 0) ::close(server);
  }
};

SilenceProxy::SilenceProxy(uint16_t target_port) : target_port_(target_port) {
  listen_fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  ::bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), sizeof a);
  ::listen(listen_fd_, 64);
  socklen_t len = sizeof a;
  ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len);
  port_ = ntohs(a.sin_port);
  accept_thread_ = std::thread([this] { Accept(); });
}

SilenceProxy::~SilenceProxy() {
  stopping_ = true;
  ::shutdown(listen_fd_, SHUT_RDWR);
  accept_thread_.join();
  ::close(listen_fd_);
  std::lock_guard lock(mu_);
  links_.clear();  // each link's thread sees stopping_ within its poll period
}

void SilenceProxy::Silence() {
  std::lock_guard lock(mu_);
  for (auto& l : links_) l->silent = true;
}

void SilenceProxy::Accept() {
  while (!stopping_) {
    const int c = ::accept(listen_fd_, nullptr, nullptr);
    if (c < 0) return;
    auto link = std::make_shared<Link>();
    link->client = c;
    link->server = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(target_port_);
    if (::connect(link->server, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) continue;
    ++connections_;
    Link* l = link.get();
    link->thread = std::thread([this, l] {
      // Pump both ways until either side closes; once silent, hold both sockets open and idle.
      char buf[64 << 10];
      pollfd fds[2] = {{l->client, POLLIN, 0}, {l->server, POLLIN, 0}};
      while (!stopping_) {
        if (l->silent) {
          std::this_thread::sleep_for(std::chrono::milliseconds(20));
          continue;
        }
        if (::poll(fds, 2, 20) <= 0) continue;
        for (int i = 0; i < 2; ++i) {
          if (!(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
          const ssize_t n = ::read(fds[i].fd, buf, sizeof buf);
          if (n <= 0) {
            ::shutdown(fds[1 - i].fd, SHUT_WR);
            return;
          }
          if (l->silent) continue;  // silenced mid-read: the bytes are lost, as on a dead link
          for (ssize_t off = 0; off < n;) {
            const ssize_t w = ::write(fds[1 - i].fd, buf + off, static_cast<size_t>(n - off));
            if (w <= 0) return;
            off += w;
          }
        }
      }
    });
    std::lock_guard lock(mu_);
    links_.push_back(std::move(link));
  }
}

// ---------------------------------------------------------------------------------------------
int KeepAliveRequest(beast::tcp_stream& stream, beast::http::verb verb, const std::string& target,
                     const std::string& token, const std::string& body, std::string* reply,
                     std::chrono::seconds timeout) {
  namespace http = beast::http;
  http::request<http::string_body> req{verb, target, 11};
  req.set(http::field::host, "127.0.0.1");
  req.keep_alive(true);
  if (!token.empty()) req.set(http::field::authorization, "Bearer " + token);
  if (!body.empty()) {
    req.set(http::field::content_type, "application/json");
    req.body() = body;
  }
  req.prepare_payload();
  beast::error_code ec;
  stream.expires_after(timeout);
  http::write(stream, req, ec);
  beast::flat_buffer buffer;
  http::response<http::string_body> res;
  if (!ec) http::read(stream, buffer, res, ec);
  if (ec) return 0;
  if (reply != nullptr) *reply = res.body();
  return res.result_int();
}

int OpenFds(int pid) {
  int n = 0;
  std::error_code ec;
  for (auto it = std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/fd", ec);
       !ec && it != std::filesystem::directory_iterator(); it.increment(ec)) {
    ++n;
  }
  return n;
}

namespace {
int64_t StatusField(int pid, const std::string& field) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(field + ":", 0) == 0) return std::stoll(line.substr(field.size() + 1));
  }
  return -1;
}
}  // namespace

int64_t RssKiB(int pid) { return StatusField(pid, "VmRSS"); }
int Threads(int pid) { return static_cast<int>(StatusField(pid, "Threads")); }

}  // namespace idms::test
