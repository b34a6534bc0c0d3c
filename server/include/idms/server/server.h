// idms-server: HTTP and WebSocket on one port (plain or TLS), the model library, tokens and roles.
// Start binds and opens the data directory; Run serves until Stop, SIGTERM or SIGINT (then stops
// accepting, finishes requests in flight within the grace period, closes the database); SIGHUP
// reloads the tokens file.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "idms/server/options.h"

namespace idms::server {

class Server {
 public:
  explicit Server(ServerOptions options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Opens the data directory (importing the shipped models into an empty library), the tokens
  // (creating DATA/tokens when none is given and none exists), TLS, and binds. False with *error.
  bool Start(std::string* error);
  uint16_t port() const;
  const std::string& tokens_path() const;
  // Serves on options.threads threads until stopped; returns the process exit code (0).
  int Run();
  // Graceful stop, from any thread.
  void Stop();

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace idms::server
