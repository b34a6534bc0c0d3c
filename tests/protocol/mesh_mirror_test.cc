// MeshMirror: over many frames of motion it equals the quantized truth; gaps, stale and
// malformed frames are reported and leave it showing the last good frame.
#include "idms/protocol/mesh_mirror.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "idms/protocol/envelope.h"
#include "idms/sim/generate.h"

namespace idms {
namespace {

// A slab surface with a dent sliding across it and pressing in and out (a stroke), plus a
// small lateral drag, so that all three axes change.
class Stroke {
 public:
  explicit Stroke(int32_t rows = 12, int32_t cols = 10) {
    SlabOptions options;
    options.rows = rows;
    options.cols = cols;
    const Model model = GenerateSlab(options);
    rest_.resize(3 * model.external_atoms.size());
    GatherSurface(model, model.atom_pos_eq, rest_);
    tris_ = SurfaceTriangles(model);
    width_ = cols;
    height_ = rows * 0.866;
  }

  std::vector<double> At(double t) const {
    std::vector<double> p = rest_;
    const double cx = width_ * (0.1 + 0.8 * std::fmod(t / 4.0, 1.0));
    const double cy = height_ / 2;
    const double depth = 0.4 * std::min(1.0, t);
    for (size_t i = 0; i < p.size(); i += 3) {
      const double dx = p[i] - cx, dy = p[i + 1] - cy;
      const double g = std::exp(-(dx * dx + dy * dy) / (2 * 0.8 * 0.8));
      p[i] += 0.05 * depth * g;
      p[i + 1] += 0.02 * depth * dy * g;
      p[i + 2] -= depth * g;
    }
    return p;
  }

  const std::vector<int32_t>& tris() const { return tris_; }

 private:
  std::vector<double> rest_;
  std::vector<int32_t> tris_;
  double width_ = 0, height_ = 0;
};

// Max over vertices and axes of |mirror - truth| in quantization steps.
double MaxErrorSteps(const MeshMirror& mirror, const std::vector<double>& truth) {
  double err = 0;
  for (size_t i = 0; i < truth.size(); ++i) {
    err = std::max(err, std::fabs(mirror.positions()[i] - truth[i]) / mirror.quant_step());
  }
  return err;
}

// The stroke's encoder (topology 1) and a viewer's mirror, for the tests of what the mirror
// refuses. Apply(t) encodes the stroke at t into env and applies it.
class StrokedMirror : public ::testing::Test {
 protected:
  StrokedMirror() { encoder.SetTopology(1, stroke.tris()); }

  MirrorStatus Apply(double t) {
    if (!encoder.Encode(t, stroke.At(t), &env, &error)) return MirrorStatus::kInvalid;
    return mirror.Apply(env, &error);
  }

