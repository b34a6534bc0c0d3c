// The real idms-server on a free loopback port, and small synchronous clients (HTTP, HTTPS, raw
// bytes, WebSocket) for the integration tests.
#pragma once

#include <boost/asio/ssl/context.hpp>
#include <chrono>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "child_process.h"

namespace idms::test {

class ServerProcess {
 public:
  // Starts idms-server --listen 127.0.0.1:0 --data DIR plus `extra`; waits for its first line.
  ServerProcess(const std::string& data_dir, const std::vector<std::string>& extra = {});
  // Kills the server (SIGKILL) if it still runs. In a sanitized build (tests/sanitizers) it is
  // stopped with SIGTERM first, so that it runs its shutdown and LeakSanitizer checks it at exit.
  ~ServerProcess();
  bool ready() const { return port_ != 0; }
  uint16_t port() const { return port_; }
  std::string port_string() const { return std::to_string(port_); }
  // The token of ROLE from DATA/tokens (the file the server wrote at first start).
  std::string Token(const std::string& role) const;
  ChildProcess& process() { return *process_; }
  std::string Log() const { return process_->Log(); }

 private:
  std::string data_dir_;
  std::unique_ptr<ChildProcess> process_;
  uint16_t port_ = 0;
};

struct HttpReply {
  int status = 0;                              // 0: no response (the connection failed or closed)
  std::map<std::string, std::string> headers;  // names lower case
  std::string body;
  std::string error;
};

struct HttpCall {
  std::string method = "GET";
  std::string target;
  std::vector<std::pair<std::string, std::string>> headers;
  std::string body;
  std::string from;  // the client's own address (e.g. 127.0.0.2: all of 127/8 is loopback); empty: any
};

// One request on a new connection. With `tls`, HTTPS verified against that context.
HttpReply Http(uint16_t port, const HttpCall& call, boost::asio::ssl::context* tls = nullptr);
// GET with a bearer token (none when empty).
HttpReply Get(uint16_t port, const std::string& target, const std::string& token);

// Sends raw bytes, then reads until the server closes or `timeout` passes; returns what came back.
std::string RawExchange(uint16_t port, const std::string& bytes, std::chrono::milliseconds timeout);

// A WebSocket handshake; status 101 on success (then `first_message` is the first text received).
struct WsResult {
  int status = 0;
  std::string first_message;
  std::string error;
};
WsResult WsConnect(uint16_t port, const std::string& target,
                   const std::vector<std::pair<std::string, std::string>>& headers,
                   boost::asio::ssl::context* tls = nullptr);

// Polls `condition` every 20 ms until it holds or `timeout` passes: for effects that have no
// completion to await (a signal's, another process's).
template <class F>
bool Eventually(F condition, std::chrono::milliseconds timeout = std::chrono::milliseconds(20000)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return condition();
}

// The file's text as a JSON string value.
std::string JsonUpload(const std::string& fem, const std::string& plg, const std::string& description);

}  // namespace idms::test
