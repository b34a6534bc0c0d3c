// A loop over the hex fragment with the palpation scene, not real-time, driven tick by tick
// (the agent tests that call Loop::Tick themselves).
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "idms/agent/device.h"
#include "idms/agent/loop.h"
#include "idms/agent/setup.h"
#include "idms/sim/model_io.h"

namespace idms::test {

inline std::unique_ptr<agent::Loop> HexLoop(Model* model, std::unique_ptr<agent::Device>* device) {
  const std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";
  LoadError load_error;
  EXPECT_TRUE(LoadModel(prefix + ".fem", prefix + ".plg", ReadOptions{}, model, &load_error)) << load_error.ToString();
  StepOptions step;
  ToolCommand tool;
  agent::Registration registration;
  std::string error;
  EXPECT_TRUE(agent::SceneToLoop(agent::DefaultScene("palpate"), &step, &tool, &registration, &error)) << error;
  agent::DeviceContext context;
  context.model = model;
  context.registration = registration;
  *device = agent::MakeDevice("scripted:palpate", context, &error);
  EXPECT_TRUE(*device) << error;
  agent::LoopOptions options;
  options.realtime = false;
  return std::make_unique<agent::Loop>(*model, step, tool, registration, **device, options);
}

}  // namespace idms::test