  const Stroke stroke;
  MeshEncoder encoder;
  MeshMirror mirror;
  v1::Envelope env;
  std::string error;
};

TEST(MeshMirror, FollowsManyFramesOfMotionWithinOneStep) {
  const Stroke stroke;
  MeshEncoder encoder;
  encoder.SetTopology(4, stroke.tris());
  MeshMirror mirror;
  v1::Envelope env, received;
  std::string bytes, error;
  double worst = 0;
  int deltas = 0;
  for (int f = 0; f < 600; ++f) {
    const double t = f / 60.0;
    const std::vector<double> p = stroke.At(t);
    ASSERT_TRUE(encoder.Encode(t, p, &env, &error)) << error;
    // Through the wire format, as a viewer gets it.
    SerializeEnvelope(env, &bytes);
    ASSERT_TRUE(ParseEnvelope(bytes, &received, &error)) << error;
    ASSERT_EQ(mirror.Apply(received, &error), MirrorStatus::kOk) << error;
    deltas += received.has_mesh_delta();
    // The mirror holds exactly what the encoder sent, which is truth rounded to the grid.
    ASSERT_TRUE(
        std::equal(mirror.quantized().begin(), mirror.quantized().end(), encoder.sent().begin(), encoder.sent().end()))
        << "frame " << f;
    worst = std::max(worst, MaxErrorSteps(mirror, p));
    EXPECT_EQ(mirror.sequence(), encoder.sequence());
    EXPECT_EQ(mirror.time_s(), t);
  }
  EXPECT_GT(deltas, 500);
  // Half a step from rounding, plus float conversion of coordinates of size ~10.
  EXPECT_LE(worst, 0.5 + 0.05);
  EXPECT_EQ(mirror.topology_version(), 4u);
  EXPECT_EQ(std::vector<int32_t>(mirror.triangles().begin(), mirror.triangles().end()), stroke.tris());
}

TEST_F(StrokedMirror, DeltaBeforeKeyframeIsAGap) {
  v1::Envelope key, delta;
  ASSERT_TRUE(encoder.Encode(0, stroke.At(0), &key, &error));
  ASSERT_TRUE(encoder.Encode(0.5, stroke.At(0.5), &delta, &error));
  EXPECT_EQ(mirror.Apply(delta, &error), MirrorStatus::kGap);
  EXPECT_NE(error.find("no keyframe"), std::string::npos) << error;
  EXPECT_FALSE(mirror.has_keyframe());
  EXPECT_EQ(mirror.Apply(key, &error), MirrorStatus::kOk) << error;
  EXPECT_EQ(mirror.Apply(delta, &error), MirrorStatus::kOk) << error;
}

TEST_F(StrokedMirror, LostDeltaIsAGapUntilTheNextKeyframe) {
  std::vector<float> shown;
  for (int f = 0; f < 40; ++f) {
    const double t = 1.0 + f / 60.0;
    if (f == 30) encoder.RequestKeyframe();  // the viewer asked after the gap
    ASSERT_TRUE(encoder.Encode(t, stroke.At(t), &env, &error));
    if (f == 10) continue;  // lost on the way
    const MirrorStatus status = mirror.Apply(env, &error);
    if (f < 10) {
      EXPECT_EQ(status, MirrorStatus::kOk) << error;
      shown.assign(mirror.positions().begin(), mirror.positions().end());
    } else if (f < 30) {
      // Every delta after the lost one is refused and the mirror keeps frame 10's state.
      EXPECT_EQ(status, MirrorStatus::kGap) << "frame " << f;
      EXPECT_EQ(mirror.sequence(), 10u);
      EXPECT_EQ(std::vector<float>(mirror.positions().begin(), mirror.positions().end()), shown);
      if (f == 11) {
        EXPECT_NE(error.find("base 11 is ahead of the mirror's frame 10"), std::string::npos) << error;
      }
    } else {
      EXPECT_EQ(status, MirrorStatus::kOk) << error;
      EXPECT_EQ(mirror.sequence(), encoder.sequence());
    }
  }
  EXPECT_LE(MaxErrorSteps(mirror, stroke.At(1.0 + 39 / 60.0)), 0.55);
}

TEST_F(StrokedMirror, StaleOrRepeatedDeltaIsAGap) {
  v1::Envelope old_delta;
  for (int f = 0; f < 5; ++f) {
    ASSERT_EQ(Apply(1 + f / 60.0), MirrorStatus::kOk) << error;
    if (f == 2) old_delta = env;
  }
  EXPECT_EQ(mirror.Apply(old_delta, &error), MirrorStatus::kGap);
  EXPECT_NE(error.find("stale"), std::string::npos) << error;
  EXPECT_EQ(mirror.Apply(env, &error), MirrorStatus::kGap);  // the last one, repeated
  EXPECT_EQ(mirror.sequence(), 5u);
}

TEST_F(StrokedMirror, MalformedDeltaLeavesStateUntouched) {
  ASSERT_EQ(Apply(1), MirrorStatus::kOk) << error;
  ASSERT_TRUE(encoder.Encode(1.1, stroke.At(1.1), &env, &error));
  ASSERT_TRUE(env.has_mesh_delta());
  ASSERT_GT(env.mesh_delta().num_changed(), 0u);
  const std::vector<float> before(mirror.positions().begin(), mirror.positions().end());

  v1::MeshDelta corrupt = env.mesh_delta();
  corrupt.mutable_payload()->push_back(1);
  EXPECT_EQ(mirror.Apply(corrupt, &error), MirrorStatus::kInvalid);
  v1::MeshDelta wrong_count = env.mesh_delta();
  wrong_count.set_num_changed(wrong_count.num_changed() + 1);
  EXPECT_EQ(mirror.Apply(wrong_count, &error), MirrorStatus::kInvalid);
  EXPECT_NE(error.find("num_changed"), std::string::npos) << error;
  v1::MeshDelta wrong_topology = env.mesh_delta();
  wrong_topology.set_topology_version(9);
  EXPECT_EQ(mirror.Apply(wrong_topology, &error), MirrorStatus::kInvalid);
  EXPECT_NE(error.find("topology version 9"), std::string::npos) << error;
  v1::MeshDelta not_after = env.mesh_delta();
  not_after.set_sequence(not_after.base_sequence());
  EXPECT_EQ(mirror.Apply(not_after, &error), MirrorStatus::kInvalid);

  EXPECT_EQ(std::vector<float>(mirror.positions().begin(), mirror.positions().end()), before);
  EXPECT_EQ(mirror.sequence(), 1u);
  // The genuine delta still applies.
  EXPECT_EQ(mirror.Apply(env, &error), MirrorStatus::kOk) << error;

  v1::Envelope other;
  other.mutable_command()->set_kind(v1::Command::KIND_RESET);
  EXPECT_EQ(mirror.Apply(other, &error), MirrorStatus::kInvalid);
}

// A needle's thread rides on the mesh frames: the mirror keeps the last frame's, a keyframe it
// makes for a late joiner carries it, a frame without one clears it, and a shape out of bounds
// (too many nodes, a non-finite one, a broken segment it does not have) is refused with the
// mirror as it was.
TEST_F(StrokedMirror, KeepsTheSutureThreadAndRefusesOneOutOfBounds) {
  ASSERT_EQ(Apply(1), MirrorStatus::kOk) << error;
  ASSERT_TRUE(encoder.Encode(1.1, stroke.At(1.1), &env, &error));
  v1::MeshDelta delta = env.mesh_delta();
  v1::SutureShape* shape = delta.mutable_suture();
  for (int i = 0; i < 3 * 65; ++i) shape->add_nodes(0.1f * i);
  for (int i = 0; i < 6; ++i) shape->add_punctures(0.5f * i);
  shape->set_ties(1);
  for (const auto& [bad, why] : std::vector<std::pair<std::function<void(v1::SutureShape*)>, std::string>>{
           {[](v1::SutureShape* s) { s->add_nodes(1); }, "x, y, z of 2 to 129 nodes, got 196 values"},
           {[](v1::SutureShape* s) {
              for (int i = 0; i < 3 * 65; ++i) s->add_nodes(0);
            },
            "got 390 values"},
           {[](v1::SutureShape* s) { s->set_nodes(7, std::nanf("")); }, "a node is not finite"},
           {[](v1::SutureShape* s) {
              for (int i = 0; i < 3 * 16; ++i) s->add_punctures(0);
            },
            "at most 16 points, got 54 values"},
           {[](v1::SutureShape* s) { s->set_broken_segment(66); }, "broken_segment 66"}}) {
    v1::MeshDelta wrong = delta;
    bad(wrong.mutable_suture());
    EXPECT_EQ(mirror.Apply(wrong, &error), MirrorStatus::kInvalid) << why;
    EXPECT_NE(error.find("suture: "), std::string::npos) << error;
    EXPECT_NE(error.find(why), std::string::npos) << error;
    EXPECT_EQ(mirror.sequence(), 1u);
  }
  ASSERT_EQ(mirror.Apply(delta, &error), MirrorStatus::kOk) << error;
  EXPECT_EQ(mirror.suture().nodes_size(), 3 * 65);
  v1::MeshKeyframe joiner;
  ASSERT_TRUE(mirror.MakeKeyframe(&joiner, &error)) << error;
  EXPECT_EQ(joiner.suture().nodes_size(), 3 * 65);
  EXPECT_EQ(joiner.suture().punctures_size(), 6);
  EXPECT_EQ(joiner.suture().ties(), 1u);
  // A frame without the thread: none shown, none in the next keyframe.
  ASSERT_TRUE(encoder.Encode(1.2, stroke.At(1.2), &env, &error));
  ASSERT_EQ(mirror.Apply(env, &error), MirrorStatus::kOk) << error;
  EXPECT_EQ(mirror.suture().nodes_size(), 0);
  ASSERT_TRUE(mirror.MakeKeyframe(&joiner, &error)) << error;
  EXPECT_FALSE(joiner.has_suture());
}

TEST(MeshMirror, TopologyChangeArrivesAsKeyframe) {
  const Stroke small(5, 4), large(8, 6);
  MeshEncoder encoder;
  encoder.SetTopology(1, small.tris());
  MeshMirror mirror;
  v1::Envelope env;
  std::string error;
  ASSERT_TRUE(encoder.Encode(0, small.At(0), &env, &error));
  ASSERT_EQ(mirror.Apply(env, &error), MirrorStatus::kOk);
  encoder.SetTopology(2, large.tris());
  ASSERT_TRUE(encoder.Encode(0.1, large.At(0.1), &env, &error)) << error;
  ASSERT_TRUE(env.has_mesh_keyframe());
  ASSERT_EQ(mirror.Apply(env, &error), MirrorStatus::kOk) << error;
  EXPECT_EQ(mirror.topology_version(), 2u);
  EXPECT_EQ(static_cast<size_t>(mirror.num_triangles()), large.tris().size() / 3);
}

// A late joiner gets the server mirror's keyframe, then the agent's deltas apply on top of it.
TEST(MeshMirror, KeyframeFromMirrorResynchronisesALateJoiner) {
  const Stroke stroke;
  MeshEncoder encoder;
  encoder.SetTopology(3, stroke.tris());
  MeshMirror server, late;
  v1::Envelope env;
  std::string error;
  for (int f = 0; f < 60; ++f) {
    const double t = f / 60.0;
    ASSERT_TRUE(encoder.Encode(t, stroke.At(t), &env, &error));
    ASSERT_EQ(server.Apply(env, &error), MirrorStatus::kOk) << error;
    if (f == 30) {
      v1::MeshKeyframe key;
      ASSERT_TRUE(server.MakeKeyframe(&key, &error)) << error;
      ASSERT_EQ(late.Apply(key, &error), MirrorStatus::kOk) << error;
    } else if (f > 30) {
      ASSERT_EQ(late.Apply(env, &error), MirrorStatus::kOk) << error;
    }
  }
  EXPECT_TRUE(std::equal(late.quantized().begin(), late.quantized().end(), server.quantized().begin(),
                         server.quantized().end()));
  EXPECT_EQ(late.sequence(), server.sequence());
  MeshMirror empty;
  v1::MeshKeyframe key;
  EXPECT_FALSE(empty.MakeKeyframe(&key, &error));
}

TEST_F(StrokedMirror, RejectsMalformedKeyframeAndKeepsState) {
  ASSERT_EQ(Apply(0), MirrorStatus::kOk) << error;
  v1::MeshKeyframe bad = env.mesh_keyframe();
  bad.set_num_vertices(bad.num_vertices() + 1);
  bad.set_sequence(99);
  EXPECT_EQ(mirror.Apply(bad, &error), MirrorStatus::kInvalid);
  EXPECT_EQ(mirror.sequence(), 1u);
  EXPECT_STREQ(MirrorStatusName(MirrorStatus::kGap), "gap");
}

}  // namespace
}  // namespace idms
