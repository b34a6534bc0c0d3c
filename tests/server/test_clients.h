// Clients that play the hostile or unlucky side of real use against the real idms-server: an
// agent speaking the protocol frame by frame (to resume while an old connection lingers, to send
// what a broken or hostile agent sends), a TCP proxy that can silence its connections without
// closing them (what a Wi-Fi drop leaves), and the server's own figures read from /proc.
#pragma once

#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/http/verb.hpp>
#include <boost/beast/websocket/stream.hpp>
#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "idms/protocol/idms.pb.h"

namespace idms::test {

// A synchronous agent on /ws/agent (or any other WebSocket target): Hello, frames, reads with a
// deadline.
class FakeAgent {
 public:
  FakeAgent(uint16_t port, const std::string& token, const std::string& target = "/ws/agent");
  bool connected() const { return connected_; }
  // Hello for a new session (empty id) or a resume; returns the server's answer (Welcome, or a
  // SessionEvent refusal), nullopt when nothing came within the timeout.
  std::optional<v1::Envelope> Hello(const std::string& session_id = "", const std::string& resume_token = "",
                                    const std::string& identity = "fake-agent", const std::string& model = "");
  bool Send(const v1::Envelope& e);
  bool SendText(const std::string& text);
  bool SendSamples(uint64_t first_tick, int n, double dt_s = 0.001);  // ticks first..first+n-1
  // Ends the session (ENDED after `last_tick`, at `time_s` when > 0) and waits for the server's
  // final Ack (the recording finished); nullopt when none came.
  std::optional<v1::Envelope> End(uint64_t last_tick, double time_s = 0);
  // The next frame from the server (nullopt: timeout or closed).
  std::optional<v1::Envelope> Read(std::chrono::milliseconds timeout = std::chrono::seconds(10));
  // Reads until a frame matching `pred` (or timeout / close).
  template <class P>
  std::optional<v1::Envelope> ReadUntil(P pred, std::chrono::milliseconds timeout = std::chrono::seconds(10)) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      auto e = Read(std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()));
      if (!e) return std::nullopt;
      if (pred(*e)) return e;
    }
    return std::nullopt;
  }
  bool closed() const { return closed_; }
  void Close();  // a clean close
  void Drop();   // the socket closed without a close frame

 private:
  boost::asio::io_context io_;
  boost::beast::websocket::stream<boost::beast::tcp_stream> ws_{io_};
  bool connected_ = false, closed_ = false;
  std::deque<v1::Envelope> unread_;  // the rest of a Frames message (a live session's viewers get them)
  // A read runs asynchronously and io_ is run until it completes or the caller's timeout passes; a
  // read that timed out stays pending for the next Read (the stream itself never times out).
  bool reading_ = false, read_done_ = false;
  boost::beast::error_code read_ec_;
  boost::beast::flat_buffer read_buffer_;
};

// A TCP proxy on a free loopback port to `target_port`, pumping bytes both ways on its own
// threads. Silence() freezes every connection open now: nothing more passes either way and
// nothing is closed; connections opened later pass normally.
class SilenceProxy {
 public:
  explicit SilenceProxy(uint16_t target_port);
  ~SilenceProxy();
  uint16_t port() const { return port_; }
  void Silence();
  int connections() const { return connections_.load(); }

 private:
  struct Link;
  void Accept();

  uint16_t target_port_, port_ = 0;
  int listen_fd_ = -1;
  std::atomic<bool> stopping_{false};
  std::atomic<int> connections_{0};
  std::mutex mu_;
  std::vector<std::shared_ptr<Link>> links_;
  std::thread accept_thread_;
};

// One HTTP/1.1 request on an open keep-alive connection (a JSON body when `body` is not empty,
// "Authorization: Bearer" when `token` is not); the response's status, 0 when none came.
int KeepAliveRequest(boost::beast::tcp_stream& stream, boost::beast::http::verb verb, const std::string& target,
                     const std::string& token = "", const std::string& body = "", std::string* reply = nullptr,
                     std::chrono::seconds timeout = std::chrono::seconds(60));

// The server process's open descriptors, resident memory (KiB) and threads, from /proc.
int OpenFds(int pid);
int64_t RssKiB(int pid);
int Threads(int pid);

}  // namespace idms::test
