// The fitter (sim/fit): parameters hidden in a synthetic recording, with noise, are found again;
// a recording that cannot determine them is refused with the reason; the CSV reader refuses what
// idms-sim run did not write.
#include "fit.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include "idms/sim/interaction_script.h"
#include "idms/sim/model_io.h"

namespace idms::fit {
namespace {

Model Hex() {
  Model m;
  LoadError error;
  const std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";
  EXPECT_TRUE(LoadModel(prefix + ".fem", prefix + ".plg", {}, &m, &error)) << error.ToString();
  return m;
}

FitOptions Options(std::vector<Param> params) {
  FitOptions o;
  o.params = std::move(params);
  o.tool.kind = ToolKind::kSphere;
  return o;
}

// A stroke across the fragment loads the home and the surface elements in changing proportions:
// it determines both stiffnesses and the home damping, each within 2% under 1% noise.
TEST(Fit, RecoversStiffnessAndDampingFromANoisyStroke) {
  const Model typed = Hex();
  Model truth = typed;
  ScaleGroup(truth, Param::kHomeK, 1.3);
  ScaleGroup(truth, Param::kSurfaceK, 0.8);
  ScaleGroup(truth, Param::kHomeB, 1.2);
  const Trace trace = ScriptedTrace(truth, Script::kStrokeGentle, 0.01, 7);
  const FitResult r = Fit(typed, trace, Options({Param::kHomeK, Param::kSurfaceK, Param::kHomeB}));
  ASSERT_TRUE(r.ok) << r.message;
  const double want[] = {1.3, 0.8, 1.2};
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_NEAR(r.scale[i] / want[i], 1.0, 0.02) << ParamName(r.params[i]) << " x " << r.scale[i];
    EXPECT_GT(r.scale_sigma[i], 0) << i;
    EXPECT_LT(r.scale_sigma[i], 0.02 * want[i]) << i;
  }
  EXPECT_NEAR(r.value[0], 1.3 * GroupMean(typed, Param::kHomeK), 0.02 * 1.3 * GroupMean(typed, Param::kHomeK));
  // The residual is the noise (1% of the peak on each of three components), not more.
  EXPECT_LT(r.rms_after, 1.1 * std::sqrt(3.0) * 0.01 * r.peak_force);
  EXPECT_GT(r.rms_before, 1.5 * r.rms_after) << "the typed-in model was measurably off";
  // The fitted model is the typed-in one with the factors applied.
  EXPECT_NEAR(GroupMean(r.fitted, Param::kHomeK), r.value[0], 1e-9 * r.value[0]);
}

// A palpation presses one point: its force against depth determines one stiffness (the other
// known), and that predicts a stroke it never saw. Asked for both, it says how little it knows.
TEST(Fit, APalpationDeterminesOneStiffnessAndPredictsAStroke) {
  const Model typed = Hex();
  Model truth = typed;
  ScaleGroup(truth, Param::kHomeK, 1.3);
  const FitResult r = Fit(typed, ScriptedTrace(truth, Script::kPalpate, 0.01, 7), Options({Param::kHomeK}));
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_NEAR(r.scale[0] / 1.3, 1.0, 0.02) << "home_k x " << r.scale[0];
  const Trace stroke = ScriptedTrace(truth, Script::kStrokeGentle, 0.0, 7);
  ToolCommand tool;
  tool.kind = ToolKind::kSphere;
  const auto predicted = Replay(r.fitted, stroke, StepOptions{}, tool, 1);
  double sum = 0, peak = 0;
  for (size_t n = 0; n < predicted.size(); ++n) {
    const auto& f = stroke.force[n];
    peak = std::max(peak, std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]));
    for (int c = 0; c < 3; ++c) sum += (predicted[n][c] - f[c]) * (predicted[n][c] - f[c]);
  }
  const double relative = std::sqrt(sum / static_cast<double>(predicted.size())) / peak;
  EXPECT_LT(relative, 0.03) << "the held-out stroke's relative RMS error";
  std::printf("palpation fit: home_k x %.5f +- %.5f; held-out stroke relative RMS error %.4f\n", r.scale[0],
              r.scale_sigma[0], relative);
  const FitResult both =
      Fit(typed, ScriptedTrace(truth, Script::kPalpate, 0.01, 7), Options({Param::kHomeK, Param::kSurfaceK}));
  ASSERT_TRUE(both.ok) << both.message;
  EXPECT_GT(both.scale_sigma[1], 0.05) << "one press cannot tell the home springs from the surface's";
}

