// The passivity controller in the agent's loop (device-agent/src/loop.cc, issue 31): a simulated hand
// pressing a stiff MIO into the hex fragment, tick by tick; what the samples carry, the counters, and
// that the windowed port energy stays above -eps and the force finite and bounded.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>

#include "idms/agent/device.h"
#include "idms/agent/loop.h"
#include "idms/agent/setup.h"
#include "idms/sim/model_io.h"

namespace idms {
namespace {

struct PassivityRun {
  double min_window = 0, max_force = 0, last_energy = 0;
  uint64_t acted = 0, samples = 0;
  bool finite = true;
};

PassivityRun PressStiff(double stiffness, bool passivity) {
  const std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";
  Model model;
  LoadError load_error;
  EXPECT_TRUE(LoadModel(prefix + ".fem", prefix + ".plg", ReadOptions{}, &model, &load_error));
  v1::Scene scene = agent::DefaultScene("palpate");
  scene.set_model_file(prefix);
  scene.mutable_tools(0)->set_stiffness(stiffness);
  std::string error;
  EXPECT_TRUE(agent::ApplyPassivitySpec(passivity ? "on" : "off", "human:palpate", &scene, &error)) << error;
  StepOptions step;
  ToolCommand tool;
  agent::Registration registration;
  EXPECT_TRUE(agent::SceneToLoop(scene, &step, &tool, &registration, &error)) << error;
  agent::DeviceContext context;
  context.model = &model;
  context.registration = registration;
  std::unique_ptr<agent::Device> device = agent::MakeDevice("human:palpate", context, &error);
  EXPECT_TRUE(device) << error;
  agent::LoopOptions options;
  options.realtime = false;
  options.passivity = agent::PassivityFromScene(scene, registration, step.dt_s);
  agent::Loop loop(model, step, tool, registration, *device, options);
  PassivityRun run;
  for (int n = 0; n < 4000; ++n) {
    loop.Tick(0, 1000000);
    agent::TickSample s;
    while (loop.samples().pop(s)) {
      ++run.samples;
      run.finite = run.finite && std::isfinite(s.force[0] + s.force[1] + s.force[2]) &&
                   std::isfinite(s.port_energy + s.port_energy_window + s.passivity_damping);
      run.min_window = std::min(run.min_window, s.port_energy_window);
      run.max_force = std::max(run.max_force, std::hypot(s.force[0], s.force[1], s.force[2]));
      run.last_energy = s.port_energy;
    }
  }
  run.acted = loop.counters().passivity_ticks.load();
  return run;
}

TEST(LoopPassivity, OffCostsNothingAndReportsZeros) {
  const PassivityRun off = PressStiff(400, false);
  EXPECT_EQ(off.samples, 4000u);
  EXPECT_EQ(off.acted, 0u);
  EXPECT_EQ(off.last_energy, 0);
  EXPECT_EQ(off.min_window, 0);
}

// Ten times the thesis's MIO: the samples carry the port's energy (the hand pressed: it put energy
// in), it never goes below -eps in the window (eps: a tick's misprediction at the force limit,
// 8 force units over an encoder-free 1e-3 step), and the force stays finite and under the clamp.
TEST(LoopPassivity, AStiffPressKeepsThePortPassiveAndTheForceFinite) {
  const PassivityRun on = PressStiff(4000, true);
  EXPECT_EQ(on.samples, 4000u);
  EXPECT_TRUE(on.finite);
  EXPECT_GT(on.last_energy, 0);
  EXPECT_GE(on.min_window, -8 * 1e-3);
  EXPECT_LE(on.max_force, 8 + 1e-9);
}

}  // namespace
}  // namespace idms
