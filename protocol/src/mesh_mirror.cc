// MeshMirror: applies keyframes and deltas in sequence, refusing gaps and malformed frames
// without touching what it shows.
#include "idms/protocol/mesh_mirror.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "idms/sim/state.h"

namespace idms {

bool ValidSutureShape(const v1::SutureShape& shape, std::string* error) {
  const auto fail = [error](const std::string& what) {
    if (error != nullptr) *error = "suture: " + what;
    return false;
  };
  const int nodes = shape.nodes_size(), punctures = shape.punctures_size();
  if (nodes % 3 != 0 || nodes > 3 * (kSutureSegments + 1) || nodes == 3) {
    return fail("nodes must hold x, y, z of 2 to " + std::to_string(kSutureSegments + 1) + " nodes, got " +
                std::to_string(nodes) + " values");
  }
  if (punctures % 3 != 0 || punctures > 3 * kSuturePunctures) {
    return fail("punctures must hold x, y, z of at most " + std::to_string(kSuturePunctures) + " points, got " +
                std::to_string(punctures) + " values");
  }
  for (const float v : shape.nodes()) {
    if (!std::isfinite(v)) return fail("a node is not finite");
  }
  for (const float v : shape.punctures()) {
    if (!std::isfinite(v)) return fail("a puncture is not finite");
  }
  if (shape.broken_segment() < 0 || shape.broken_segment() > nodes / 3) {
    return fail("broken_segment " + std::to_string(shape.broken_segment()) + " is not a segment + 1 (or 0)");
  }
  return true;
}

const char* MirrorStatusName(MirrorStatus status) {
  switch (status) {
    case MirrorStatus::kOk:
      return "ok";
    case MirrorStatus::kGap:
      return "gap";
    case MirrorStatus::kInvalid:
      return "invalid";
  }
  return "unknown";
}

MeshMirror::MeshMirror(const DecodeLimits& limits) : limits_(limits) {}

MirrorStatus MeshMirror::Apply(const v1::MeshKeyframe& keyframe, std::string* error) {
  // Decode into scratch; only a fully valid keyframe replaces the state. A refused frame leaves
  // no buffer behind, whatever it inflated to.
  if (!ValidSutureShape(keyframe.suture(), error)) return MirrorStatus::kInvalid;
  if (!DecodeKeyframe(keyframe, limits_, ctx_, &scratch_, error)) {
    ctx_.ReleaseScratchAbove(KeepBytes());
    return MirrorStatus::kInvalid;
  }
  has_keyframe_ = true;
  sequence_ = scratch_.sequence;
  topology_version_ = scratch_.topology_version;
  time_s_ = scratch_.time_s;
  quant_step_ = scratch_.quant_step;
  q_.swap(scratch_.q);
  tri_verts_.swap(scratch_.tri_verts);
  pos_.resize(q_.size());
  Dequantize(q_, quant_step_, pos_);
  changed_.clear();
  suture_ = keyframe.suture();
  ctx_.ReleaseScratchAbove(KeepBytes());
  return MirrorStatus::kOk;
}

size_t MeshMirror::KeepBytes() const {
  // What a frame of the current surface can need: 10-byte varints for every value.
  return std::max<size_t>(size_t{1} << 20, 10 * (q_.size() + tri_verts_.size()));
}

MirrorStatus MeshMirror::Apply(const v1::MeshDelta& delta, std::string* error) {
  // Sequencing: a delta applies only to the frame it was made against.
  const std::string where = "delta " + std::to_string(delta.sequence()) + ": ";
  if (!has_keyframe_) {
    if (error != nullptr) *error = where + "no keyframe received yet";
    return MirrorStatus::kGap;
  }
  if (delta.base_sequence() != sequence_) {
    if (error != nullptr) {
      *error = where + "base " + std::to_string(delta.base_sequence()) +
               (delta.base_sequence() > sequence_ ? " is ahead of" : " is behind") + " the mirror's frame " +
               std::to_string(sequence_) +
               (delta.base_sequence() > sequence_ ? " (frames lost)" : " (stale or repeated)");
    }
    return MirrorStatus::kGap;
  }
  if (delta.sequence() <= delta.base_sequence()) {
    if (error != nullptr) {
      *error = where + "sequence is not after its base " + std::to_string(delta.base_sequence());
    }
    return MirrorStatus::kInvalid;
  }
  if (delta.topology_version() != topology_version_) {
    if (error != nullptr) {
      *error = where + "topology version " + std::to_string(delta.topology_version()) +
               " differs from the base frame's " + std::to_string(topology_version_);
    }
    return MirrorStatus::kInvalid;
  }
  // Decode and apply (all or nothing), then refresh the moved vertices' float positions.
  if (!ValidSutureShape(delta.suture(), error)) return MirrorStatus::kInvalid;
  if (!ApplyDelta(delta, limits_, ctx_, q_, &changed_, error)) {
    ctx_.ReleaseScratchAbove(KeepBytes());
    return MirrorStatus::kInvalid;
  }
  for (const int32_t v : changed_) {
    const size_t k = 3 * static_cast<size_t>(v);
    for (size_t a = 0; a < 3; ++a) pos_[k + a] = static_cast<float>(q_[k + a] * quant_step_);
  }
  sequence_ = delta.sequence();
  time_s_ = delta.time_s();
  suture_ = delta.suture();
  return MirrorStatus::kOk;
}

MirrorStatus MeshMirror::Apply(const v1::Envelope& envelope, std::string* error) {
  switch (envelope.body_case()) {
    case v1::Envelope::kMeshKeyframe:
      return Apply(envelope.mesh_keyframe(), error);
    case v1::Envelope::kMeshDelta:
      return Apply(envelope.mesh_delta(), error);
    default:
      if (error != nullptr) *error = "not a mesh frame";
      return MirrorStatus::kInvalid;
  }
}

bool MeshMirror::MakeKeyframe(v1::MeshKeyframe* out, std::string* error) {
  if (!has_keyframe_) {
    if (error != nullptr) *error = "the mirror has no keyframe yet";
    return false;
  }
  const FrameInfo info{.sequence = sequence_,
                       .base_sequence = 0,
                       .topology_version = topology_version_,
                       .time_s = time_s_,
                       .quant_step = quant_step_};
  if (!EncodeKeyframe(info, q_, tri_verts_, ctx_, out, error)) return false;
  if (suture_.nodes_size() > 0) {
    *out->mutable_suture() = suture_;
  } else {
    out->clear_suture();  // a reused message keeps nothing of an earlier thread
  }
  return true;
}

}  // namespace idms
