// Scene files: the shipped scenes load; syntax errors and bad values are reported with
// FILE:LINE:COL and the field; defaults fill what a scene leaves out.
#include "idms/protocol/scene.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <utility>

#include "idms/sim/interaction_script.h"

namespace idms {
namespace {

constexpr const char* kMinimal = R"(model: "hex_4x5_home"
tools {
  kind: KIND_SPHERE
  radius: 1.5
  stiffness: 400
}
)";

std::string LoadError(const std::string& text) {
  v1::Scene scene;
  scene.set_model("untouched");
  std::string error;
  EXPECT_FALSE(LoadSceneText(text, "test.scene", &scene, &error));
  EXPECT_EQ(scene.model(), "untouched") << "scene changed on failure";
  return error;
}

TEST(Scene, ShippedScenesLoad) {
  const std::filesystem::path dir = std::filesystem::path(IDMS_SOURCE_DIR) / "models";
  for (const char* name : {"palpate", "stroke-slow", "stroke-fast", "pluck"}) {
    v1::Scene scene;
    std::string error;
    ASSERT_TRUE(LoadScene((dir / (std::string(name) + ".scene")).string(), &scene, &error)) << error;
    EXPECT_EQ(scene.model(), "hex_4x5_home");
    ASSERT_EQ(scene.tools_size(), 1);
    EXPECT_EQ(scene.tools(0).radius(), 1.5);
    EXPECT_EQ(scene.tools(0).stiffness(), 400);
    // The default step (symplectic Euler, r_l = 2 r), as every entry point.
    EXPECT_EQ(scene.integrator(), v1::INTEGRATOR_SYMPLECTIC_EULER) << name;
    EXPECT_EQ(scene.tools(0).local_radius(), 3.0) << name;
    EXPECT_EQ(scene.dt_s(), 0.001);
    EXPECT_EQ(scene.tools(0).kind(), std::string(name) == "pluck" ? v1::Tool::KIND_TWEEZERS : v1::Tool::KIND_SPHERE);
  }
}

// The pierce's scene is the needle scripted:pierce is made for (PierceNeedle, docs/needle.md).
TEST(Scene, ThePierceSceneIsThePiercesNeedle) {
  v1::Scene scene;
  std::string error;
  ASSERT_TRUE(LoadScene(std::string(IDMS_SOURCE_DIR) + "/models/pierce.scene", &scene, &error)) << error;
  ASSERT_EQ(scene.tools_size(), 1);
  const v1::Tool& t = scene.tools(0);
  const ToolCommand c = PierceNeedle();
  EXPECT_EQ(t.kind(), v1::Tool::KIND_NEEDLE);
  EXPECT_EQ(t.radius(), c.radius);
  EXPECT_EQ(t.stiffness(), c.stiffness);
  EXPECT_EQ(t.force_law(), v1::FORCE_LAW_LINEAR);
  EXPECT_EQ(t.needle().length(), c.needle.length);
  EXPECT_EQ(t.needle().puncture_force(), c.needle.puncture_force);
  EXPECT_EQ(t.needle().axial_friction(), c.needle.mu);
  EXPECT_EQ(t.needle().grip(), c.needle.grip);
  EXPECT_EQ(t.needle().capture_radius(), c.needle.capture_radius);
  EXPECT_EQ(t.needle().lateral_stiffness(), c.needle.lateral_stiffness);
  EXPECT_EQ(t.needle().axial_stiffness(), c.needle.axial_stiffness);
}

TEST(Scene, DefaultsFillUnsetFields) {
  v1::Scene scene;
  std::string error;
  ASSERT_TRUE(LoadSceneText(kMinimal, "minimal.scene", &scene, &error)) << error;
  EXPECT_EQ(scene.dt_s(), 0.001);
  EXPECT_EQ(scene.stream_rate_hz(), 60);
  EXPECT_EQ(scene.quant_step(), 1e-4);
  EXPECT_EQ(scene.keyframe_interval_s(), 5);
  EXPECT_EQ(scene.sample_batch(), 20u);
  EXPECT_EQ(scene.preset(), v1::PRESET_DEFAULT);
  EXPECT_EQ(scene.integrator(), v1::INTEGRATOR_SYMPLECTIC_EULER);  // the default step, as idms-sim run
  EXPECT_EQ(scene.tools(0).force_law(), v1::FORCE_LAW_THESIS);     // the pseudo-code's law, as idms-sim run
  EXPECT_EQ(scene.tools(0).local_radius(), 2 * scene.tools(0).radius());
  EXPECT_EQ(scene.device().scale(), 1);
  EXPECT_EQ(scene.device().max_force(), 10);
  EXPECT_EQ(scene.device().max_rate_hz(), 1000);
  EXPECT_FALSE(scene.recording());
}

// The thesis's configuration by name: explicit Euler and a window of 1.5 radii, where the scene
// leaves them unset; what it sets stays.
TEST(Scene, ThesisPresetFillsTheThesisStep) {
  v1::Scene scene;
  std::string error;
  ASSERT_TRUE(LoadSceneText(std::string(kMinimal) + "preset: PRESET_THESIS\n", "thesis.scene", &scene, &error))
      << error;
  EXPECT_EQ(scene.integrator(), v1::INTEGRATOR_EXPLICIT_EULER);
  EXPECT_EQ(scene.tools(0).local_radius(), 1.5 * scene.tools(0).radius());
  ASSERT_TRUE(LoadSceneText(std::string(kMinimal) + "preset: PRESET_THESIS\nintegrator: INTEGRATOR_RK4\n",
                            "thesis.scene", &scene, &error))
      << error;
  EXPECT_EQ(scene.integrator(), v1::INTEGRATOR_RK4);
  EXPECT_EQ(
      LoadError("model: \"x\"\ntools {\n  kind: KIND_SPHERE\n}\npreset: PRESET_FAST\n").rfind("test.scene:5:9: ", 0),
      0u);
}

TEST(Scene, SyntaxErrorsHaveLineAndColumn) {
  EXPECT_EQ(LoadError("model: \"x\"\ntools {\n  radius: 1.5\n  colour: 3\n}\n"),
            "test.scene:4:3: Message type \"idms.v1.Tool\" has no field named \"colour\".");
  const std::string e1 = LoadError("model: \"x\"\ntools {\n  radius: abc\n}\n");
  EXPECT_EQ(e1.rfind("test.scene:3:11: ", 0), 0u) << e1;
  const std::string e2 = LoadError("model: \"x\"\ntools {\n  kind: KIND_CUBE\n}\n");
  EXPECT_EQ(e2.rfind("test.scene:3:9: ", 0), 0u) << e2;
  const std::string e5 = LoadError("model: \"x\"\ntools {\n\tkind: KIND_CUBE }\n");
  EXPECT_EQ(e5.rfind("test.scene:3:15: ", 0), 0u) << e5;
  EXPECT_NE(e2.find("KIND_CUBE"), std::string::npos) << e2;
  const std::string e3 = LoadError("model: \"x\"\ntools {\n  radius: 1\n");
  EXPECT_EQ(e3.rfind("test.scene:4:", 0), 0u) << e3;
  const std::string e4 = LoadError("model: \"x\"\nmodel: \"y\"\n");
  EXPECT_EQ(e4.rfind("test.scene:2:", 0), 0u) << e4;
}

TEST(Scene, BadValuesNameTheFieldAndWhere) {
  EXPECT_EQ(LoadError("model: \"hex\"\ntools {\n  kind: KIND_SPHERE\n  radius: -1\n"
                      "  stiffness: 400\n}\n"),
            "test.scene:4:3: tools[0].radius: must be in (0, inf), got -1");
  EXPECT_EQ(LoadError(std::string(kMinimal) + "dt_s: 0\n"), "test.scene:7:1: dt_s: must be in (0, 0.1], got 0");
  EXPECT_EQ(LoadError(std::string(kMinimal) + "device {\n  max_force: -2\n}\n"),
            "test.scene:8:3: device.max_force: must be in (0, inf), got -2");
  EXPECT_EQ(LoadError(std::string(kMinimal) + "stream_rate_hz: 5000\n"),
            "test.scene:7:1: stream_rate_hz: must be in (0, 1000], got 5000");
  EXPECT_EQ(LoadError(std::string(kMinimal) + "gravity { z: nan }\n"), "test.scene:7:1: gravity: must be finite");
  EXPECT_EQ(LoadError(std::string(kMinimal) + "global_rate_hz: 900\n"),
            "test.scene:7:1: global_rate_hz: must be in [0, 500], got 900");
  EXPECT_EQ(LoadError(std::string(kMinimal) + "full_simulation: true\nglobal_rate_hz: 50\n"),
            "test.scene:8:1: global_rate_hz: a global pass beside full_simulation, which already moves every atom");
  EXPECT_EQ(LoadError(std::string(kMinimal) + "units {\n  mm_per_unit: 0\n}\n"),
            "test.scene:8:3: units.mm_per_unit: must be in (0, 1e+09], got 0");
  EXPECT_EQ(LoadError(std::string(kMinimal) + "units {\n  newtons_per_force_unit: -1\n}\n"),
            "test.scene:8:3: units.newtons_per_force_unit: must be in (0, 1e+09], got -1");
  v1::Scene good;
  std::string error;
  ASSERT_TRUE(LoadSceneText(std::string(kMinimal) + "units {\n  mm_per_unit: 25.4\n}\n", "test.scene", &good, &error))
      << error;
  EXPECT_EQ(good.units().mm_per_unit(), 25.4);
  EXPECT_FALSE(good.units().has_newtons_per_force_unit());
  // A missing field is located at its parent.
  EXPECT_EQ(LoadError("model: \"hex\"\ntools {\n  kind: KIND_SPHERE\n  radius: 1\n}\n"),
            "test.scene:2:1: tools[0].stiffness: required (force / length, > 0)");
  EXPECT_EQ(LoadError("model: \"hex\"\ntools {\n  radius: 1\n  stiffness: 1\n}\n"),
            "test.scene:2:1: tools[0].kind: set kind: KIND_SPHERE, KIND_TWEEZERS, KIND_SCALPEL or KIND_NEEDLE");
  EXPECT_EQ(LoadError("model: \"hex\"\ntools {\n  kind: KIND_SPHERE\n  radius: 2\n"
                      "  stiffness: 1\n  local_radius: 1\n}\n"),
            "test.scene:6:3: tools[0].local_radius: must be >= radius (2) so that contact atoms "
            "are simulated, got 1");
  // Whole-scene problems have no position.
  EXPECT_EQ(LoadError("tools {\n  kind: KIND_SPHERE\n  radius: 1\n  stiffness: 1\n}\n"),
            "test.scene: model: set model (a library NAME or NAME@VERSION) or model_file "
            "(a .fem/.plg prefix)");
  EXPECT_EQ(LoadError("model: \"hex\"\n"), "test.scene: tools: at least one tool is required");
  EXPECT_EQ(LoadError("model: \"../etc\"\ntools {\n  kind: KIND_SPHERE\n  radius: 1\n"
                      "  stiffness: 1\n}\n")
                .rfind("test.scene:1:1: model: expected NAME or NAME@VERSION", 0),
            0u);
  EXPECT_EQ(LoadError(std::string(kMinimal) + "model_file: \"models/hex\"\n"),
            "test.scene:7:1: model_file: set only one of model and model_file");
}

TEST(Scene, ModelNamesWithVersions) {
  v1::Scene scene;
  std::string error;
  ASSERT_TRUE(LoadSceneText(kMinimal, "s", &scene, &error)) << error;
  scene.set_model("hex_4x5_home@3");
  EXPECT_TRUE(ValidateScene(scene, &error)) << error;
  scene.set_model("hex@");
  EXPECT_FALSE(ValidateScene(scene, &error));
  EXPECT_EQ(error.rfind("model: ", 0), 0u) << error;
  scene.set_model("a b");
  EXPECT_FALSE(ValidateScene(scene, &error));
}

TEST(Scene, MissingFileIsAnError) {
  v1::Scene scene;
  std::string error;
  EXPECT_FALSE(LoadScene("/nonexistent/x.scene", &scene, &error));
  EXPECT_NE(error.find("/nonexistent/x.scene: cannot open"), std::string::npos) << error;
}

TEST(Scene, ParseWithoutValidation) {
  v1::Scene scene;
  std::string error;
  ASSERT_TRUE(ParseSceneText("dt_s: -1\n", "s", &scene, &error)) << error;
  EXPECT_EQ(scene.dt_s(), -1);
  EXPECT_FALSE(ValidateScene(scene, &error));
  EXPECT_NE(error.find("model"), std::string::npos) << error;
}

}  // namespace
}  // namespace idms

