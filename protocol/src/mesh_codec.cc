// The mesh codec's pure functions: quantization, keyframe and delta payloads (zigzag varints,
// planar axes), zstd with size limits, and the validation every decoded byte goes through.
#include "idms/protocol/mesh_codec.h"

#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "codec_context_internal.h"
#include "idms/sim/check.h"
#include "idms/sim/model.h"
#include "varint_internal.h"

namespace idms {
namespace {

using internal::PutSigned;
using internal::VarintReader;

constexpr int64_t kInt32Min = std::numeric_limits<int32_t>::min();
constexpr int64_t kInt32Max = std::numeric_limits<int32_t>::max();
// A varint is at most 10 bytes: the most raw bytes a count of values can take.
constexpr int64_t kMaxVarintBytes = 10;

std::string Str(int64_t v) { return std::to_string(v); }

bool Fail(std::string* error, std::string message) {
  if (error != nullptr) *error = std::move(message);
  return false;
}

}  // namespace

CodecContext::CodecContext(int zstd_level) : impl_(std::make_unique<Impl>()) {
  impl_->cctx = ZSTD_createCCtx();
  impl_->dctx = ZSTD_createDCtx();
  IDMS_CHECK(impl_->cctx != nullptr && impl_->dctx != nullptr);
  ZSTD_CCtx_setParameter(impl_->cctx, ZSTD_c_compressionLevel, zstd_level);
  ZSTD_CCtx_setParameter(impl_->cctx, ZSTD_c_contentSizeFlag, 1);
  ZSTD_CCtx_setParameter(impl_->cctx, ZSTD_c_checksumFlag, 0);
  // Bounds the decoder's window memory whatever a frame asks for (2^27 = 128 MiB is zstd's own
  // default; our payloads are far smaller, so a frame asking for more is refused).
  ZSTD_DCtx_setParameter(impl_->dctx, ZSTD_d_windowLogMax, 26);
}

CodecContext::~CodecContext() {
  ZSTD_freeCCtx(impl_->cctx);
  ZSTD_freeDCtx(impl_->dctx);
}

void CodecContext::ReleaseScratchAbove(size_t keep_bytes) {
  if (impl_->raw.capacity() > keep_bytes) std::string().swap(impl_->raw);
  if (impl_->compressed.capacity() > keep_bytes) std::string().swap(impl_->compressed);
  if (impl_->ids.capacity() * sizeof(int32_t) > keep_bytes) std::vector<int32_t>().swap(impl_->ids);
  if (impl_->dq.capacity() * sizeof(int32_t) > keep_bytes) std::vector<int32_t>().swap(impl_->dq);
}

namespace internal {

v1::Compression CompressPayload(CodecContext::Impl& ctx, std::string* out) {
  // Compress into scratch; keep the raw bytes when zstd's frame overhead would not pay off.
  const size_t bound = ZSTD_compressBound(ctx.raw.size());
  if (ctx.compressed.size() < bound) ctx.compressed.resize(bound);
  const size_t n =
      ZSTD_compress2(ctx.cctx, ctx.compressed.data(), ctx.compressed.size(), ctx.raw.data(), ctx.raw.size());
  if (!ZSTD_isError(n) && n < ctx.raw.size()) {
    out->assign(ctx.compressed.data(), n);
    return v1::COMPRESSION_ZSTD;
  }
  out->assign(ctx.raw);
  return v1::COMPRESSION_NONE;
}

bool DecompressPayload(CodecContext::Impl& ctx, v1::Compression compression, std::string_view payload,
                       int64_t max_bytes, std::string_view* raw, std::string* error) {
  if (compression == v1::COMPRESSION_NONE) {
    if (static_cast<int64_t>(payload.size()) > max_bytes) {
      return Fail(error, "payload of " + Str(static_cast<int64_t>(payload.size())) + " bytes exceeds the limit of " +
                             Str(max_bytes));
    }
    *raw = payload;
    return true;
  }
  if (compression != v1::COMPRESSION_ZSTD) {
    return Fail(error, "unknown compression " + Str(compression));
  }
  // The declared size decides the buffer: it must be present and within the limit.
  const unsigned long long declared = ZSTD_getFrameContentSize(payload.data(), payload.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR) return Fail(error, "payload is not a zstd frame");
  if (declared == ZSTD_CONTENTSIZE_UNKNOWN) {
    return Fail(error, "zstd frame does not declare its content size");
  }
  if (declared > static_cast<unsigned long long>(max_bytes)) {
    return Fail(error,
                "zstd frame declares " + std::to_string(declared) + " bytes, more than the limit of " + Str(max_bytes));
  }
  // Exactly one frame, nothing after it.
  const size_t frame_size = ZSTD_findFrameCompressedSize(payload.data(), payload.size());
  if (ZSTD_isError(frame_size)) {
    return Fail(error, std::string("corrupt zstd frame: ") + ZSTD_getErrorName(frame_size));
  }
  if (frame_size != payload.size()) {
    return Fail(error, Str(static_cast<int64_t>(payload.size() - frame_size)) + " bytes follow the zstd frame");
  }
  // Decompress into exactly the declared size; a frame that holds more fails here.
  ctx.raw.resize(static_cast<size_t>(declared));
  const size_t n = ZSTD_decompressDCtx(ctx.dctx, ctx.raw.data(), ctx.raw.size(), payload.data(), payload.size());
  if (ZSTD_isError(n)) {
    ZSTD_DCtx_reset(ctx.dctx, ZSTD_reset_session_only);
    return Fail(error, std::string("zstd: ") + ZSTD_getErrorName(n));
  }
  if (n != declared) {
    return Fail(error, "zstd frame decompresses to " + Str(static_cast<int64_t>(n)) + " bytes but declares " +
                           std::to_string(declared));
  }
  *raw = std::string_view(ctx.raw.data(), n);
  return true;
}

}  // namespace internal

bool Quantize(std::span<const double> pos, double step, std::span<int32_t> q, std::string* error) {
  IDMS_CHECK(q.size() == pos.size());
  if (!(step > 0) || !std::isfinite(step)) return Fail(error, "quant_step must be > 0");
  const double inv = 1.0 / step;
  for (size_t i = 0; i < pos.size(); ++i) {
    const double v = pos[i] * inv;
    // The negated test also catches NaN.
    if (!(std::fabs(v) < static_cast<double>(kInt32Max))) {
      return Fail(error, "vertex " + Str(static_cast<int64_t>(i / 3)) + " axis " + Str(static_cast<int64_t>(i % 3)) +
                             ": position " + std::to_string(pos[i]) + " is not finite or outside +-" +
                             std::to_string(kInt32Max * step));
    }
    // Round half away from zero; a truncating conversion is much cheaper than lround.
    q[i] = static_cast<int32_t>(v + (v >= 0 ? 0.5 : -0.5));
  }
  return true;
}

void Dequantize(std::span<const int32_t> q, double step, std::span<float> pos) {
  IDMS_CHECK(q.size() == pos.size());
  for (size_t i = 0; i < q.size(); ++i) pos[i] = static_cast<float>(q[i] * step);
}

bool EncodeKeyframe(const FrameInfo& info, std::span<const int32_t> q, std::span<const int32_t> tri_verts,
                    CodecContext& ctx, v1::MeshKeyframe* out, std::string* error) {
  const int64_t num_vertices = static_cast<int64_t>(q.size() / 3);
  const int64_t num_triangles = static_cast<int64_t>(tri_verts.size() / 3);
  if (q.size() % 3 != 0 || tri_verts.size() % 3 != 0) {
    return Fail(error, "positions and triangles must be multiples of 3 values");
  }
  if (!(info.quant_step > 0) || !std::isfinite(info.quant_step)) {
    return Fail(error, "quant_step must be > 0");
  }
  for (size_t i = 0; i < tri_verts.size(); ++i) {
    if (tri_verts[i] < 0 || tri_verts[i] >= num_vertices) {
      return Fail(error, "triangle " + Str(static_cast<int64_t>(i / 3)) + " has vertex id " + Str(tri_verts[i]) +
                             ", outside [0, " + Str(num_vertices) + ")");
    }
  }
  // Planar axes, each vertex relative to the previous one (neighbours in plg order are close).
  CodecContext::Impl& c = ctx.impl();
  c.raw.clear();
  c.raw.reserve(static_cast<size_t>(3 * (num_vertices + num_triangles) * 3));
  for (int axis = 0; axis < 3; ++axis) {
    int64_t prev = 0;
    for (int64_t i = 0; i < num_vertices; ++i) {
      const int64_t v = q[static_cast<size_t>(3 * i + axis)];
      PutSigned(v - prev, &c.raw);
      prev = v;
    }
  }
  // Triangle ids, each relative to the previous id.
  int64_t prev = 0;
  for (const int32_t id : tri_verts) {
    PutSigned(id - prev, &c.raw);
    prev = id;
  }
  out->set_sequence(info.sequence);
  out->set_topology_version(info.topology_version);
  out->set_time_s(info.time_s);
  out->set_quant_step(info.quant_step);
  out->set_num_vertices(static_cast<uint32_t>(num_vertices));
  out->set_num_triangles(static_cast<uint32_t>(num_triangles));
  out->set_compression(internal::CompressPayload(c, out->mutable_payload()));
  return true;
}

bool EncodeDelta(const FrameInfo& info, std::span<const int32_t> base_q, std::span<const int32_t> next_q,
                 CodecContext& ctx, v1::MeshDelta* out, std::string* error) {
  if (base_q.size() != next_q.size() || base_q.size() % 3 != 0) {
    return Fail(error, "base and next positions differ in size");
  }
  // Collect the changed vertices and their per-axis changes (planar).
  CodecContext::Impl& c = ctx.impl();
  c.ids.clear();
  const size_t num_vertices = base_q.size() / 3;
  for (size_t i = 0; i < num_vertices; ++i) {
    const size_t k = 3 * i;
    if (base_q[k] != next_q[k] || base_q[k + 1] != next_q[k + 1] || base_q[k + 2] != next_q[k + 2]) {
      c.ids.push_back(static_cast<int32_t>(i));
    }
  }
  const size_t n = c.ids.size();
  out->set_sequence(info.sequence);
  out->set_base_sequence(info.base_sequence);
  out->set_topology_version(info.topology_version);
  out->set_time_s(info.time_s);
  out->set_num_changed(static_cast<uint32_t>(n));
  if (n == 0) {
    out->set_compression(v1::COMPRESSION_NONE);
    out->clear_payload();
    return true;
  }
  // Count, id gaps, then all x changes, all y changes, all z changes.
  c.raw.clear();
  c.raw.reserve(4 * n * 3 + kMaxVarintBytes);
  PutSigned(static_cast<int64_t>(n), &c.raw);
  int64_t prev = -1;
  for (const int32_t id : c.ids) {
    PutSigned(id - prev, &c.raw);
    prev = id;
  }
  for (size_t axis = 0; axis < 3; ++axis) {
    for (const int32_t id : c.ids) {
      const size_t k = 3 * static_cast<size_t>(id) + axis;
      PutSigned(int64_t{next_q[k]} - int64_t{base_q[k]}, &c.raw);
    }
  }
  out->set_compression(internal::CompressPayload(c, out->mutable_payload()));
  return true;
}

namespace {

// "keyframe 12: ", the start of every message about a frame (built only on failure).
std::string Where(const char* kind, uint64_t sequence) {
  return std::string(kind) + " " + std::to_string(sequence) + ": ";
}

// Reads a payload's zigzag values; a failure becomes one message naming the frame, the byte and
// the value being read. Messages are built only on failure: reading allocates nothing.
class ValueReader {
 public:
  ValueReader(std::string_view raw, const char* kind, uint64_t sequence)
      : reader_(raw.data(), raw.size()), kind_(kind), sequence_(sequence), size_(raw.size()) {}

