// The mesh codec: surface positions quantized on a per-session grid, sent as keyframes (the
// whole surface) and deltas (only the vertices whose quantized position changed), zstd-compressed.
// Pure functions below; MeshEncoder (the sender's policy) and MeshMirror (mesh_mirror.h) use them.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "idms/protocol/idms.pb.h"
#include "idms/sim/surface.h"  // SurfaceTriangles, GatherSurface: what the codec encodes

namespace idms {

struct Model;

// Default quantization step, model units. The grid is absolute (q = round(p / step), origin at
// the model origin) rather than relative to the rest pose or a per-frame box: a receiver then
// needs nothing but the keyframe to decode (no rest pose download, no per-frame origin to send),
// and the encoder and every mirror agree on the grid for the whole session. int32 per axis
// covers |p| < 2^31 * step (214748 model units at 1e-4); larger positions are rejected.
inline constexpr double kDefaultQuantStep = 1e-4;

// Limits a decoder enforces before it allocates; anything above is rejected with a message.
struct DecodeLimits {
  int64_t max_vertices = int64_t{1} << 22;              // vertices in a keyframe
  int64_t max_triangles = int64_t{1} << 23;             // triangles in a keyframe
  int64_t max_decompressed_bytes = int64_t{256} << 20;  // payload after zstd, whatever the counts say
};

// Reusable zstd contexts and scratch buffers (one ZSTD_CCtx, one ZSTD_DCtx). Owned by one
// thread; pass the same one to every call so that contexts and buffers are reused across frames.
class CodecContext {
 public:
  // level: zstd compression level for encoding (1 fastest .. 19 smallest).
  explicit CodecContext(int zstd_level = 3);
  ~CodecContext();
  CodecContext(const CodecContext&) = delete;
  CodecContext& operator=(const CodecContext&) = delete;

  struct Impl;
  Impl& impl() { return *impl_; }

  // Frees the scratch buffers whose capacity is above `keep_bytes`: a frame that inflated hugely
  // (or claimed to) leaves no memory behind; buffers of the usual size stay for reuse.
  void ReleaseScratchAbove(size_t keep_bytes);

