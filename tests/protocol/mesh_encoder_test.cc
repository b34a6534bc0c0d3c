// MeshEncoder: the keyframe policy (start, interval, topology, request), the deadband, and
// invalid positions refused without changing what receivers are assumed to hold.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "idms/protocol/mesh_codec.h"
#include "idms/protocol/mesh_mirror.h"
#include "idms/sim/generate.h"

namespace idms {
namespace {

struct Surface {
  std::vector<double> rest;  // (num_vertices x 3)
  std::vector<int32_t> tris;
};

Surface Slab(int32_t rows, int32_t cols) {
  SlabOptions options;
  options.rows = rows;
  options.cols = cols;
  const Model model = GenerateSlab(options);
  Surface s;
  s.rest.resize(3 * model.external_atoms.size());
  GatherSurface(model, model.atom_pos_eq, s.rest);
  s.tris = SurfaceTriangles(model);
  return s;
}

// The rest surface pressed by a Gaussian dent of `depth` at (cx, cy).
std::vector<double> Dent(const Surface& s, double cx, double cy, double depth) {
  std::vector<double> p = s.rest;
  for (size_t i = 0; i < p.size(); i += 3) {
    const double dx = p[i] - cx, dy = p[i + 1] - cy;
    const double g = std::exp(-(dx * dx + dy * dy) / (2 * 0.75 * 0.75));
    p[i] += 0.1 * depth * dx * g;
    p[i + 1] += 0.1 * depth * dy * g;
    p[i + 2] -= depth * g;
  }
  return p;
}

TEST(MeshEncoder, KeyframeAtStartThenDeltas) {
  const Surface s = Slab(5, 4);
  MeshEncoder encoder;
  encoder.SetTopology(1, s.tris);
  v1::Envelope env;
  std::string error;
  EncodeStats stats;
  ASSERT_TRUE(encoder.Encode(0, s.rest, &env, &error, &stats)) << error;
  EXPECT_TRUE(env.has_mesh_keyframe());
  EXPECT_TRUE(stats.keyframe);
  EXPECT_EQ(env.mesh_keyframe().sequence(), 1u);
  EXPECT_EQ(env.mesh_keyframe().topology_version(), 1u);

  ASSERT_TRUE(encoder.Encode(1.0 / 60, Dent(s, 2, 1.7, 0.3), &env, &error, &stats)) << error;
  ASSERT_TRUE(env.has_mesh_delta());
  EXPECT_FALSE(stats.keyframe);
  EXPECT_EQ(env.mesh_delta().sequence(), 2u);
  EXPECT_EQ(env.mesh_delta().base_sequence(), 1u);
  EXPECT_GT(stats.num_changed, 0);
  EXPECT_EQ(encoder.sequence(), 2u);
}

TEST(MeshEncoder, KeyframesOnIntervalTopologyAndRequest) {
  const Surface s = Slab(5, 4);
  EncoderOptions options;
  options.keyframe_interval_s = 1.0;
  MeshEncoder encoder(options);
  encoder.SetTopology(1, s.tris);
  v1::Envelope env;
  std::string error;
  std::vector<int> keyframe_frames;
  for (int f = 0; f < 180; ++f) {
    if (f == 100) encoder.RequestKeyframe();
    if (f == 110) encoder.SetTopology(2, s.tris);
    if (f == 111) encoder.SetTopology(2, s.tris);  // same version: no keyframe
    // 64 Hz keeps frame times exact in binary.
    ASSERT_TRUE(encoder.Encode(f / 64.0, s.rest, &env, &error)) << error;
    if (env.has_mesh_keyframe()) keyframe_frames.push_back(f);
  }
  EXPECT_EQ(keyframe_frames, (std::vector<int>{0, 64, 100, 110, 174}));
}

TEST(MeshEncoder, TimeRunningBackwardsSendsAKeyframe) {
  const Surface s = Slab(5, 4);
  MeshEncoder encoder;
  encoder.SetTopology(1, s.tris);
  v1::Envelope env;
  std::string error;
  ASSERT_TRUE(encoder.Encode(3.0, s.rest, &env, &error));
  ASSERT_TRUE(encoder.Encode(3.1, s.rest, &env, &error));
  EXPECT_TRUE(env.has_mesh_delta());
  ASSERT_TRUE(encoder.Encode(0.0, s.rest, &env, &error));
  EXPECT_TRUE(env.has_mesh_keyframe());
}

TEST(MeshEncoder, RefusesInvalidPositionsAndKeepsState) {
  const Surface s = Slab(5, 4);
  MeshEncoder encoder;
  encoder.SetTopology(1, s.tris);
  v1::Envelope env;
  std::string error;
  ASSERT_TRUE(encoder.Encode(0, s.rest, &env, &error));
  const std::vector<int32_t> sent(encoder.sent().begin(), encoder.sent().end());

  std::vector<double> bad = Dent(s, 2, 1.7, 0.3);
  bad[3 * 7 + 2] = std::nan("");
  EXPECT_FALSE(encoder.Encode(0.1, bad, &env, &error));
  EXPECT_NE(error.find("vertex 7 axis 2"), std::string::npos) << error;
  EXPECT_EQ(encoder.sequence(), 1u);
  EXPECT_EQ(std::vector<int32_t>(encoder.sent().begin(), encoder.sent().end()), sent);

  // A different vertex count without a topology change.
  std::vector<double> fewer(s.rest.begin(), s.rest.end() - 3);
  EXPECT_FALSE(encoder.Encode(0.2, fewer, &env, &error));
  EXPECT_NE(error.find("without a new topology version"), std::string::npos) << error;
  EXPECT_EQ(encoder.sequence(), 1u);
}

// The deadband trades vertices per delta for error: with a threshold of t steps, what receivers
// hold is never more than t steps off on any axis, and fewer vertices are sent than at 0.5.
TEST(MeshEncoder, DeadbandBoundsErrorAndSendsLess) {
  const Surface s = Slab(20, 20);
  int64_t changed[2] = {0, 0};
  const double thresholds[2] = {0.5, 1.0};
  for (int t = 0; t < 2; ++t) {
    EncoderOptions options;
    options.resend_threshold_steps = thresholds[t];
    MeshEncoder encoder(options);
    encoder.SetTopology(1, s.tris);
    v1::Envelope env;
    std::string error;
    EncodeStats stats;
    double max_err_steps = 0;
    for (int f = 0; f < 240; ++f) {
      // Slow press and release: many vertices move by less than a step per frame.
      const double depth = 0.3 * std::sin(3.14159 * f / 240.0);
      const std::vector<double> p = Dent(s, 10, 8, depth);
      ASSERT_TRUE(encoder.Encode(f / 60.0, p, &env, &error, &stats)) << error;
      if (!stats.keyframe) changed[t] += stats.num_changed;
      for (size_t i = 0; i < p.size(); ++i) {
        max_err_steps = std::max(max_err_steps, std::fabs(p[i] / 1e-4 - encoder.sent()[i]));
      }
    }
    EXPECT_LE(max_err_steps, thresholds[t] + 1e-6);
  }
  EXPECT_LT(changed[1], changed[0]);
}

}  // namespace
}  // namespace idms
