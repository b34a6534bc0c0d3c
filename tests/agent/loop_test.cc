// The loop's tick, driven without sleeping: it allocates nothing (commands and reset included),
// hands every tick to the sample ring in order, publishes the surface at the stream rate, counts
// overruns, and never lets a non-finite or oversize force reach the device.
#include "idms/agent/loop.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "alloc_counter.h"
#include "idms/agent/device.h"
#include "idms/agent/setup.h"
#include "idms/sim/model_io.h"

namespace idms::test {
namespace {

using agent::Device;
using agent::DeviceReading;
using agent::Loop;
using agent::LoopCommand;
using agent::LoopOptions;
using agent::TickSample;

Model HexModel() {
  const std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";
  Model model;
  LoadError error;
  EXPECT_TRUE(LoadModel(prefix + ".fem", prefix + ".plg", ReadOptions{}, &model, &error)) << error.ToString();
  return model;
}

// Wraps a device and records what the loop writes to it.
class RecordingDevice final : public Device {
 public:
  explicit RecordingDevice(std::unique_ptr<Device> inner) : inner_(std::move(inner)) {}
  void Read(int64_t tick, double t_s, DeviceReading* out) override {
    inner_->Read(tick, t_s, out);
    if (poison_) out->pos[2] = std::nan("");
  }
  void Write(int64_t tick, const double force[3]) override {
    for (int i = 0; i < 3; ++i) all_finite_ = all_finite_ && std::isfinite(force[i]);
    max_force_ = std::max(max_force_, std::sqrt(force[0] * force[0] + force[1] * force[1] + force[2] * force[2]));
    ++writes_;
    inner_->Write(tick, force);
  }
  void Release() override { released_ = true; }
  const char* name() const override { return inner_->name(); }

  std::unique_ptr<Device> inner_;
  bool poison_ = false, all_finite_ = true, released_ = false;
  double max_force_ = 0;
  int64_t writes_ = 0;
};

// A loop over the hex fragment with the scene defaults for `spec`'s script.
struct Fixture {
  explicit Fixture(const std::string& spec, double max_force = 8) {
    std::string script = "palpate", error;
    agent::DeviceScriptName(spec, &script);
    const v1::Scene scene = agent::DefaultScene(script);
    EXPECT_TRUE(agent::SceneToLoop(scene, &step, &tool, &registration, &error)) << error;
    registration.max_force = max_force;
    model = HexModel();
    agent::DeviceContext context;
    context.model = &model;
    context.registration = registration;
    device = std::make_unique<RecordingDevice>(agent::MakeDevice(spec, context, &error));
    EXPECT_TRUE(device->inner_) << error;
    LoopOptions options;
    options.realtime = false;
    loop = std::make_unique<Loop>(model, step, tool, registration, *device, options);
  }

  // n ticks with generous deadlines, draining the rings like the I/O thread would.
  void Run(int n, std::vector<TickSample>* samples = nullptr, int* mesh_frames = nullptr) {
    for (int i = 0; i < n; ++i) {
      const int64_t now = agent::MonotonicNs();
      loop->Tick(now, now + 1000000000);
      loop->samples().consume_all([&](const TickSample& s) {
        if (samples != nullptr) samples->push_back(s);
      });
      int32_t index = -1;
      while (loop->PopMeshSlot(&index)) {
        if (mesh_frames != nullptr) ++*mesh_frames;
        loop->ReleaseMeshSlot(index);
      }
    }
  }

