// The real servers the several-servers tests start on loopback: nats-server, HAProxy, and
// tokens shared by several idms-servers; and what those tests read from a viewer.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "child_process.h"
#include "server_process.h"
#include "session_checks.h"

namespace idms::test {

// nats-server on 127.0.0.1: a free port (or `port`), its log in DIR/nats-N.log.
class NatsServer {
 public:
  // `extra`: more arguments (a cluster's --cluster and --routes, -c FILE).
  explicit NatsServer(const std::string& dir, int port = -1, const std::vector<std::string>& extra = {});
  int port() const { return port_; }
  std::string url() const { return "nats://127.0.0.1:" + std::to_string(port_); }
  void Kill();
  std::string Log() const;

 private:
  std::string log_;
  std::unique_ptr<ChildProcess> process_;
  int port_ = 0;
};

bool HaveNats();
bool HaveHaproxy();
// A port no one listens on now (bound and released: haproxy cannot say which port it took).
uint16_t FreePort();
// A new token of `role` appended to `file` (idms-server token create), as several servers share.
std::string CreateToken(const std::string& file, const std::string& role);

// HAProxy in front of the servers: agents to `agents`, viewers hashed by their URL (the session
// id) over `viewers`, consistently and with bounded load, health-checked on /api/health.
class Haproxy {
 public:
  Haproxy(const std::string& dir, const std::vector<uint16_t>& agents, const std::vector<uint16_t>& viewers);
  uint16_t port() const { return port_; }

 private:
  uint16_t port_;
  std::unique_ptr<ChildProcess> process_;
};

// Every device tick a viewer got, in order.
std::vector<uint64_t> Ticks(TestViewer& v);

}  // namespace idms::test
