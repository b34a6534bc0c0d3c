// A fault-injecting stand-in for idms-server in the agent's tests, for the fault the real server
// does not produce: /ws/agent (token check, Hello/Welcome with resume), recording every Envelope
// it receives, dropping the first connection mid-run without a close frame while it stays up.
// Runs its own io_context thread.
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

  // Copies under the lock.
  std::vector<ConnectionRecord> Connections();

  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
  uint16_t port_ = 0;
  std::thread thread_;
};

}  // namespace idms::test
