// Which frame the uplink sends next on a connection: session events first (they are rare and
// say what the rest means), then the newest surface, preceded by the samples up to its tick (a
// short batch: the server forwards samples to viewers with the next surface, so samples sent
// just before it reach the viewers at once instead of waiting up to a mesh period there), then
// samples in full batches; once the loop has ended, the last samples in a short batch, then
// ENDED. Pure: decides, sends nothing.
#pragma once

#include <cstddef>
#include <cstdint>

namespace idms::agent {

// What is waiting to be sent.
struct Waiting {
  size_t events = 0;     // session events queued
  bool surface = false;  // a surface to encode (newer than the last sent, or a resend)
  size_t samples = 0;    // unsent samples in the backlog
  // Of those, how many are at or before the waiting surface's tick (oldest first). Counted anew
  // for every frame, so samples that arrive while these are written never hold the surface back.
  size_t samples_to_surface = 0;
  bool loop_finished = false;  // no more samples or surfaces will come
};

enum class FrameKind : uint8_t {
  kNone,     // nothing to send yet (a partial batch waits for more samples)
  kEvent,    // the oldest session event
  kSurface,  // a mesh keyframe or delta
  kSamples,  // a DeviceSamples batch of num_samples
  kEnded,    // SessionEvent ENDED, then the close handshake: everything has been sent
};

struct NextFrame {
  FrameKind kind = FrameKind::kNone;
  size_t num_samples = 0;  // kSamples: how many, oldest first
};

class FrameOrder {
 public:
  // batch: samples per DeviceSamples frame; 0 = the default 20 (the scene's sample_batch unset).
  explicit FrameOrder(int64_t batch);

  NextFrame Next(const Waiting& waiting) const;
  size_t batch() const { return batch_; }

 private:
  size_t batch_;
};

}  // namespace idms::agent
