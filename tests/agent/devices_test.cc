// Device specs and the simulated hand: a closed loop that stays stable in contact.
#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <filesystem>

#include "idms/agent/device.h"
#include "idms/agent/loop.h"
#include "idms/agent/setup.h"
#include "idms/protocol/recording.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/model_io.h"
#include "warning_guard.h"

namespace idms::test {
namespace {

Model Hex() {
  const std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";
  Model model;
  LoadError error;
  EXPECT_TRUE(LoadModel(prefix + ".fem", prefix + ".plg", ReadOptions{}, &model, &error));
  return model;
}

TEST(Devices, BadSpecsAreExplained) {
  const Model model = Hex();
  agent::DeviceContext context;
  context.model = &model;
  std::string error;
  EXPECT_FALSE(agent::MakeDevice("scripted:poke", context, &error));
  EXPECT_NE(error.find("expected palpate, stroke-slow, stroke-fast, pluck, stroke-gentle, scan, pierce, stitch, suture "
                       "or (scripted) drag"),
            std::string::npos)
      << error;
  EXPECT_FALSE(agent::MakeDevice("human:palpate,mass=-1", context, &error));
  EXPECT_NE(error.find("mass > 0"), std::string::npos) << error;
  EXPECT_FALSE(agent::MakeDevice("udp:99999", context, &error));
  EXPECT_NE(error.find("1..65535"), std::string::npos) << error;
  EXPECT_FALSE(agent::MakeDevice("replay:/nonexistent/session.mcap", context, &error));
  EXPECT_NE(error.find("/nonexistent/session.mcap"), std::string::npos) << error;
  EXPECT_FALSE(agent::MakeDevice("phantom", context, &error));
  EXPECT_NE(error.find("expected scripted:SCRIPT"), std::string::npos) << error;
}

TEST(Devices, AHandItsOwnIntegratorCannotRunIsRefusedWithTheLimit) {
  const Model model = Hex();
  agent::DeviceContext context;
  context.model = &model;
  context.dt_s = 0.001;
  std::string error;
  // sqrt(1000 / 0.0001) * 0.001 = 3.16, above symplectic Euler's 2 for an undamped hand.
  EXPECT_FALSE(agent::MakeDevice("human:palpate,mass=0.0001,k=1000,zeta=0", context, &error));
  EXPECT_NE(error.find("sqrt(k/mass)*dt = 3.16"), std::string::npos) << error;
  EXPECT_NE(error.find("stable only below 2 "), std::string::npos) << error;
  // Damping lowers the limit: 2 (sqrt(zeta^2 + 1) - zeta) = 1.04 at zeta = 0.7.
  EXPECT_FALSE(agent::MakeDevice("human:palpate,mass=0.001,k=1200,zeta=0.7", context, &error));
  EXPECT_NE(error.find("below 1.04"), std::string::npos) << error;
  EXPECT_TRUE(agent::MakeDevice("human:palpate,mass=0.001,k=1000,zeta=0.7", context, &error)) << error;
  EXPECT_TRUE(agent::MakeDevice("human:palpate", context, &error)) << error;
}

// The position device `spec` reports at t_s, mapped back into the model frame by the registration.
std::array<double, 3> ModelPositionAt(const agent::DeviceContext& context, const std::string& spec, double t_s) {
  std::string error;
  auto device = agent::MakeDevice(spec, context, &error);
  EXPECT_TRUE(device) << error;
  std::array<double, 3> p = {NAN, NAN, NAN};
  if (!device) return p;
  agent::DeviceReading r;
  device->Read(0, t_s, &r);
  context.registration.DeviceToModel(r.pos, p.data());
  return p;
}

TEST(Devices, ScriptedDeviceUndoesTheRegistration) {
  // The scripted trajectory lives in the model frame; the device reports it in device
  // coordinates, so the loop's registration maps it back onto the surface.
  const Model model = Hex();
  agent::DeviceContext context;
  context.model = &model;
  std::string error;
  ASSERT_TRUE(agent::ParseRotation("rpy:10,20,30", context.registration.rot, &error));
  context.registration.scale = 2;
  context.registration.offset[2] = 5;
  const std::array<double, 3> p_model = ModelPositionAt(context, "scripted:stroke-slow", 4.0);
  const ScriptSample s = SampleScript(Script::kStrokeSlow, MakeScriptGeometry(model, 1.5), 4.0);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(p_model[i], s.pos[i], 1e-12);
}

// scripted:scan (issue 34) plays the scan: at 0.9 s it holds the first press, at the first grid
// point, below the height where the sphere first touches the surface there.
TEST(Devices, TheScanDevicePressesAtTheGridPoints) {
  const Model model = Hex();
  agent::DeviceContext context;
  context.model = &model;
  const std::array<double, 3> p = ModelPositionAt(context, "scripted:scan", 0.9);
  const ScriptGeometry g = MakeScriptGeometry(model, 1.5);
  const std::array<double, 2> first = ScanPoint(g, 0);
  EXPECT_NEAR(p[0], first[0], 1e-12);
  EXPECT_NEAR(p[1], first[1], 1e-12);
  EXPECT_LT(p[2], g.scan_top_z[0] + 1.5);
  EXPECT_GT(p[2], g.scan_top_z[0] + 1.5 - 0.1) << "a shallow press";
  EXPECT_GT(ScriptDuration(Script::kScan), kScanGrid * kScanGrid * 0.9) << "every grid point visited";
}

// A denser grid (scripted:scan,grid=N): its second press is at its own second point, and the
// scan lasts its N x N presses; a grid out of 2..15, or on another script, is refused.
TEST(Devices, TheScanTakesItsGrid) {
  const Model model = Hex();
  agent::DeviceContext context;
  context.model = &model;
  const ScriptGeometry g9 = MakeScriptGeometry(model, 1.5, 9), g7 = MakeScriptGeometry(model, 1.5);
  const std::array<double, 3> p = ModelPositionAt(context, "scripted:scan,grid=9", 1.9);  // the second press
  EXPECT_NEAR(p[0], ScanPoint(g9, 1)[0], 1e-12);
  EXPECT_NEAR(p[1], ScanPoint(g9, 1)[1], 1e-12);
  EXPECT_GT(std::abs(ScanPoint(g9, 1)[0] - ScanPoint(g7, 1)[0]), 0.01);
  EXPECT_GT(ScriptDuration(Script::kScan, g9), 81 * 0.9);
  EXPECT_EQ(ScriptDuration(Script::kScan, g7), ScriptDuration(Script::kScan));
  std::string error;
  for (const char* bad :
       {"scripted:scan,grid=16", "scripted:scan,grid=1", "scripted:scan,grid=7.5", "scripted:palpate,grid=9"}) {
    EXPECT_FALSE(agent::MakeDevice(bad, context, &error)) << bad;
    EXPECT_NE(error.find("option 'grid' is unknown or out of range here"), std::string::npos) << error;
  }
  EXPECT_NE(error.find("(scripted devices take no options)"), std::string::npos) << error;
  EXPECT_TRUE(agent::MakeDevice("human:scan,grid=5,k=80", context, &error)) << error;
}

// One contact law by default, the thesis's pseudo-code's (as idms-sim run); the prose's by name.
TEST(Devices, TheSceneChoosesTheContactLawAndTheThesisLawIsTheDefault) {
  StepOptions step;
  ToolCommand tool;
  agent::Registration reg;
  std::string error;
  v1::Scene scene = agent::DefaultScene("palpate");
  ASSERT_TRUE(agent::SceneToLoop(scene, &step, &tool, &reg, &error)) << error;
  EXPECT_EQ(tool.law, ContactLaw::kThesis);
  EXPECT_EQ(ToolCommand{}.law, ContactLaw::kThesis) << "idms-sim's default";
  scene.mutable_tools(0)->set_force_law(v1::FORCE_LAW_LINEAR);
  ASSERT_TRUE(agent::SceneToLoop(scene, &step, &tool, &reg, &error)) << error;
  EXPECT_EQ(tool.law, ContactLaw::kLinear);
}

// The built-in scene steps as every entry point does (symplectic Euler, r_l = 2 r); the thesis's
// step (explicit Euler, r_l = 1.5 r) by name, as idms-agent --preset thesis asks for it.
TEST(Devices, TheBuiltInSceneTakesTheDefaultStepAndTheThesisStepByName) {
  StepOptions step;
  ToolCommand tool;
  agent::Registration reg;
  std::string error;
  ASSERT_TRUE(agent::SceneToLoop(agent::DefaultScene("palpate"), &step, &tool, &reg, &error)) << error;
  EXPECT_EQ(step.integrator, Integrator::kSymplecticEuler);
  EXPECT_EQ(step.local_radius, 3.0);
  EXPECT_EQ(step.integrator, StepOptions{}.integrator) << "the sim's own default";
  ASSERT_TRUE(agent::SceneToLoop(agent::DefaultScene("pluck", v1::PRESET_THESIS), &step, &tool, &reg, &error)) << error;
  EXPECT_EQ(step.integrator, Integrator::kExplicitEuler);
  EXPECT_EQ(step.local_radius, 2.25);
  EXPECT_EQ(tool.kind, ToolKind::kTweezers);
}

// Friction from the scene or --friction reaches the tool; bad coefficients are refused by name;
// the scripted stroke's samples carry the tangential force and the stick/slip state.
TEST(Devices, FrictionReachesTheToolAndTheSamples) {
  StepOptions step;
  ToolCommand tool;
  agent::Registration reg;
  std::string error;
  v1::Scene scene = agent::DefaultScene("stroke-slow");
  ASSERT_TRUE(agent::SceneToLoop(scene, &step, &tool, &reg, &error)) << error;
  EXPECT_EQ(tool.mu_s, 0.0) << "the built-in scene is frictionless";
  scene.set_model("hex_4x5_home");  // as the agent's command line names it before --friction
  ASSERT_TRUE(agent::ApplyFrictionSpec("mu_s=0.6,mu_d=0.4", &scene, &error)) << error;
  EXPECT_EQ(scene.tools(0).static_friction(), 0.6);
  EXPECT_EQ(scene.tools(0).friction_stiffness(), 400);
  ASSERT_TRUE(agent::SceneToLoop(scene, &step, &tool, &reg, &error)) << error;
  EXPECT_EQ(tool.mu_s, 0.6);
  EXPECT_EQ(tool.mu_d, 0.4);
  EXPECT_DOUBLE_EQ(tool.friction_damping, 0.4);
  v1::Scene bad = scene;
  EXPECT_FALSE(agent::ApplyFrictionSpec("mu_s=0.3,mu_d=0.5", &bad, &error));
  EXPECT_EQ(error, "--friction: mu_d must be <= mu_s (0.3), got 0.5");
  EXPECT_FALSE(agent::ApplyFrictionSpec("mu_s=nan", &bad, &error));
  EXPECT_NE(error.find("bad item 'mu_s=nan'"), std::string::npos) << error;
  EXPECT_FALSE(agent::ApplyFrictionSpec("mu_s=-1", &bad, &error));
  EXPECT_EQ(error, "--friction: mu_s must be a finite number >= 0, got -1");
  EXPECT_FALSE(agent::ApplyFrictionSpec("mu_s=0.6,mu_s=0.5", &bad, &error));
  EXPECT_NE(error.find("bad item 'mu_s=0.5'"), std::string::npos) << error;
  EXPECT_FALSE(agent::ApplyFrictionSpec("mu_d=0.4", &bad, &error));
  EXPECT_EQ(error, "--friction: give mu_s=S (the static coefficient, >= 0)");
  EXPECT_EQ(bad.tools(0).static_friction(), 0.6) << "a refused spec leaves the scene as it was";
  EXPECT_EQ(bad.tools(0).kinetic_friction(), 0.4);

  const Model model = Hex();
  agent::DeviceContext context;
  context.model = &model;
  context.registration = reg;
  auto device = agent::MakeDevice("scripted:stroke-slow", context, &error);
  ASSERT_TRUE(device) << error;
  agent::LoopOptions options;
  options.realtime = false;
  agent::Loop loop(model, step, tool, reg, *device, options);
  int64_t stick = 0, slip = 0;
  double max_ft = 0;
  for (int i = 0; i < 5800; ++i) {
    const int64_t now = agent::MonotonicNs();
    loop.Tick(now, now + 1000000000);
    agent::TickSample s;
    while (loop.samples().pop(s)) {
      stick += s.friction == FrictionState::kStick;
      slip += s.friction == FrictionState::kSlip;
      max_ft = std::max(max_ft, std::hypot(s.friction_force[0], s.friction_force[1], s.friction_force[2]));
      if (s.friction != FrictionState::kNone) {
        ASSERT_LE(std::hypot(s.friction_force[0], s.friction_force[1], s.friction_force[2]),
                  0.6 * s.normal_force + 1e-9);
      }
    }
    int32_t index;
    while (loop.PopMeshSlot(&index)) loop.ReleaseMeshSlot(index);
  }
  EXPECT_GT(stick, 100);
  EXPECT_GT(slip, 100);
  EXPECT_GT(max_ft, 0.1);

  // Closed loop: a simulated hand strokes with friction; the stick holds the hand back and nothing
  // grows (no warning, the force stays under the thesis stroke's scale).
  auto hand = agent::MakeDevice("human:stroke-slow", context, &error);
  ASSERT_TRUE(hand) << error;
  agent::Loop human_loop(model, step, tool, reg, *hand, options);
  double max_force = 0;
  int64_t human_stick = 0, warnings = 0;
  for (int i = 0; i < 5800; ++i) {
    const int64_t now = agent::MonotonicNs();
    human_loop.Tick(now, now + 1000000000);
    agent::TickSample s;
    while (human_loop.samples().pop(s)) {
      max_force = std::max(max_force, std::hypot(s.force[0], s.force[1], s.force[2]));
      human_stick += s.friction == FrictionState::kStick;
      warnings += s.warnings;
    }
    int32_t index;
    while (human_loop.PopMeshSlot(&index)) human_loop.ReleaseMeshSlot(index);
  }
  EXPECT_EQ(warnings, 0);
  EXPECT_GT(human_stick, 100);
  EXPECT_LT(max_force, 5.0);
}

// scripted:drag holds a finger with friction under a sideways push at half of mu_s f_n: over the
// script's last 10 s the device does not move (and without friction the device is refused).
TEST(Devices, DragHoldsBelowTheStaticLimit) {
  const Model model = Hex();
  v1::Scene scene = agent::DefaultScene("drag");
  scene.set_model("hex_4x5_home");
  std::string error;
  ASSERT_TRUE(agent::ApplyFrictionSpec("mu_s=0.6,mu_d=0.4", &scene, &error)) << error;
  StepOptions step;
  ToolCommand tool;
  agent::Registration reg;
  ASSERT_TRUE(agent::SceneToLoop(scene, &step, &tool, &reg, &error)) << error;
  agent::DeviceContext context;
  context.model = &model;
  context.registration = reg;
  EXPECT_FALSE(agent::MakeDevice("scripted:drag", context, &error));
  EXPECT_NE(error.find("give the tool friction"), std::string::npos) << error;
  context.mu_s = tool.mu_s;
  EXPECT_FALSE(agent::MakeDevice("scripted:drag,fraction=-1", context, &error));
  auto device = agent::MakeDevice("scripted:drag,fraction=0.5", context, &error);
  ASSERT_TRUE(device) << error;
  agent::LoopOptions options;
  options.realtime = false;
  agent::Loop loop(model, step, tool, reg, *device, options);
  double x_at_5s = 0, x_last = 0;
  int64_t slip = 0, stick = 0;
  for (int i = 0; i < 15000; ++i) {
    const int64_t now = agent::MonotonicNs();
    loop.Tick(now, now + 1000000000);
    agent::TickSample s;
    while (loop.samples().pop(s)) {
      if (s.tick == 4999) x_at_5s = s.tool_pos[0];
      x_last = s.tool_pos[0];
      slip += s.friction == FrictionState::kSlip;
      stick += s.friction == FrictionState::kStick;
    }
    int32_t index;
    while (loop.PopMeshSlot(&index)) loop.ReleaseMeshSlot(index);
  }
  EXPECT_EQ(slip, 0);
  EXPECT_GT(stick, 13000);
  EXPECT_LT(std::fabs(x_last - x_at_5s), 1e-6);
  EXPECT_GT(x_last, MakeScriptGeometry(model, 1.5).center[0] + 1e-3) << "the push did not move the hand at all";
}

TEST(Devices, HumanHandIsStableInContact) {
  // Pressing with a soft hand: the tissue pushes it back (it lags the script), and nothing grows.
  const Model model = Hex();
  const v1::Scene scene = agent::DefaultScene("palpate");
  StepOptions step;
  ToolCommand tool;
  agent::Registration reg;
  std::string error;
  ASSERT_TRUE(agent::SceneToLoop(scene, &step, &tool, &reg, &error));
  agent::DeviceContext context;
  context.model = &model;
  context.registration = reg;
  auto device = agent::MakeDevice("human:palpate", context, &error);
  ASSERT_TRUE(device) << error;
  agent::LoopOptions options;
  options.realtime = false;
  agent::Loop loop(model, step, tool, reg, *device, options);
  WarningGuard warnings(loop.state());  // the loop is never reset here: the State stays put
  const ScriptGeometry g = MakeScriptGeometry(model, 1.5);
  double max_force = 0, max_lag = 0, lag_at_press = 0, fz_at_press = 0;
  for (int i = 0; i < 5500; ++i) {
    const int64_t now = agent::MonotonicNs();
    loop.Tick(now, now + 1000000000);
    agent::TickSample s;
    while (loop.samples().pop(s)) {
      max_force = std::max(max_force, std::hypot(s.force[0], s.force[1], s.force[2]));
      const ScriptSample target = SampleScript(Script::kPalpate, g, s.time_s);
      const double lag = s.tool_pos[2] - target.pos[2];
      max_lag = std::max(max_lag, std::abs(lag));
      if (s.tick == 2800) lag_at_press = lag, fz_at_press = s.force[2];
    }
    int32_t index;
    while (loop.PopMeshSlot(&index)) loop.ReleaseMeshSlot(index);
  }
  // Held at depth (the script holds from 2.5 to 3 s; the hand, w = 35 rad/s, zeta = 0.7, settles
  // in ~0.2 s), the hand's spring balances the device force: k * lag = f_z, k = 60 by default.
  EXPECT_GT(fz_at_press, 0.5);
  EXPECT_NEAR(lag_at_press, fz_at_press / 60, 0.01 * lag_at_press) << "the tissue pushes the hand above its target";
  // Giving way, the hand presses less deep than the rigid script, whose peak is 1.667 N.
  EXPECT_LT(max_force, 1.667);
  EXPECT_LT(max_lag, 2 * lag_at_press);
}

// Writes a recording with `n` ticks of palpation at 1 kHz on /device, 20 samples per frame.
std::string WriteRecording(const Model& model, int n) {
  const std::string path =
      (std::filesystem::temp_directory_path() / ("idms-replay-test-" + std::to_string(::getpid()) + ".mcap")).string();
  RecordingWriter writer;
  std::string error;
  EXPECT_TRUE(writer.Open(path, RecordingWriterOptions{}, &error)) << error;
  const ScriptGeometry g = MakeScriptGeometry(model, 1.5);
  v1::Envelope envelope;
  v1::DeviceSamples* batch = envelope.mutable_device_samples();
  for (int i = 0; i < n; ++i) {
    const ScriptSample s = SampleScript(Script::kPalpate, g, 1e-3 * (i + 1000));
    v1::DeviceSample* d = batch->add_samples();
    d->set_tick(static_cast<uint64_t>(i));
    d->set_time_s(1e-3 * (i + 1));
    d->mutable_tool_pos()->set_x(s.pos[0]);
    d->mutable_tool_pos()->set_y(s.pos[1]);
    d->mutable_tool_pos()->set_z(s.pos[2]);
    if (batch->samples_size() == 20 || i + 1 == n) {
      EXPECT_TRUE(writer.Write(envelope, 1000000ull * static_cast<uint64_t>(i), 0, &error)) << error;
      batch->Clear();
    }
  }
  EXPECT_TRUE(writer.Close(&error)) << error;
  return path;
}

TEST(Devices, ReplayPlaysTheRecordedTrajectoryThenStopsTheLoop) {
  const Model model = Hex();
  const std::string path = WriteRecording(model, 300);
  agent::DeviceContext context;
  context.model = &model;
  std::string error;
  auto device = agent::MakeDevice("replay:" + path, context, &error);
  ASSERT_TRUE(device) << error;
  // Recorded sample i (time (i + 1) ms) is played at loop time i ms: the recording starts at 0.
  const ScriptGeometry g = MakeScriptGeometry(model, 1.5);
  agent::DeviceReading r;
  device->Read(0, 0.1234, &r);
  const ScriptSample expected = SampleScript(Script::kPalpate, g, 1e-3 * (123 + 1000));
  for (int i = 0; i < 3; ++i) EXPECT_DOUBLE_EQ(r.pos[i], expected.pos[i]);
  EXPECT_FALSE(device->finished());
  // The loop ends when the recording does.
  auto fresh = agent::MakeDevice("replay:" + path, context, &error);
  const v1::Scene scene = agent::DefaultScene("palpate");
  StepOptions step;
  ToolCommand tool;
  agent::Registration reg;
  ASSERT_TRUE(agent::SceneToLoop(scene, &step, &tool, &reg, &error));
  agent::LoopOptions options;
  options.realtime = false;
  agent::Loop loop(model, step, tool, reg, *fresh, options);
  loop.Run();
  EXPECT_TRUE(fresh->finished());
  EXPECT_NEAR(static_cast<double>(loop.counters().ticks.load()), 300, 1);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace idms::test
