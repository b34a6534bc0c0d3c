// Scene -> loop (device-agent/src/setup.cc): the passivity controller's scene options and
// --passivity (issue 31): who gets it by default, the items, the round trip through a scene's text,
// validation, and the conversion into the model's units; the suture's two tools (issue 32).
#include "idms/agent/setup.h"

#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>

#include <string>

#include "idms/protocol/scene.h"
#include "idms/sim/interaction_script.h"

namespace idms::agent {
namespace {

v1::Scene Scene(v1::Preset preset = v1::PRESET_DEFAULT) {
  v1::Scene scene = DefaultScene("palpate", preset);
  scene.set_model_file("models/hex_4x5_home");
  return scene;
}

TEST(Setup, PassivityIsOnForUdpDevicesOnlyAndOffInTheThesisPreset) {
  std::string error;
  v1::Scene udp = Scene(), human = Scene(), thesis = Scene(v1::PRESET_THESIS);
  ASSERT_TRUE(ApplyPassivitySpec("", "udp:9000", &udp, &error)) << error;
  ASSERT_TRUE(ApplyPassivitySpec("", "human:palpate", &human, &error)) << error;
  ASSERT_TRUE(ApplyPassivitySpec("", "udp:9000", &thesis, &error)) << error;
  EXPECT_TRUE(udp.device().passivity().enabled());
  EXPECT_FALSE(human.device().passivity().enabled());
  EXPECT_FALSE(thesis.device().passivity().enabled());
  // Written into the scene (the recording says what ran), with its defaults.
  EXPECT_TRUE(human.device().passivity().has_enabled());
  EXPECT_EQ(udp.device().passivity().window_s(), 0.1);
  EXPECT_EQ(udp.device().passivity().max_damping(), 0.5);
}

TEST(Setup, PassivitySpecItemsOverrideTheScene) {
  std::string error;
  v1::Scene scene = Scene();
  scene.mutable_device()->mutable_passivity()->set_enabled(false);
  ASSERT_TRUE(ApplyPassivitySpec("on,window=0.25,max_damping=2,quantum=1e-4", "udp:1", &scene, &error)) << error;
  const v1::Passivity& p = scene.device().passivity();
  EXPECT_TRUE(p.enabled());
  EXPECT_EQ(p.window_s(), 0.25);
  EXPECT_EQ(p.max_damping(), 2);
  EXPECT_EQ(p.encoder_quantum(), 1e-4);
  v1::Scene off = Scene();
  ASSERT_TRUE(ApplyPassivitySpec("off", "udp:1", &off, &error)) << error;
  EXPECT_FALSE(off.device().passivity().enabled());
  // A scene's own choice stands when the command line says nothing.
  v1::Scene own = Scene();
  own.mutable_device()->mutable_passivity()->set_enabled(true);
  ASSERT_TRUE(ApplyPassivitySpec("", "human:palpate", &own, &error)) << error;
  EXPECT_TRUE(own.device().passivity().enabled());
}

TEST(Setup, BadPassivityItemsAreRefusedNamingThem) {
  for (const char* spec : {"maybe", "on,window", "on,window=x", "on,speed=3", "on,window=nan", "on,max_damping=0",
                           "on,window=-1", "on,quantum=-1e-3"}) {
    v1::Scene scene = Scene();
    std::string error;
    EXPECT_FALSE(ApplyPassivitySpec(spec, "udp:1", &scene, &error)) << spec;
    EXPECT_NE(error.find("--passivity"), std::string::npos) << spec << ": " << error;
  }
  v1::Scene scene = Scene();
  std::string error;
  ASSERT_FALSE(ApplyPassivitySpec("on,max_damping=0", "udp:1", &scene, &error));
  EXPECT_NE(error.find("max_damping"), std::string::npos) << error;
}

TEST(Setup, PassivityOptionsRoundTripThroughASceneFile) {
  v1::Scene scene = Scene();
  std::string error;
  ASSERT_TRUE(ApplyPassivitySpec("on,window=0.3,max_damping=1.5,quantum=2e-4", "udp:1", &scene, &error)) << error;
  std::string text;
  ASSERT_TRUE(google::protobuf::TextFormat::PrintToString(scene, &text));
  EXPECT_NE(text.find("passivity"), std::string::npos) << text;
  v1::Scene back;
  ASSERT_TRUE(LoadSceneText(text, "round.scene", &back, &error)) << error;
  const v1::Passivity& p = back.device().passivity();
  EXPECT_TRUE(p.enabled());
  EXPECT_EQ(p.window_s(), 0.3);
  EXPECT_EQ(p.max_damping(), 1.5);
  EXPECT_EQ(p.encoder_quantum(), 2e-4);
  // A bad value in a file names the field.
  const std::string bad =
      "model_file: \"m\"\ntools { kind: KIND_SPHERE radius: 1.5 stiffness: 400 }\ndevice { passivity { window_s: -2 } "
      "}\n";
  ASSERT_FALSE(LoadSceneText(bad, "bad.scene", &back, &error));
  EXPECT_NE(error.find("window_s"), std::string::npos) << error;
}

TEST(Setup, PassivityOptionsAreConvertedIntoModelUnits) {
  v1::Scene scene = Scene();
  std::string error;
  ASSERT_TRUE(ApplyPassivitySpec("on,max_damping=2,quantum=1e-3", "udp:1", &scene, &error)) << error;
  Registration r;
  r.scale = 4;        // model units per device unit
  r.force_scale = 2;  // device force units per model force unit
  const PassivityOptions o = PassivityFromScene(scene, r, 1e-3);
  EXPECT_TRUE(o.enabled);
  EXPECT_EQ(o.dt_s, 1e-3);
  EXPECT_DOUBLE_EQ(o.max_damping, 2.0 / (2 * 4));  // (F_dev / 2) / (4 L_dev / s)
  EXPECT_DOUBLE_EQ(o.quantum, 4e-3);
}

// The suture's scene (models/suture.scene) and scripted:suture's built-in one hold the needle the
// script is made for (SutureScriptNeedle) first and its scalpel second, with the blade through the
// slab; a scene of more tools than a device can hold is refused naming the count.
TEST(Setup, TheSutureScenesHoldTheScriptsNeedleAndScalpel) {
  v1::Scene file;
  std::string error;
  ASSERT_TRUE(LoadScene(std::string(IDMS_SOURCE_DIR) + "/models/suture.scene", &file, &error)) << error;
  ASSERT_TRUE(ValidateScene(file, &error)) << error;
  const ToolCommand want = SutureScriptNeedle();
  for (const v1::Scene& scene : {file, DefaultScene("suture")}) {
    std::array<ToolCommand, kMaxTools> tools{};
    int32_t n = 0;
    ASSERT_TRUE(SceneTools(scene, &tools, &n, &error)) << error;
    ASSERT_EQ(n, 2);
    const ToolCommand& needle = tools[0];
    EXPECT_EQ(needle.kind, ToolKind::kNeedle);
    EXPECT_EQ(needle.radius, want.radius);
    EXPECT_EQ(needle.needle.length, want.needle.length);
    EXPECT_EQ(needle.needle.puncture_force, want.needle.puncture_force);
    EXPECT_EQ(needle.needle.grip, want.needle.grip);
    EXPECT_EQ(needle.needle.capture_radius, want.needle.capture_radius);
    EXPECT_EQ(needle.needle.lateral_stiffness, want.needle.lateral_stiffness);
    EXPECT_EQ(needle.needle.axial_stiffness, want.needle.axial_stiffness);
    EXPECT_EQ(needle.suture.length, want.suture.length);
    EXPECT_EQ(needle.suture.segments, want.suture.segments);
    EXPECT_EQ(needle.suture.mass, want.suture.mass);
    EXPECT_EQ(needle.suture.tie_force, want.suture.tie_force);
    EXPECT_EQ(needle.suture.hold_stiffness, want.suture.hold_stiffness);
    EXPECT_EQ(tools[1].kind, ToolKind::kScalpel);
    EXPECT_EQ(tools[1].blade[2], -kSutureBlade);
    EXPECT_EQ(scene.tools(0).local_radius(), kSutureLocalRadius);
  }
  v1::Scene five = file;
  for (int i = 0; i < 3; ++i) *five.add_tools() = file.tools(1);
  StepOptions step;
  ToolCommand first;
  Registration reg;
  EXPECT_FALSE(SceneToLoop(five, &step, &first, &reg, &error));
  EXPECT_NE(error.find("holds one of 1 to 4 tools, got 5"), std::string::npos) << error;
}

}  // namespace
}  // namespace idms::agent
