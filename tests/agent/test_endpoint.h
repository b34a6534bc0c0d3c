// A small stand-in for idms-server in the agent's tests: one loopback port serving the model
// library's HTTP routes and /ws/agent (token check, Hello/Welcome with resume), recording every
// Envelope it receives, able to drop a connection mid-run. Runs its own io_context thread.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "idms/protocol/idms.pb.h"

namespace idms::test {

struct EndpointOptions {
  std::string token = "agent-secret";
  // Close the first WebSocket connection abruptly (no close frame) once it has delivered this
  // many device samples; -1 = never. The next Hello may resume.
  int64_t drop_after_samples = -1;
  // After that drop, refuse WebSocket upgrades with 503 for this long (a server restarting).
  std::chrono::milliseconds down_after_drop{0};
  // HTTP GET targets (path and query, exactly) -> 200 bodies; anything else is a 404.
  std::map<std::string, std::string> files;
};

// What one WebSocket connection carried.
struct ConnectionRecord {
  v1::Hello hello;
  v1::Welcome welcome;
  std::vector<v1::Envelope> frames;  // every frame after the Hello, in arrival order
  bool dropped_by_endpoint = false;
  bool close_frame = false;  // the agent closed with a WebSocket close frame
  bool ended = false;        // the connection is over
};

class TestEndpoint {
 public:
  explicit TestEndpoint(EndpointOptions options);
  ~TestEndpoint();
  TestEndpoint(const TestEndpoint&) = delete;
  TestEndpoint& operator=(const TestEndpoint&) = delete;

  uint16_t port() const { return port_; }
  std::string url() const { return "ws://127.0.0.1:" + std::to_string(port_); }

  // Waits until pred(connections) holds (checked under the lock at every change), or timeout.
  bool WaitFor(const std::function<bool(const std::vector<ConnectionRecord>&)>& pred,
               std::chrono::milliseconds timeout);

  // Copies under the lock.
  std::vector<ConnectionRecord> Connections();
  int64_t SamplesReceived();
  int UpgradesRefused();
  int HttpRequests(const std::string& target);

  // Sends a Command to the current connection (no-op without one).
  void SendCommand(const v1::Command& command);

  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
  uint16_t port_ = 0;
  std::thread thread_;
};

}  // namespace idms::test
