// The mesh codec's pure functions: round trips, and every malformed or oversize payload rejected
// with a message (never a crash, never a half-applied delta).
#include "idms/protocol/mesh_codec.h"

#include <gtest/gtest.h>
#include <zstd.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "idms/sim/generate.h"

namespace idms {
namespace {

// Zigzag LEB128, written independently of the codec so that the tests check the documented format.
void Put(int64_t v, std::string* out) {
  uint64_t u = (static_cast<uint64_t>(v) << 1) ^ static_cast<uint64_t>(v >> 63);
  while (u >= 0x80) {
    out->push_back(static_cast<char>((u & 0x7F) | 0x80));
    u >>= 7;
  }
  out->push_back(static_cast<char>(u));
}

std::string Zstd(const std::string& raw, bool declare_size = true) {
  if (declare_size) {
    std::string out(ZSTD_compressBound(raw.size()), '\0');
    out.resize(ZSTD_compress(out.data(), out.size(), raw.data(), raw.size(), 3));
    return out;
  }
  // Without the content size flag the frame does not declare its size.
  ZSTD_CCtx* cctx = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 0);
  std::string out(ZSTD_compressBound(raw.size()), '\0');
  out.resize(ZSTD_compress2(cctx, out.data(), out.size(), raw.data(), raw.size()));
  ZSTD_freeCCtx(cctx);
  return out;
}

// A delta message with a hand-made raw payload.
v1::MeshDelta RawDelta(uint32_t num_changed, const std::string& payload,
                       v1::Compression compression = v1::COMPRESSION_NONE) {
  v1::MeshDelta d;
  d.set_sequence(2);
  d.set_base_sequence(1);
  d.set_num_changed(num_changed);
  d.set_compression(compression);
  d.set_payload(payload);
  return d;
}

std::vector<int32_t> Grid(int32_t nv) {
  std::vector<int32_t> q(3 * static_cast<size_t>(nv));
  for (size_t i = 0; i < q.size(); ++i) q[i] = static_cast<int32_t>(i * 7 % 1000) - 500;
  return q;
}

TEST(Quantize, RoundsToNearestAndRejectsNonFinite) {
  std::vector<double> pos = {0.00014, -0.00016, 1.0, 0.00005, -0.00005, 0};
  std::vector<int32_t> q(pos.size());
  std::string error;
  ASSERT_TRUE(Quantize(pos, 1e-4, q, &error)) << error;
  EXPECT_EQ(q, (std::vector<int32_t>{1, -2, 10000, 1, -1, 0}));

  pos[4] = std::nan("");
  EXPECT_FALSE(Quantize(pos, 1e-4, q, &error));
  EXPECT_NE(error.find("vertex 1 axis 1"), std::string::npos) << error;
  pos[4] = 1e6;  // 1e10 quanta: beyond int32
  EXPECT_FALSE(Quantize(pos, 1e-4, q, &error));
  EXPECT_FALSE(Quantize(pos, 0, q, &error));
}

TEST(Keyframe, RoundTripsPositionsAndTriangles) {
  const Model model = GenerateSlab(SlabOptions{});
  std::vector<double> pos(3 * model.external_atoms.size());
  GatherSurface(model, model.atom_pos_eq, pos);
  std::vector<int32_t> q(pos.size());
  std::string error;
  ASSERT_TRUE(Quantize(pos, 1e-4, q, &error));
  const std::vector<int32_t> tris = SurfaceTriangles(model);
  ASSERT_EQ(tris.size(), 28u * 3);

  CodecContext ctx;
  v1::MeshKeyframe msg;
  const FrameInfo info{.sequence = 5, .topology_version = 3, .time_s = 1.5, .quant_step = 1e-4};
  ASSERT_TRUE(EncodeKeyframe(info, q, tris, ctx, &msg, &error)) << error;
  EXPECT_EQ(msg.num_vertices(), 22u);
  EXPECT_EQ(msg.num_triangles(), 28u);

  DecodedKeyframe out;
  ASSERT_TRUE(DecodeKeyframe(msg, DecodeLimits{}, ctx, &out, &error)) << error;
  EXPECT_EQ(out.q, q);
  EXPECT_EQ(out.tri_verts, tris);
  EXPECT_EQ(out.sequence, 5u);
  EXPECT_EQ(out.topology_version, 3u);
  EXPECT_EQ(out.time_s, 1.5);
  EXPECT_EQ(out.quant_step, 1e-4);
}

TEST(Keyframe, LargeKeyframeIsCompressed) {
  const std::vector<int32_t> q = Grid(20000);
  CodecContext ctx;
  v1::MeshKeyframe msg;
  std::string error;
  ASSERT_TRUE(EncodeKeyframe(FrameInfo{}, q, {}, ctx, &msg, &error));
  EXPECT_EQ(msg.compression(), v1::COMPRESSION_ZSTD);
  DecodedKeyframe out;
  ASSERT_TRUE(DecodeKeyframe(msg, DecodeLimits{}, ctx, &out, &error)) << error;
  EXPECT_EQ(out.q, q);
}

TEST(Keyframe, EncodeRejectsTriangleOutOfRange) {
  const std::vector<int32_t> q = Grid(3);
  const std::vector<int32_t> tris = {0, 1, 3};
  CodecContext ctx;
  v1::MeshKeyframe msg;
  std::string error;
  EXPECT_FALSE(EncodeKeyframe(FrameInfo{}, q, tris, ctx, &msg, &error));
  EXPECT_NE(error.find("vertex id 3"), std::string::npos) << error;
}

// A keyframe message with a hand-made raw payload.
v1::MeshKeyframe RawKeyframe(uint32_t nv, uint32_t nt, const std::string& payload,
                             v1::Compression compression = v1::COMPRESSION_NONE) {
  v1::MeshKeyframe k;
  k.set_sequence(1);
  k.set_quant_step(1e-4);
  k.set_num_vertices(nv);
  k.set_num_triangles(nt);
  k.set_compression(compression);
  k.set_payload(payload);
  return k;
}

std::string DecodeKeyframeError(const v1::MeshKeyframe& msg, const DecodeLimits& limits = {}) {
  CodecContext ctx;
  DecodedKeyframe out;
  out.sequence = 77;
  std::string error;
  EXPECT_FALSE(DecodeKeyframe(msg, limits, ctx, &out, &error));
  EXPECT_EQ(out.sequence, 77u) << "output changed on failure";
  EXPECT_FALSE(error.empty());
  return error;
}

TEST(Keyframe, RejectsMalformed) {
  // One vertex (x, y, z) and one triangle (0, 0, 0): a valid payload to break.
  std::string good;
  for (int v : {10, 20, 30, 0, 0, 0}) Put(v, &good);
  {
    CodecContext ctx;
    DecodedKeyframe out;
    std::string error;
    ASSERT_TRUE(DecodeKeyframe(RawKeyframe(1, 1, good), {}, ctx, &out, &error)) << error;
  }
  auto bad_step = RawKeyframe(1, 1, good);
  bad_step.set_quant_step(0);
  EXPECT_NE(DecodeKeyframeError(bad_step).find("quant_step"), std::string::npos);
  bad_step.set_quant_step(std::nan(""));
  EXPECT_NE(DecodeKeyframeError(bad_step).find("quant_step"), std::string::npos);

  DecodeLimits small;
  small.max_vertices = 100;
  small.max_triangles = 100;
  EXPECT_NE(DecodeKeyframeError(RawKeyframe(101, 1, good), small).find("vertices exceed"), std::string::npos);
  EXPECT_NE(DecodeKeyframeError(RawKeyframe(1, 101, good), small).find("triangles exceed"), std::string::npos);
  // Counts that disagree with the payload, both ways.
  EXPECT_NE(DecodeKeyframeError(RawKeyframe(1000000, 0, good)).find("too short"), std::string::npos);
  EXPECT_NE(DecodeKeyframeError(RawKeyframe(1, 0, good)).find("bytes left"), std::string::npos);
  // Triangle id out of range.
  std::string bad_tri;
  for (int v : {10, 20, 30, 0, 1, -1}) Put(v, &bad_tri);
  EXPECT_NE(DecodeKeyframeError(RawKeyframe(1, 1, bad_tri)).find("outside [0, 1)"), std::string::npos);
  // Truncated varint: the last byte keeps its continuation bit.
  std::string truncated = good;
  truncated.back() = static_cast<char>(0x80);
  EXPECT_NE(DecodeKeyframeError(RawKeyframe(1, 1, truncated)).find("truncated varint"), std::string::npos);
  // A coordinate beyond int32.
  std::string big;
  Put(int64_t{1} << 40, &big);
  for (int v : {0, 0, 0, 0, 0}) Put(v, &big);
  EXPECT_NE(DecodeKeyframeError(RawKeyframe(1, 1, big)).find("int32"), std::string::npos);
}

TEST(Keyframe, RejectsOversizeZstd) {
  // 1 MiB of zero bytes compresses to a few hundred bytes: a small frame declaring a big payload.
  const std::string bomb = Zstd(std::string(1 << 20, '\0'));
  ASSERT_LT(bomb.size(), 1000u);
  // 10 vertices allow at most 300 raw bytes whatever the limits.
  const std::string error = DecodeKeyframeError(RawKeyframe(10, 0, bomb, v1::COMPRESSION_ZSTD));
  EXPECT_NE(error.find("declares 1048576 bytes, more than the limit of 300"), std::string::npos) << error;
  // The absolute limit applies even when the counts would allow it.
  DecodeLimits limits;
  limits.max_decompressed_bytes = 4096;
  const std::string error2 = DecodeKeyframeError(RawKeyframe(1000000, 0, bomb, v1::COMPRESSION_ZSTD), limits);
  EXPECT_NE(error2.find("limit of 4096"), std::string::npos) << error2;
}

std::string ApplyDeltaError(const v1::MeshDelta& msg, int32_t nv = 10, const DecodeLimits& limits = {}) {
  CodecContext ctx;
  std::vector<int32_t> q = Grid(nv);
  const std::vector<int32_t> before = q;
  std::string error;
  EXPECT_FALSE(ApplyDelta(msg, limits, ctx, q, nullptr, &error));
  EXPECT_EQ(q, before) << "state changed by a rejected delta";
  EXPECT_FALSE(error.empty());
  return error;
}

TEST(Delta, RoundTripsAndListsChangedVertices) {
  std::mt19937 rng(7);
  const std::vector<int32_t> base = Grid(5000);
  std::vector<int32_t> next = base;
  std::vector<int32_t> moved;
  for (int32_t i = 0; i < 5000; i += 1 + static_cast<int32_t>(rng() % 40)) {
    moved.push_back(i);
    next[3 * static_cast<size_t>(i) + rng() % 3] += static_cast<int32_t>(rng() % 2001) - 1000;
    next[3 * static_cast<size_t>(i)] += 1;  // every listed vertex changes at least x
  }
  CodecContext ctx;
  v1::MeshDelta msg;
  std::string error;
  const FrameInfo info{.sequence = 8, .base_sequence = 7, .topology_version = 2, .time_s = 0.5};
  ASSERT_TRUE(EncodeDelta(info, base, next, ctx, &msg, &error)) << error;
  EXPECT_EQ(msg.num_changed(), moved.size());
  EXPECT_EQ(msg.sequence(), 8u);
  EXPECT_EQ(msg.base_sequence(), 7u);

  std::vector<int32_t> q = base;
  std::vector<int32_t> changed;
  ASSERT_TRUE(ApplyDelta(msg, DecodeLimits{}, ctx, q, &changed, &error)) << error;
  EXPECT_EQ(q, next);
  EXPECT_EQ(changed, moved);
}

TEST(Delta, NothingChangedIsAnEmptyPayload) {
  const std::vector<int32_t> q = Grid(100);
  CodecContext ctx;
  v1::MeshDelta msg;
  std::string error;
  ASSERT_TRUE(EncodeDelta(FrameInfo{}, q, q, ctx, &msg, &error));
  EXPECT_EQ(msg.num_changed(), 0u);
  EXPECT_TRUE(msg.payload().empty());
  std::vector<int32_t> copy = q;
  EXPECT_TRUE(ApplyDelta(msg, DecodeLimits{}, ctx, copy, nullptr, &error)) << error;
  EXPECT_EQ(copy, q);
}

// A payload listing `ids` (as given, gaps computed) with change (1, 2, 3) each.
std::string Payload(int64_t count, const std::vector<int64_t>& ids) {
  std::string p;
  Put(count, &p);
  int64_t prev = -1;
  for (const int64_t id : ids) {
    Put(id - prev, &p);
    prev = id;
  }
  for (int axis = 1; axis <= 3; ++axis) {
    for (size_t k = 0; k < ids.size(); ++k) Put(axis, &p);
  }
  return p;
}

TEST(Delta, AcceptsHandMadePayload) {
  CodecContext ctx;
  std::vector<int32_t> q = Grid(10);
  const std::vector<int32_t> before = q;
  std::string error;
  ASSERT_TRUE(ApplyDelta(RawDelta(2, Payload(2, {3, 9})), {}, ctx, q, nullptr, &error)) << error;
  EXPECT_EQ(q[9], before[9] + 1);
  EXPECT_EQ(q[10], before[10] + 2);
  EXPECT_EQ(q[29], before[29] + 3);
}

TEST(Delta, RejectsIdsOutOfRangeOrNotIncreasing) {
  EXPECT_NE(ApplyDeltaError(RawDelta(2, Payload(2, {3, 10}))).find("beyond the 10 vertices"), std::string::npos);
  EXPECT_NE(ApplyDeltaError(RawDelta(2, Payload(2, {3, 3}))).find("not increasing at entry 1"), std::string::npos);
  EXPECT_NE(ApplyDeltaError(RawDelta(2, Payload(2, {5, 2}))).find("not increasing"), std::string::npos);
  EXPECT_NE(ApplyDeltaError(RawDelta(1, Payload(1, {-1}))).find("not increasing"), std::string::npos);
  // A gap so large that prev + gap would overflow.
  std::string p;
  Put(1, &p);
  Put(std::numeric_limits<int64_t>::max(), &p);
  for (int i = 0; i < 3; ++i) Put(0, &p);
  EXPECT_NE(ApplyDeltaError(RawDelta(1, p)).find("beyond"), std::string::npos);
}

TEST(Delta, RejectsCountsThatDisagree) {
  EXPECT_NE(ApplyDeltaError(RawDelta(11, Payload(11, {}))).find("exceeds the 10 vertices"), std::string::npos);
  EXPECT_NE(ApplyDeltaError(RawDelta(2, Payload(3, {1, 2, 3}))).find("lists 3 vertices"), std::string::npos);
  EXPECT_NE(ApplyDeltaError(RawDelta(2, Payload(2, {1, 2}) + '\x02')).find("bytes left"), std::string::npos);
  EXPECT_NE(ApplyDeltaError(RawDelta(0, Payload(0, {}))).find("num_changed is 0"), std::string::npos);
  // Payload ends before the last change.
  std::string short_payload = Payload(2, {1, 2});
  short_payload.pop_back();
  EXPECT_NE(ApplyDeltaError(RawDelta(2, short_payload)).find("payload ends early"), std::string::npos);
}

TEST(Delta, RejectsBadVarints) {
  std::string truncated = Payload(1, {4});
  truncated.back() = static_cast<char>(0x81);
  EXPECT_NE(ApplyDeltaError(RawDelta(1, truncated)).find("truncated varint"), std::string::npos);
  std::string overlong;
  Put(1, &overlong);
  overlong += std::string(10, '\xff') + '\x01';
  EXPECT_NE(ApplyDeltaError(RawDelta(1, overlong)).find("longer than 64 bits"), std::string::npos);
}

TEST(Delta, RejectsValuesLeavingInt32) {
  std::string p;
  Put(1, &p);
  Put(1, &p);  // id 0
  Put(int64_t{1} << 40, &p);
  Put(0, &p);
  Put(0, &p);
  EXPECT_NE(ApplyDeltaError(RawDelta(1, p)).find("int32"), std::string::npos);
  // The largest change that still lands inside int32 from the grid value is fine; one more is not.
  std::string q;
  Put(1, &q);
  Put(1, &q);
  Put(int64_t{std::numeric_limits<int32_t>::max()} + 1 + 500, &q);  // Grid(..)[0] = -500
  Put(0, &q);
  Put(0, &q);
  EXPECT_NE(ApplyDeltaError(RawDelta(1, q)).find("int32"), std::string::npos);
}

TEST(Delta, RejectsBadCompression) {
  const std::string payload = Payload(2, {1, 2});
  // Unknown compression value.
  EXPECT_NE(ApplyDeltaError(RawDelta(2, payload, static_cast<v1::Compression>(7))).find("unknown compression 7"),
            std::string::npos);
  // Not zstd at all.
  EXPECT_NE(ApplyDeltaError(RawDelta(2, payload, v1::COMPRESSION_ZSTD)).find("not a zstd frame"), std::string::npos);
  // No declared content size.
  EXPECT_NE(ApplyDeltaError(RawDelta(2, Zstd(payload, false), v1::COMPRESSION_ZSTD)).find("does not declare"),
            std::string::npos);
  // Two frames back to back.
  EXPECT_NE(
      ApplyDeltaError(RawDelta(2, Zstd(payload) + Zstd(payload), v1::COMPRESSION_ZSTD)).find("follow the zstd frame"),
      std::string::npos);
  // Cut short.
  std::string cut = Zstd(std::string(500, 'a') + payload);
  cut.resize(cut.size() - 3);
  EXPECT_FALSE(ApplyDeltaError(RawDelta(2, cut, v1::COMPRESSION_ZSTD)).empty());
  // Valid zstd of a valid payload is accepted.
  CodecContext ctx;
  std::vector<int32_t> q = Grid(10);
  std::string error;
  EXPECT_TRUE(ApplyDelta(RawDelta(2, Zstd(payload), v1::COMPRESSION_ZSTD), {}, ctx, q, nullptr, &error)) << error;
}

TEST(Delta, RejectsOversizeZstd) {
  // Two changed vertices allow 10 * (1 + 4 * 2) = 90 raw bytes.
  const std::string bomb = Zstd(std::string(1 << 20, '\0'));
  const std::string error = ApplyDeltaError(RawDelta(2, bomb, v1::COMPRESSION_ZSTD));
  EXPECT_NE(error.find("declares 1048576 bytes, more than the limit of 90"), std::string::npos) << error;
  // And a raw payload beyond the limit.
  EXPECT_NE(ApplyDeltaError(RawDelta(2, std::string(91, '\x02'))).find("exceeds the limit"), std::string::npos);
}

TEST(Delta, EncodeRefusesDifferentSizes) {
  CodecContext ctx;
  v1::MeshDelta msg;
  std::string error;
  EXPECT_FALSE(EncodeDelta(FrameInfo{}, Grid(3), Grid(4), ctx, &msg, &error));
}

}  // namespace
}  // namespace idms