  bool Read(int64_t* v) { return reader_.ReadSigned(v); }

  // After Read failed: why, where, and what was being read.
  bool ReadFailed(const std::string& what) {
    return Fail(std::string(reader_.error()) + " at byte " + Str(static_cast<int64_t>(reader_.offset())) + " (" + what +
                ")");
  }

  // False (with a message) when bytes are left after the counts the header gave.
  bool AtEnd(int64_t nv, int64_t nt) {
    if (reader_.at_end()) return true;
    const std::string counts = nt < 0 ? Str(nv) + " vertices" : Str(nv) + " vertices and " + Str(nt) + " triangles";
    return Fail(Str(static_cast<int64_t>(size_ - reader_.offset())) + " bytes left after " + counts +
                " (counts disagree with the payload)");
  }

  bool Fail(const std::string& message) {
    message_ = Where(kind_, sequence_) + message;
    return false;
  }

  const std::string& message() const { return message_; }

 private:
  VarintReader reader_;
  const char* kind_;
  uint64_t sequence_;
  size_t size_;
  std::string message_;
};

// base + d when the result is an int32; |d| < 2^33 keeps the sum far from int64 overflow.
bool AddInt32(int64_t base, int64_t d, int64_t* out) {
  if (d <= -(int64_t{1} << 33) || d >= (int64_t{1} << 33)) return false;
  *out = base + d;
  return *out >= kInt32Min && *out <= kInt32Max;
}

// Keyframe positions: planar axes, each value relative to the previous vertex's.
bool ReadPositions(ValueReader& r, int64_t nv, std::vector<int32_t>* q) {
  q->resize(static_cast<size_t>(3 * nv));
  for (int64_t axis = 0; axis < 3; ++axis) {
    int64_t prev = 0;
    for (int64_t i = 0; i < nv; ++i) {
      int64_t d = 0;
      if (!r.Read(&d)) return r.ReadFailed("vertex " + Str(i) + " axis " + Str(axis));
      if (!AddInt32(prev, d, &prev)) {
        return r.Fail("vertex " + Str(i) + " axis " + Str(axis) + " leaves the int32 range");
      }
      (*q)[static_cast<size_t>(3 * i + axis)] = static_cast<int32_t>(prev);
    }
  }
  return true;
}

// Keyframe triangles: ids relative to the previous id, each in [0, nv).
bool ReadTriangles(ValueReader& r, int64_t nv, int64_t nt, std::vector<int32_t>* tris) {
  tris->resize(static_cast<size_t>(3 * nt));
  int64_t prev = 0;
  for (int64_t j = 0; j < 3 * nt; ++j) {
    int64_t d = 0;
    if (!r.Read(&d)) return r.ReadFailed("triangle " + Str(j / 3));
    if (!AddInt32(prev, d, &prev) || prev < 0 || prev >= nv) {
      return r.Fail("triangle " + Str(j / 3) + " has a vertex id outside [0, " + Str(nv) + ")");
    }
    (*tris)[static_cast<size_t>(j)] = static_cast<int32_t>(prev);
  }
  return true;
}

// Delta ids: gaps >= 1 from -1, every id < nv.
bool ReadIds(ValueReader& r, int64_t n, int64_t nv, std::vector<int32_t>* ids) {
  ids->resize(static_cast<size_t>(n));
  int64_t prev = -1;
  for (int64_t k = 0; k < n; ++k) {
    int64_t gap = 0;
    if (!r.Read(&gap)) return r.ReadFailed("id " + Str(k));
    if (gap < 1) return r.Fail("ids not increasing at entry " + Str(k) + " (gap " + Str(gap) + ")");
    if (gap > nv - 1 - prev) return r.Fail("id at entry " + Str(k) + " is beyond the " + Str(nv) + " vertices");
    prev += gap;
    (*ids)[static_cast<size_t>(k)] = static_cast<int32_t>(prev);
  }
  return true;
}

// Delta changes, planar: the new values (3 x n, planar) into *next, q untouched.
bool ReadChanges(ValueReader& r, std::span<const int32_t> ids, std::span<const int32_t> q, std::vector<int32_t>* next) {
  const size_t n = ids.size();
  next->resize(3 * n);
  for (size_t axis = 0; axis < 3; ++axis) {
    for (size_t k = 0; k < n; ++k) {
      int64_t d = 0;
      const int32_t id = ids[k];
      if (!r.Read(&d)) return r.ReadFailed("vertex " + Str(id) + " axis " + Str(static_cast<int64_t>(axis)));
      int64_t v = 0;
      if (!AddInt32(q[3 * static_cast<size_t>(id) + axis], d, &v)) {
        return r.Fail("vertex " + Str(id) + " axis " + Str(static_cast<int64_t>(axis)) + " leaves the int32 range");
      }
      (*next)[axis * n + k] = static_cast<int32_t>(v);
    }
  }
  return true;
}

}  // namespace

bool DecodeKeyframe(const v1::MeshKeyframe& msg, const DecodeLimits& limits, CodecContext& ctx, DecodedKeyframe* out,
                    std::string* error) {
  const auto where = [&msg] { return Where("keyframe", msg.sequence()); };
  // Header values first: nothing is allocated for counts beyond the limits.
  if (!(msg.quant_step() > 0) || !std::isfinite(msg.quant_step())) {
    return Fail(error, where() + "quant_step must be finite and > 0, got " + std::to_string(msg.quant_step()));
  }
  const int64_t nv = msg.num_vertices();
  const int64_t nt = msg.num_triangles();
  if (nv > limits.max_vertices) {
    return Fail(error, where() + Str(nv) + " vertices exceed the limit of " + Str(limits.max_vertices));
  }
  if (nt > limits.max_triangles) {
    return Fail(error, where() + Str(nt) + " triangles exceed the limit of " + Str(limits.max_triangles));
  }
  // The payload, no larger than its counts allow.
  const int64_t num_values = 3 * (nv + nt);
  const int64_t max_bytes = std::min(limits.max_decompressed_bytes, kMaxVarintBytes * num_values);
  std::string_view raw;
  std::string message;
  if (!internal::DecompressPayload(ctx.impl(), msg.compression(), msg.payload(), max_bytes, &raw, &message)) {
    return Fail(error, where() + message);
  }
  // Every value takes at least one byte: a short payload cannot hold the counts it claims.
  if (static_cast<int64_t>(raw.size()) < num_values) {
    return Fail(error, where() + "payload of " + Str(static_cast<int64_t>(raw.size())) + " bytes is too short for " +
                           Str(nv) + " vertices and " + Str(nt) + " triangles");
  }
  // Positions, triangles, nothing after.
  ValueReader reader(raw, "keyframe", msg.sequence());
  std::vector<int32_t> q, tris;
  if (!ReadPositions(reader, nv, &q) || !ReadTriangles(reader, nv, nt, &tris) || !reader.AtEnd(nv, nt)) {
    return Fail(error, reader.message());
  }
  out->sequence = msg.sequence();
  out->topology_version = msg.topology_version();
  out->time_s = msg.time_s();
  out->quant_step = msg.quant_step();
  out->q.swap(q);
  out->tri_verts.swap(tris);
  return true;
}

bool ApplyDelta(const v1::MeshDelta& msg, const DecodeLimits& limits, CodecContext& ctx, std::span<int32_t> q,
                std::vector<int32_t>* changed, std::string* error) {
  const auto where = [&msg] { return Where("delta", msg.sequence()); };
  const int64_t nv = static_cast<int64_t>(q.size() / 3);
  const int64_t n = msg.num_changed();
  if (changed != nullptr) changed->clear();
  // Counts first: a delta lists at most every vertex, and nothing when it lists none.
  if (n > nv) return Fail(error, where() + "num_changed " + Str(n) + " exceeds the " + Str(nv) + " vertices");
  if (n == 0) {
    if (msg.payload().empty()) return true;
    return Fail(error, where() + "num_changed is 0 but the payload has " +
                           Str(static_cast<int64_t>(msg.payload().size())) + " bytes");
  }
  // The payload, no larger than n entries of 10-byte varints.
  const int64_t max_bytes = std::min(limits.max_decompressed_bytes, kMaxVarintBytes * (1 + 4 * n));
  CodecContext::Impl& c = ctx.impl();
  std::string_view raw;
  std::string message;
  if (!internal::DecompressPayload(c, msg.compression(), msg.payload(), max_bytes, &raw, &message)) {
    return Fail(error, where() + message);
  }
  // Count, ids, changes, nothing after; new values go to scratch so that q stays untouched on error.
  ValueReader reader(raw, "delta", msg.sequence());
  int64_t count = 0;
  if (!reader.Read(&count)) {
    reader.ReadFailed("count");
    return Fail(error, reader.message());
  }
  if (count != n)
    return Fail(error, where() + "payload lists " + Str(count) + " vertices but num_changed is " + Str(n));
  if (!ReadIds(reader, n, nv, &c.ids) || !ReadChanges(reader, c.ids, q, &c.dq) || !reader.AtEnd(n, -1)) {
    return Fail(error, reader.message());
  }
  // All valid: apply.
  const size_t nn = static_cast<size_t>(n);
  for (size_t axis = 0; axis < 3; ++axis) {
    for (size_t k = 0; k < nn; ++k) q[3 * static_cast<size_t>(c.ids[k]) + axis] = c.dq[axis * nn + k];
  }
  if (changed != nullptr) changed->assign(c.ids.begin(), c.ids.end());
  return true;
}

}  // namespace idms
