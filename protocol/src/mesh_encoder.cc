// MeshEncoder: the sender's keyframe policy and deadband on top of the pure codec functions.
#include <cmath>
#include <limits>

#include "codec_context_internal.h"
#include "idms/protocol/mesh_codec.h"

namespace idms {

MeshEncoder::MeshEncoder(const EncoderOptions& options) : options_(options), ctx_(options.zstd_level) {}

void MeshEncoder::SetTopology(uint64_t topology_version, std::span<const int32_t> tri_verts) {
  if (!has_sent_ || topology_version != topology_version_) keyframe_due_ = true;
  topology_version_ = topology_version;
  tri_verts_.assign(tri_verts.begin(), tri_verts.end());
}

void MeshEncoder::RequestKeyframe() { keyframe_due_ = true; }

bool MeshEncoder::Encode(double time_s, std::span<const double> pos, v1::Envelope* out, std::string* error,
                         EncodeStats* stats) {
  if (pos.size() % 3 != 0) {
    if (error != nullptr) *error = "positions must be a multiple of 3 values";
    return false;
  }
  // A keyframe at start, on topology change or request, every keyframe_interval_s, and when
  // time runs backwards (a reset or a replay restarting).
  const bool periodic =
      options_.keyframe_interval_s > 0 && time_s - last_keyframe_time_s_ >= options_.keyframe_interval_s;
  const bool keyframe = keyframe_due_ || !has_sent_ || periodic || time_s < last_keyframe_time_s_;
  if (!keyframe && pos.size() != sent_q_.size()) {
    if (error != nullptr) {
      *error = "the surface changed from " + std::to_string(sent_q_.size() / 3) + " to " +
               std::to_string(pos.size() / 3) + " vertices without a new topology version";
    }
    return false;
  }
  EncodeStats local;
  EncodeStats& s = stats != nullptr ? *stats : local;
  s = EncodeStats{};
  if (!keyframe) {
    if (!EncodeDeltaFrame(time_s, pos, out, &s)) {
      // Quantize finds and describes the bad position.
      next_q_.resize(pos.size());
      if (Quantize(pos, options_.quant_step, next_q_, error) && error != nullptr) {
        *error = "a position is not finite or outside the int32 grid";
      }
      return false;
    }
  } else {
    // Quantize everything and send the whole surface.
    next_q_.resize(pos.size());
    if (!Quantize(pos, options_.quant_step, next_q_, error)) return false;
    const FrameInfo info{.sequence = sequence_ + 1,
                         .base_sequence = 0,
                         .topology_version = topology_version_,
                         .time_s = time_s,
                         .quant_step = options_.quant_step};
    if (!EncodeKeyframe(info, next_q_, tri_verts_, ctx_, out->mutable_mesh_keyframe(), error)) {
      return false;
    }
    keyframe_due_ = false;
    last_keyframe_time_s_ = time_s;
    s.keyframe = true;
    s.num_changed = static_cast<int32_t>(pos.size() / 3);
    s.payload_bytes = static_cast<int64_t>(out->mesh_keyframe().payload().size());
  }
  // Receivers now hold next_q_.
  s.raw_payload_bytes = s.num_changed > 0 ? static_cast<int64_t>(ctx_.impl().raw.size()) : 0;
  sent_q_.swap(next_q_);
  ++sequence_;
  has_sent_ = true;
  return true;
}

bool MeshEncoder::EncodeDeltaFrame(double time_s, std::span<const double> pos, v1::Envelope* out, EncodeStats* stats) {
  // Choose what receivers will hold: round(p / step) for vertices whose sent position is off by
  // more than the threshold on some axis (every vertex whose rounding changed, at 0.5), the sent
  // value otherwise. Measured against the sent state, so errors never accumulate.
  const double inv = 1.0 / options_.quant_step;
  const double threshold = options_.resend_threshold_steps;
  const double limit = static_cast<double>(std::numeric_limits<int32_t>::max());
  next_q_.resize(pos.size());
  const size_t nv = pos.size() / 3;
  for (size_t i = 0; i < nv; ++i) {
    const size_t k = 3 * i;
    double v[3];
    bool resend = false;
    for (size_t a = 0; a < 3; ++a) {
      v[a] = pos[k + a] * inv;
      if (!(std::fabs(v[a]) < limit)) return false;
      resend = resend || std::fabs(v[a] - sent_q_[k + a]) > threshold;
    }
    for (size_t a = 0; a < 3; ++a) {
      next_q_[k + a] = resend ? static_cast<int32_t>(v[a] + (v[a] >= 0 ? 0.5 : -0.5)) : sent_q_[k + a];
    }
  }
  const FrameInfo info{.sequence = sequence_ + 1,
                       .base_sequence = sequence_,
                       .topology_version = topology_version_,
                       .time_s = time_s,
                       .quant_step = options_.quant_step};
  v1::MeshDelta* delta = out->mutable_mesh_delta();
  std::string unused;
  if (!EncodeDelta(info, sent_q_, next_q_, ctx_, delta, &unused)) return false;
  stats->num_changed = static_cast<int32_t>(delta->num_changed());
  stats->payload_bytes = static_cast<int64_t>(delta->payload().size());
  return true;
}

}  // namespace idms
