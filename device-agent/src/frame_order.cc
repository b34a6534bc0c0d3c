// The uplink's frame order (frame_order.h).
#include "frame_order.h"

#include <algorithm>

namespace idms::agent {

FrameOrder::FrameOrder(int64_t batch) : batch_(batch > 0 ? static_cast<size_t>(batch) : 20) {}

NextFrame FrameOrder::Next(const Waiting& waiting) const {
  // Events, then the surface: both are small next to what they describe.
  if (waiting.events > 0) return {FrameKind::kEvent, 0};
  // The live case: the samples of the last mesh period (fewer than a batch) go just before the
  // surface they belong with. Catching up after a resume (more than a batch waiting), the surface
  // goes first: viewers need its keyframe more than old samples.
  if (waiting.surface && waiting.samples_to_surface > 0 && waiting.samples_to_surface <= batch_)
    return {FrameKind::kSamples, waiting.samples_to_surface};
  if (waiting.surface) return {FrameKind::kSurface, 0};
  // Samples in full batches; a partial one only when no more will come.
  if (waiting.samples >= batch_ || (waiting.samples > 0 && waiting.loop_finished)) {
    return {FrameKind::kSamples, std::min(waiting.samples, batch_)};
  }
  if (waiting.loop_finished) return {FrameKind::kEnded, 0};
  return {FrameKind::kNone, 0};
}

}  // namespace idms::agent