  Model model;
  StepOptions step;
  ToolCommand tool;
  agent::Registration registration;
  std::unique_ptr<RecordingDevice> device;
  std::unique_ptr<Loop> loop;
};

TEST(Loop, TickAllocatesNothing) {
  for (const char* spec : {"scripted:palpate", "human:stroke-fast", "scripted:pluck"}) {
    Fixture f(spec);
    std::vector<TickSample> samples;
    samples.reserve(6000);
    f.Run(10);  // warm-up
    const int64_t before = AllocationCount();
    f.Run(2500, &samples);
    // Commands go through the ring too: tweezers held, released, a reset to rest.
    f.loop->PushCommand(LoopCommand{LoopCommand::kTweezersClose, 0});
    f.Run(200, &samples);
    f.loop->PushCommand(LoopCommand{LoopCommand::kTweezersDevice, 0});
    f.loop->PushCommand(LoopCommand{LoopCommand::kReset, 0});
    f.Run(2500, &samples);
    EXPECT_EQ(AllocationCount() - before, 0) << spec;
    EXPECT_EQ(samples.size(), 5200u) << spec;
    EXPECT_EQ(f.loop->counters().commands.load(), 3u);
  }
}

TEST(Loop, SamplesAreConsecutiveAndSurfaceFollowsStreamRate) {
  Fixture f("scripted:palpate");
  std::vector<TickSample> samples;
  int frames = 0;
  f.Run(3000, &samples, &frames);
  ASSERT_EQ(samples.size(), 3000u);
  for (size_t i = 0; i < samples.size(); ++i) ASSERT_EQ(samples[i].tick, i);
  EXPECT_NEAR(samples.back().time_s, 3.0, 1e-9);
  EXPECT_NEAR(frames, 180, 1);  // 60 Hz for 3 s
  // The palpation reaches the surface: contact and an upward force on the device.
  double max_fz = 0;
  for (const TickSample& s : samples) max_fz = std::max(max_fz, s.force[2]);
  EXPECT_GT(max_fz, 0.1);
  EXPECT_EQ(f.loop->counters().mesh_skipped.load(), 0u);
}

TEST(Loop, SurfacePoolExhaustionSkipsFramesInsteadOfWaiting) {
  Fixture f("scripted:palpate");
  // Nobody releases slots: of the 31 frames due in 0.5 s at 60 Hz (t = 0, 1/60, ...), the pool
  // holds 8; the rest are skipped and counted.
  for (int i = 0; i < 500; ++i) {
    const int64_t now = agent::MonotonicNs();
    f.loop->Tick(now, now + 1000000000);
    f.loop->samples().consume_all([](const TickSample&) {});
  }
  EXPECT_EQ(f.loop->counters().mesh_skipped.load(), 31u - 8u);
  int32_t index = -1;
  ASSERT_TRUE(f.loop->PopMeshSlot(&index));
  EXPECT_GE(f.loop->slot(index).num_tris, 0) << "the first frame carries the triangles";
  EXPECT_EQ(f.loop->slot(index).pos.size(), 3u * static_cast<size_t>(f.model.num_external));
}

TEST(Loop, MissedDeadlineIsAnOverrun) {
  Fixture f("scripted:palpate");
  const int64_t now = agent::MonotonicNs();
  f.loop->Tick(now, now - 1);  // the deadline passed before the work started
  f.loop->Tick(now, now + 1000000000);
  EXPECT_EQ(f.loop->counters().overruns.load(), 1u);
  TickSample s;
  ASSERT_TRUE(f.loop->samples().pop(s));
  EXPECT_TRUE(s.overrun);
}

TEST(Loop, DeviceNeverSeesNonFiniteOrOversizeForce) {
  // A stiff press with a low clamp, then garbage input from the device.
  Fixture f("scripted:palpate", /*max_force=*/0.5);
  f.Run(3000);
  EXPECT_TRUE(f.device->all_finite_);
  EXPECT_LE(f.device->max_force_, 0.5 + 1e-12);
  EXPECT_GT(f.device->max_force_, 0.4) << "the clamp should have been reached";
  f.device->poison_ = true;
  f.Run(500);
  EXPECT_TRUE(f.device->all_finite_);
  EXPECT_LE(f.device->max_force_, 0.5 + 1e-12);
  EXPECT_EQ(f.device->writes_, 3500);
}

TEST(Loop, SanitizeDeviceForceZeroesNaNAndClamps) {
  double nan_force[3] = {1, std::nan(""), 0};
  EXPECT_EQ(agent::SanitizeDeviceForce(nan_force, 8), 1);
  EXPECT_EQ(nan_force[0], 0);
  EXPECT_EQ(nan_force[1], 0);
  double inf_force[3] = {0, 0, -INFINITY};
  EXPECT_EQ(agent::SanitizeDeviceForce(inf_force, 8), 1);
  EXPECT_EQ(inf_force[2], 0);
  double big[3] = {30, 40, 0};
  EXPECT_EQ(agent::SanitizeDeviceForce(big, 5), 0);
  EXPECT_DOUBLE_EQ(big[0], 3);
  EXPECT_DOUBLE_EQ(big[1], 4);
}

TEST(Loop, RunStopsAfterMaxTicksReleasesDeviceAndPublishesFinalFrame) {
  Fixture f("scripted:palpate");
  LoopOptions options;
  options.realtime = false;
  options.max_ticks = 50;
  Loop loop(f.model, f.step, f.tool, f.registration, *f.device, options);
  loop.Run();
  EXPECT_TRUE(loop.finished());
  EXPECT_TRUE(f.device->released_);
  EXPECT_EQ(loop.counters().ticks.load(), 50u);
  bool final_frame = false;
  int32_t index = -1;
  while (loop.PopMeshSlot(&index)) final_frame = loop.slot(index).final_frame;
  EXPECT_TRUE(final_frame);
  EXPECT_EQ(loop.period_histogram().count(), 49u);
}

}  // namespace
}  // namespace idms::test
