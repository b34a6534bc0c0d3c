// The agent's I/O thread: drains the loop's rings, encodes (DeviceSamples batches, mesh keyframes
// and deltas), sends them over one WebSocket to the server, receives Commands, reconnects with
// backoff and resumes the session, keeping a bounded backlog of samples so a server restart
// loses nothing that fits in it. Beast/Asio stay inside uplink.cc.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "idms/agent/loop.h"
#include "idms/protocol/idms.pb.h"

namespace idms::agent {

struct UplinkOptions {
  bool offline = false;    // --server none: drain the rings and discard (benches)
  std::string host, port;  // the server, from ws://HOST:PORT
  std::string target = "/ws/agent";
  std::string token;                 // sent as "Authorization: Bearer TOKEN" on the upgrade request
  std::string identity;              // Hello.identity
  std::string trainee;               // Hello.trainee: who is at the device
  std::string device;                // Hello.device
  v1::Scene scene;                   // Hello.scene, and quant_step / keyframe_interval_s / sample_batch
  int64_t backlog_samples = 120000;  // samples kept for resending (2 min at 1 kHz); oldest dropped first
  double backoff_initial_s = 0.1;    // first retry delay; doubles (with +-20 % jitter) up to the max
  double backoff_max_s = 5.0;
  double connect_timeout_s = 5.0;  // TCP connect, WebSocket upgrade, Hello -> Welcome
  double flush_timeout_s = 5.0;    // after the loop ends: time allowed to deliver the rest and close
  // A server link silent this long (no frame, no pong) is dropped and the session resumed on a
  // new connection; the server is pinged at half of it.
  double idle_timeout_s = 2.0;
  double poll_interval_s = 0.002;  // how often the rings are drained
};

struct UplinkStats {
  uint64_t samples_received = 0;  // taken from the loop's ring
  uint64_t samples_sent = 0;      // distinct ticks sent at least once
  uint64_t samples_resent = 0;    // sent again after a resume
  uint64_t samples_dropped = 0;   // lost to backlog overflow (or evicted before the server had them)
  uint64_t samples_unsent = 0;    // still waiting when the agent gave up at exit
  uint64_t mesh_frames = 0;
  uint64_t keyframes = 0;
  uint64_t mesh_bytes = 0;  // mesh payload bytes sent
  uint64_t reconnects = 0;  // sessions resumed after a lost connection
  uint64_t connect_failures = 0;
  uint64_t commands = 0;  // Commands received
  // SessionEvent ENDED sent and acknowledged by the server's final Ack: the recording is finished
  // and holds every tick the agent did not count as dropped.
  bool ended_cleanly = false;
  uint64_t acked_next_tick = 0;  // the server has stored every tick before this one
  std::string session_id;
  std::string fatal_error;  // why the server refused us (bad token, protocol mismatch), or ""
};

class Uplink {
 public:
  // loop must outlive the uplink. Allocates the encoder and the backlog's first block.
  Uplink(Loop& loop, const UplinkOptions& options);
  ~Uplink();
  Uplink(const Uplink&) = delete;
  Uplink& operator=(const Uplink&) = delete;

  // The I/O thread body (call on the thread that is to own the io_context). SIGINT and SIGTERM
  // stop the loop; once the loop has finished and everything is delivered (or flush_timeout_s
  // passed), sends SessionEvent ENDED, closes the WebSocket and returns. On a fatal refusal it
  // stops the loop, waits for it and returns false.
  bool Run();

  // Valid after Run returned.
  const UplinkStats& stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace idms::agent