namespace idms {
namespace {

// Friction's fields (issue 30): bad coefficients are refused naming the field and its place;
// defaults are filled only where there is friction.
TEST(Scene, FrictionIsValidatedAndDefaulted) {
  const std::string tool = "model: \"hex\"\ntools {\n  kind: KIND_SPHERE\n  radius: 1.5\n  stiffness: 400\n";
  EXPECT_EQ(LoadError(tool + "  static_friction: -0.5\n}\n"),
            "test.scene:6:3: tools[0].static_friction: must be in [0, inf), got -0.5");
  EXPECT_EQ(LoadError(tool + "  static_friction: 0.4\n  kinetic_friction: 0.6\n}\n"),
            "test.scene:7:3: tools[0].kinetic_friction: must be <= static_friction (0.4), got 0.6");
  EXPECT_EQ(LoadError(tool + "  static_friction: nan\n}\n"),
            "test.scene:6:3: tools[0].static_friction: must be in [0, inf), got nan");
  EXPECT_EQ(LoadError(tool + "  kinetic_friction: 0.3\n}\n"),
            "test.scene:6:3: tools[0].kinetic_friction: needs static_friction (mu_s >= mu_d) set too");
  EXPECT_EQ(LoadError(tool + "  static_friction: 0.5\n  friction_stiffness: 0\n}\n"),
            "test.scene:7:3: tools[0].friction_stiffness: must be in (0, inf), got 0");
  EXPECT_EQ(LoadError(tool + "  static_friction: 0.5\n  friction_damping: -1\n}\n"),
            "test.scene:7:3: tools[0].friction_damping: must be in [0, inf), got -1");
  EXPECT_EQ(LoadError("model: \"hex\"\ntools {\n  kind: KIND_SCALPEL\n  radius: 1\n  stiffness: 1\n"
                      "  static_friction: 0.5\n}\n"),
            "test.scene:6:3: tools[0].static_friction: friction applies to KIND_SPHERE and KIND_TWEEZERS only");

  v1::Scene scene;
  std::string error;
  ASSERT_TRUE(LoadSceneText(tool + "  static_friction: 0.6\n}\ndt_s: 0.002\n", "f.scene", &scene, &error)) << error;
  EXPECT_EQ(scene.tools(0).kinetic_friction(), 0.6);
  EXPECT_EQ(scene.tools(0).friction_stiffness(), 400);
  EXPECT_DOUBLE_EQ(scene.tools(0).friction_damping(), 0.8);
  // Frictionless: no friction field appears.
  ASSERT_TRUE(LoadSceneText(kMinimal, "m.scene", &scene, &error)) << error;
  EXPECT_FALSE(scene.tools(0).has_static_friction());
  EXPECT_FALSE(scene.tools(0).has_friction_damping());
}

// Issue 32: a needle's parameters are checked, each refusal naming the field; a needle message on
// another kind and friction on a needle are refused.
TEST(SceneTest, NeedleParametersAreCheckedByField) {
  const std::string needle = "model: \"hex\"\ntools {\n  kind: KIND_NEEDLE\n  radius: 0.2\n  stiffness: 400\n";
  v1::Scene scene;
  std::string error;
  ASSERT_TRUE(LoadSceneText(needle + "  needle { length: 8 puncture_force: 2 axial_friction: 0.4 grip: 1 }\n}\n",
                            "n.scene", &scene, &error))
      << error;
  EXPECT_EQ(scene.tools(0).kind(), v1::Tool::KIND_NEEDLE);
  EXPECT_EQ(scene.tools(0).needle().puncture_force(), 2);
  // Each bad value, refused at its own column.
  const std::pair<const char*, const char*> bad[] = {
      {"puncture_force: 0", "puncture_force: must be in (0, inf), got 0"},
      {"length: -1", "length: must be in (0, inf), got -1"},
      {"axial_friction: nan", "axial_friction: must be in [0, inf), got nan"},
      {"capture_radius: 0", "capture_radius: must be in (0, inf), got 0"},
      {"lateral_damping: -1", "lateral_damping: must be in [0, inf), got -1"},
  };
  for (const auto& [field, message] : bad) {
    EXPECT_EQ(LoadError(needle + "  needle { " + field + " }\n}\n"),
              std::string("test.scene:6:12: tools[0].needle.") + message);
  }
  EXPECT_EQ(LoadError("model: \"hex\"\ntools {\n  kind: KIND_SPHERE\n  radius: 1\n  stiffness: 1\n"
                      "  needle { length: 5 }\n}\n"),
            "test.scene:6:3: tools[0].needle: applies to KIND_NEEDLE only");
  EXPECT_EQ(LoadError(needle + "  static_friction: 0.5\n}\n"),
            "test.scene:6:3: tools[0].static_friction: friction applies to KIND_SPHERE and KIND_TWEEZERS only");
}

// A needle's suture thread: its parameters checked by field (its length required, its segments
// 1 to 128), each refusal at its own column.
TEST(SceneTest, SutureParametersAreCheckedByField) {
  const std::string needle = "model: \"hex\"\ntools {\n  kind: KIND_NEEDLE\n  radius: 0.2\n  stiffness: 400\n";
  v1::Scene scene;
  std::string error;
  ASSERT_TRUE(LoadSceneText(needle + "  needle { length: 5 suture { length: 8 segments: 64 tie_force: 3 } }\n}\n",
                            "n.scene", &scene, &error))
      << error;
  EXPECT_EQ(scene.tools(0).needle().suture().segments(), 64u);
  EXPECT_EQ(LoadError(needle + "  needle { suture { segments: 8 } }\n}\n"),
            "test.scene:6:12: tools[0].needle.suture.length: required (model units, > 0)");
  const std::pair<const char*, const char*> bad[] = {
      {"segments: 0", "segments: must be in [1, 128], got 0"},
      {"segments: 129", "segments: must be in [1, 128], got 129"},
      {"mass: 0", "mass: must be in (0, inf), got 0"},
      {"tie_force: -2", "tie_force: must be in (0, inf), got -2"},
      {"strength: inf", "strength: must be in [0, inf), got inf"},
  };
  for (const auto& [field, message] : bad) {
    EXPECT_EQ(LoadError(needle + "  needle { suture { length: 8 " + field + " } }\n}\n"),
              std::string("test.scene:6:31: tools[0].needle.suture.") + message);
  }
}

}  // namespace
}  // namespace idms
