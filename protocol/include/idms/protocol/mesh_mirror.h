// MeshMirror: a receiver's copy of the surface, built from keyframes and deltas. The server keeps
// one per session for late joiners, the renderer draws from one, the tests compare one to truth.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "idms/protocol/idms.pb.h"
#include "idms/protocol/mesh_codec.h"

namespace idms {

enum class MirrorStatus {
  kOk,       // applied
  kGap,      // cannot apply yet: no keyframe, or the delta's base is not the current frame
             // (frames were lost or arrive late); ask for a keyframe. The mirror is unchanged.
  kInvalid,  // malformed or oversize; the mirror is unchanged
};

const char* MirrorStatusName(MirrorStatus status);

// Owned by one thread. Apply() never leaves the mirror half-updated: on kGap or kInvalid it still
// shows the last frame applied.
class MeshMirror {
 public:
  explicit MeshMirror(const DecodeLimits& limits = {});

  MirrorStatus Apply(const v1::MeshKeyframe& keyframe, std::string* error);
  MirrorStatus Apply(const v1::MeshDelta& delta, std::string* error);
  // A mesh frame in an envelope; any other body is kInvalid.
  MirrorStatus Apply(const v1::Envelope& envelope, std::string* error);

  // A keyframe of the current state (for a late joiner or a viewer being resynchronised); the
  // sender's next delta applies on top of it. False before the first keyframe.
  bool MakeKeyframe(v1::MeshKeyframe* out, std::string* error);

  bool has_keyframe() const { return has_keyframe_; }
  uint64_t sequence() const { return sequence_; }  // of the last frame applied, 0 = none
  uint64_t topology_version() const { return topology_version_; }
  double time_s() const { return time_s_; }
  double quant_step() const { return quant_step_; }
  int32_t num_vertices() const { return static_cast<int32_t>(q_.size() / 3); }
  int32_t num_triangles() const { return static_cast<int32_t>(tri_verts_.size() / 3); }
  std::span<const float> positions() const { return pos_; }          // (num_vertices x 3), model units
  std::span<const int32_t> quantized() const { return q_; }          // (num_vertices x 3), quanta
  std::span<const int32_t> triangles() const { return tri_verts_; }  // (num_triangles x 3), vertex ids
  // Vertices the last delta moved (all of them after a keyframe: empty, see positions()).
  std::span<const int32_t> changed() const { return changed_; }
  // The suture thread the last frame showed (empty nodes: none). A keyframe made here carries it.
  const v1::SutureShape& suture() const { return suture_; }

 private:
  size_t KeepBytes() const;  // scratch kept between frames

  DecodeLimits limits_;
  CodecContext ctx_;
  bool has_keyframe_ = false;
  uint64_t sequence_ = 0;
  uint64_t topology_version_ = 0;
  double time_s_ = 0;
  double quant_step_ = kDefaultQuantStep;
  std::vector<int32_t> q_;
  std::vector<float> pos_;
  std::vector<int32_t> tri_verts_;
  std::vector<int32_t> changed_;
  v1::SutureShape suture_;
  DecodedKeyframe scratch_;
};

// A frame's suture shape within its bounds (whole xyz triples, at most 129 nodes and 16
// punctures, finite, the broken segment one of its own); false with *error saying what.
bool ValidSutureShape(const v1::SutureShape& shape, std::string* error);

}  // namespace idms