TEST(Fit, RecoversDampingFromAStroke) {
  const Model typed = Hex();
  Model truth = typed;
  ScaleGroup(truth, Param::kSurfaceK, 1.2);
  ScaleGroup(truth, Param::kSurfaceB, 1.5);
  const Trace trace = ScriptedTrace(truth, Script::kStrokeFast, 0.01, 7);
  const FitResult r = Fit(typed, trace, Options({Param::kSurfaceK, Param::kSurfaceB}));
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_NEAR(r.scale[0] / 1.2, 1.0, 0.02) << "surface_k x " << r.scale[0];
  EXPECT_NEAR(r.scale[1] / 1.5, 1.0, 0.02) << "surface_b x " << r.scale[1];
}

// The MIO's contact stiffness (the thesis's k = 400 is typed in too): a palpation made with a
// stiffer fingertip gives its k back; the model is left as it was.
TEST(Fit, RecoversTheToolsContactStiffness) {
  const Model typed = Hex();
  const FitResult r = Fit(typed, ScriptedTrace(typed, Script::kPalpate, 0.01, 7, 500), Options({Param::kToolK}));
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_NEAR(r.value[0] / 500, 1.0, 0.02) << "tool_k " << r.value[0];
  EXPECT_NEAR(r.fitted_tool.stiffness, r.value[0], 1e-9 * r.value[0]);
  EXPECT_EQ(r.fitted.elem_k, typed.elem_k);
}

TEST(Fit, APathThatNeverTouchesIsRefused) {
  const Model typed = Hex();
  Trace trace = ScriptedTrace(typed, Script::kPalpate, 0.0, 7);
  for (auto& p : trace.pos) p[2] += 50;  // far above the surface
  for (auto& f : trace.force) f = {0, 0, 0};
  const FitResult r = Fit(typed, trace, Options({Param::kHomeK}));
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("never touches"), std::string::npos) << r.message;
}

TEST(Fit, ParamsAreNamedEachOnceAndAGroupWithNothingToScaleIsRefused) {
  std::vector<Param> params;
  std::string error;
  EXPECT_FALSE(ParseParams("home_k,home_k", &params, &error));
  EXPECT_NE(error.find("bad item 'home_k'"), std::string::npos) << error;
  EXPECT_FALSE(ParseParams("home_k,stiffness", &params, &error));
  EXPECT_NE(error.find("bad item 'stiffness'"), std::string::npos) << error;
  ASSERT_TRUE(ParseParams("surface_b,home_k", &params, &error)) << error;
  EXPECT_EQ(params, (std::vector<Param>{Param::kSurfaceB, Param::kHomeK}));
  Model springless = Hex();
  ScaleGroup(springless, Param::kHomeK, 0.0);
  const FitResult r = Fit(springless, ScriptedTrace(Hex(), Script::kPalpate, 0.0, 7), Options({Param::kHomeK}));
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.message, "home_k: the model has no home elements with a nonzero value to scale");
}

TEST(Fit, TheCsvReaderTakesIdmsSimRunsColumnsAndRefusesOthers) {
  const std::string dir = testing::TempDir();
  const std::string good = dir + "/fit-good.csv", bad = dir + "/fit-bad.csv", uneven = dir + "/fit-uneven.csv";
  std::ofstream(good) << "t,x,y,z,fx,fy,fz,active_atoms,substeps,compute_us\n"
                      << "0.001000,1,2,3,0.1,0.2,0.3,5,1,2.5\n0.002000,1,2,2.9,0.1,0.2,0.4,5,1,2.5\n";
  std::ofstream(bad) << "time,x,y,z\n0.001,1,2,3\n";
  std::ofstream(uneven) << "t,x,y,z,fx,fy,fz\n0.001,1,2,3,0,0,0\n0.002,1,2,3,0,0,0\n0.004,1,2,3,0,0,0\n";
  Trace t;
  std::string error;
  ASSERT_TRUE(ReadTraceCsv(good, &t, &error)) << error;
  EXPECT_NEAR(t.dt_s, 1e-3, 1e-12);
  ASSERT_EQ(t.pos.size(), 2u);
  EXPECT_EQ(t.pos[1][2], 2.9);
  EXPECT_EQ(t.force[1][2], 0.4);
  EXPECT_FALSE(ReadTraceCsv(bad, &t, &error));
  EXPECT_NE(error.find("fit-bad.csv:1: expected the header"), std::string::npos) << error;
  EXPECT_FALSE(ReadTraceCsv(uneven, &t, &error));
  EXPECT_NE(error.find("fit-uneven.csv:4: t = 0.004"), std::string::npos) << error;
  EXPECT_FALSE(ReadTraceCsv(dir + "/none.csv", &t, &error));
  EXPECT_NE(error.find("cannot read"), std::string::npos) << error;
}

}  // namespace
}  // namespace idms::fit