 private:
  std::unique_ptr<Impl> impl_;
};

// Header fields of a frame, copied into the message by the encode functions.
struct FrameInfo {
  uint64_t sequence = 0;
  uint64_t base_sequence = 0;  // deltas only
  uint64_t topology_version = 0;
  double time_s = 0;
  double quant_step = kDefaultQuantStep;  // keyframes only
};

// Quantizes positions (num_vertices x 3, model units) onto the grid of `step`: q = round(p / step).
// Returns false and names the first offending vertex when a position is not finite or outside
// the int32 range. q must have pos.size() entries. Does not allocate unless it fails.
bool Quantize(std::span<const double> pos, double step, std::span<int32_t> q, std::string* error);

// q * step as float (num_vertices x 3). Does not allocate.
void Dequantize(std::span<const int32_t> q, double step, std::span<float> pos);

// Encodes a keyframe of quantized positions q (num_vertices x 3) and triangles (num_triangles x 3
// vertex ids < num_vertices). Returns false when a triangle id is out of range or step is not
// positive. The payload is zstd-compressed unless that would not make it smaller.
bool EncodeKeyframe(const FrameInfo& info, std::span<const int32_t> q, std::span<const int32_t> tri_verts,
                    CodecContext& ctx, v1::MeshKeyframe* out, std::string* error);

// Encodes the delta that takes a receiver from base_q to next_q (both num_vertices x 3): every
// vertex where they differ is listed. Fails only when the sizes differ.
bool EncodeDelta(const FrameInfo& info, std::span<const int32_t> base_q, std::span<const int32_t> next_q,
                 CodecContext& ctx, v1::MeshDelta* out, std::string* error);

// A decoded keyframe.
struct DecodedKeyframe {
  uint64_t sequence = 0;
  uint64_t topology_version = 0;
  double time_s = 0;
  double quant_step = 0;
  std::vector<int32_t> q;          // (num_vertices x 3) quantized positions
  std::vector<int32_t> tri_verts;  // (num_triangles x 3) vertex ids
};

// Decodes and validates a keyframe: counts within limits, a single zstd frame whose declared
// and actual sizes agree and fit, varints complete, values within int32, triangle ids in range,
// no bytes left over. On failure *out is unchanged and *error says what was wrong.
bool DecodeKeyframe(const v1::MeshKeyframe& msg, const DecodeLimits& limits, CodecContext& ctx, DecodedKeyframe* out,
                    std::string* error);

// Decodes a delta against the current quantized state q (num_vertices x 3) and applies it.
// Validates everything first (payload as for keyframes, num_changed <= num_vertices, ids
// strictly increasing and < num_vertices, results within int32); on failure q is untouched.
// Writes the changed vertex ids to *changed when it is not null. Sequence and topology checks
// are the caller's (MeshMirror).
bool ApplyDelta(const v1::MeshDelta& msg, const DecodeLimits& limits, CodecContext& ctx, std::span<int32_t> q,
                std::vector<int32_t>* changed, std::string* error);

// When MeshEncoder sends a keyframe rather than a delta, and how it quantizes.
struct EncoderOptions {
  double quant_step = kDefaultQuantStep;  // model units, > 0
  // A vertex is resent when its sent position is off by more than this many steps on some axis.
  // 0.5 = plain quantization (resent whenever its rounded value changes; error <= step / 2).
  // Larger values are a deadband: fewer vertices per delta, error <= this many steps per axis.
  // Measured (idms-codec-bench): 1.0 saves only 1-3 % of bytes for twice the error, hence 0.5.
  double resend_threshold_steps = 0.5;
  double keyframe_interval_s = 5.0;  // periodic keyframes; 0 = only at start, topology change, request
  int zstd_level = 3;
};

// What one Encode() produced.
struct EncodeStats {
  bool keyframe = false;
  int32_t num_changed = 0;  // vertices listed (all of them for a keyframe)
  int64_t payload_bytes = 0;
  int64_t raw_payload_bytes = 0;  // before compression
};

// The sender's side: tracks the quantized state every receiver holds after the last frame sent,
// so errors never accumulate (each delta moves receivers to round(p / step), not by a float
// difference). Owned by one thread; allocates only when the surface grows.
class MeshEncoder {
 public:
  explicit MeshEncoder(const EncoderOptions& options = {});

  // Sets the surface triangles (vertex ids) and their topology version. A new version makes the
  // next frame a keyframe.
  void SetTopology(uint64_t topology_version, std::span<const int32_t> tri_verts);

  // The next frame will be a keyframe (a viewer asked, or a connection was re-established).
  void RequestKeyframe();

  // Encodes the surface positions pos (num_vertices x 3, model units) at simulation time time_s
  // into *out as a MeshKeyframe or MeshDelta. A change of num_vertices needs a new topology
  // version first. Returns false on invalid positions; the encoder state is then unchanged and
  // *out must not be sent.
  bool Encode(double time_s, std::span<const double> pos, v1::Envelope* out, std::string* error,
              EncodeStats* stats = nullptr);

  // The sequence number of the last frame produced (0 before the first).
  uint64_t sequence() const { return sequence_; }
  // The quantized state receivers hold after the last frame (num_vertices x 3).
  std::span<const int32_t> sent() const { return sent_q_; }
  const EncoderOptions& options() const { return options_; }

 private:
  bool EncodeDeltaFrame(double time_s, std::span<const double> pos, v1::Envelope* out, EncodeStats* stats);

  EncoderOptions options_;
  CodecContext ctx_;
  uint64_t topology_version_ = 0;
  std::vector<int32_t> tri_verts_;
  bool keyframe_due_ = true;
  bool has_sent_ = false;
  double last_keyframe_time_s_ = 0;
  uint64_t sequence_ = 0;
  std::vector<int32_t> sent_q_;  // (num_vertices x 3) what receivers hold
  std::vector<int32_t> next_q_;  // (num_vertices x 3) scratch
};

}  // namespace idms
