// The fitter (sim/fit): parameters hidden in a synthetic recording, with noise, are found again;
// a recording that cannot determine them is refused with the reason; the CSV reader refuses what
// idms-sim run did not write.
#include "fit.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include "idms/sim/generate.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/model_io.h"
#include "step_test_util.h"

namespace idms::fit {
namespace {

using test::LoadShippedModel;

Model Hex() { return LoadShippedModel("hex_4x5_home"); }

// The fit of `params` with the recordings' sphere; and, given a region's spec, inside it and outside.
FitOptions Options(std::vector<Param> params, const std::string& region = "") {
  FitOptions o;
  o.params = std::move(params);
  o.tool.kind = ToolKind::kSphere;
  if (!region.empty()) {
    Region g;
    std::string error;
    EXPECT_TRUE(ParseRegion(region, 0, &g, &error)) << error;
    o.regions = {g};
  }
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
    EXPECT_NEAR(r.scale[i] / want[i], 1.0, 0.02) << r.names[i] << " x " << r.scale[i];
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

// The pluck (thesis 6.1.3): the tweezers close on an atom pressed in, lift it and let go. Replayed
// closed where the recording held the atom, its force determines the home stiffness as a press
// does; replayed open throughout (a sphere), the lift pulls nothing and the fit is far off.
TEST(Fit, ThePlucksTweezersAreReplayedClosedAndItsForceDeterminesTheStiffness) {
  const Model typed = Hex();
  Model truth = typed;
  ScaleGroup(truth, Param::kHomeK, 1.3);
  const Trace trace = ScriptedTrace(truth, Script::kPluck, 0.01, 7);
  ASSERT_EQ(trace.closed.size(), trace.pos.size());
  FitOptions o = Options({Param::kHomeK});
  o.tool.kind = ToolKind::kTweezers;
  const FitResult r = Fit(typed, trace, o);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_NEAR(r.scale[0] / 1.3, 1.0, 0.02) << "home_k x " << r.scale[0];
  EXPECT_LT(r.rms_after, 1.1 * std::sqrt(3.0) * 0.01 * r.peak_force);
  std::printf("pluck fit: home_k x %.5f +- %.5f, RMS %.4g of peak %.4g\n", r.scale[0], r.scale_sigma[0], r.rms_after,
              r.peak_force);
  Trace open = trace;
  open.closed.clear();
  const FitResult blind = Fit(typed, open, o);
  EXPECT_TRUE(!blind.ok || blind.rms_after > 5 * r.rms_after) << "without the grasp the lift is not explained";
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

// Progress is reported every solver iteration, and a stop set from another thread (here the
// progress callback, at the first iteration) ends the fit at its next replay as "stopped"; the
// progress callback's false does the same.
TEST(Fit, ReportsProgressAndAStopEndsTheFitAtItsNextReplay) {
  const Model truth = Hex();
  Model typed = truth;
  ScaleGroup(typed, Param::kHomeK, 0.8);
  const Trace trace = ScriptedTrace(truth, Script::kPalpate, 0.01, 7);
  FitOptions o = Options({Param::kHomeK, Param::kSurfaceK});
  std::vector<FitProgress> seen;
  o.progress = [&](const FitProgress& p) {
    seen.push_back(p);
    return true;
  };
  const FitResult whole = Fit(typed, trace, o);
  ASSERT_TRUE(whole.ok) << whole.message;
  ASSERT_GE(seen.size(), 2u);
  EXPECT_EQ(seen.front().iteration, 0);
  EXPECT_GT(seen.back().replays, seen.front().replays);
  EXPECT_LT(seen.back().rms, seen.front().rms);

  std::atomic<bool> stop{false};
  int replays_at_stop = -1;
  o.stop = &stop;
  o.progress = [&](const FitProgress& p) {
    if (replays_at_stop < 0) replays_at_stop = p.replays;
    stop = true;
    return true;
  };
  const FitResult stopped = Fit(typed, trace, o);
  EXPECT_FALSE(stopped.ok);
  EXPECT_EQ(stopped.message, "stopped");
  EXPECT_EQ(stopped.replays, replays_at_stop) << "no replay after the stop";

  o.stop = nullptr;
  o.progress = [](const FitProgress&) { return false; };
  const FitResult refused = Fit(typed, trace, o);
  EXPECT_FALSE(refused.ok);
  EXPECT_EQ(refused.message, "stopped");
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

// Per region: an inclusion on the stroke's line (k x 3.3 inside, the rest x 1.1) is found again
// in both parts from one noisy stroke, which crosses into it and out again.
TEST(Fit, RecoversARegionsStiffnessFromANoisyStroke) {
  const Model typed = Hex();
  Model truth = typed;
  Inclusion lump;
  lump.center[0] = 2, lump.center[1] = 1.5, lump.radius = 0.9, lump.k_scale = 3;
  ApplyInclusions({lump}, &truth);
  ScaleGroup(truth, Param::kK, 1.1);
  const FitOptions o = Options({Param::kK}, "lump=sphere:2,1.5,0,0.9");
  const FitResult r = Fit(typed, ScriptedTrace(truth, Script::kStrokeGentle, 0.01, 7), o);
  ASSERT_TRUE(r.ok) << r.message;
  ASSERT_EQ(r.names, (std::vector<std::string>{"k@lump", "k@rest"}));
  EXPECT_NEAR(r.scale[0] / 3.3, 1.0, 0.02) << "k@lump x " << r.scale[0] << " +- " << r.scale_sigma[0];
  EXPECT_NEAR(r.scale[1] / 1.1, 1.0, 0.02) << "k@rest x " << r.scale[1] << " +- " << r.scale_sigma[1];
  // Without the region the one factor is neither.
  const FitResult whole = Fit(typed, ScriptedTrace(truth, Script::kStrokeGentle, 0.01, 7), Options({Param::kK}));
  ASSERT_TRUE(whole.ok) << whole.message;
  EXPECT_GT(whole.rms_after, 2 * r.rms_after) << "one factor for the whole model fits worse";
}

TEST(Fit, RegionsAreParsedAndOneThatHoldsNothingIsRefused) {
  Region g;
  std::string error;
  ASSERT_TRUE(ParseRegion("box:0,0,-1,1,2,0.5", 2, &g, &error)) << error;
  EXPECT_EQ(g.name, "region3");
  EXPECT_EQ(g.shape, Region::Shape::kBox);
  const double inside[3] = {0.5, 1, 0}, outside[3] = {0.5, 1, 0.6};
  EXPECT_TRUE(g.Contains(inside));
  EXPECT_FALSE(g.Contains(outside));
  EXPECT_FALSE(ParseRegion("lump=sphere:1,2,3", 0, &g, &error));
  EXPECT_EQ(error, "--region 'lump=sphere:1,2,3': sphere takes 4 numbers, got 3");
  EXPECT_FALSE(ParseRegion("sphere:1,2,x,1", 0, &g, &error));
  EXPECT_NE(error.find("value 3 ('x') is not one"), std::string::npos) << error;
  EXPECT_FALSE(ParseRegion("cone:1,2,3,4", 0, &g, &error));
  EXPECT_NE(error.find("expected [NAME=]sphere"), std::string::npos) << error;
  EXPECT_FALSE(ParseRegion("rest=sphere:1,2,3,4", 0, &g, &error));
  EXPECT_NE(error.find("not 'rest'"), std::string::npos) << error;
  EXPECT_FALSE(ParseRegion("sphere:1,2,3,0", 0, &g, &error));
  EXPECT_NE(error.find("radius must be > 0"), std::string::npos) << error;
  std::vector<Param> params;
  EXPECT_FALSE(ParseParams("k,home_k", &params, &error));
  EXPECT_EQ(error, "--params: k (every element) overlaps home_k; fit one or the other");
  // A region away from the model holds no element: refused by name, before any replay.
  const FitResult r =
      Fit(Hex(), ScriptedTrace(Hex(), Script::kPalpate, 0.0, 7), Options({Param::kSurfaceK}, "far=sphere:50,50,50,1"));
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.message,
            "surface_k@far: the model has no surface elements with a nonzero value to scale inside region far");
  EXPECT_EQ(r.replays, 0);
}

// A region the tool never loads (a corner of the slab, far outside the palpation's haptic
// window) cannot be fitted: its elements never move, its column of the Jacobian is zero, and the
// fit says so instead of returning the starting value as if it were measured.
TEST(Fit, ARegionTheRecordingNeverLoadsIsRefusedAsUndetermined) {
  const Model slab = LoadShippedModel("slab_40x40");
  const FitResult r =
      Fit(slab, ScriptedTrace(slab, Script::kPalpate, 0.01, 7), Options({Param::kK}, "corner=box:0,0,-2,5,5,1"));
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("does not determine every parameter asked for"), std::string::npos) << r.message;
  EXPECT_GT(r.replays, 0) << "found by the solver, not by a rule before it";
}

// The lump a clinician palpates for (issue 34): a scan of slab_40x40_tumour (k x 8 in a sphere of
// radius 4 at 20, 17, -0.4) with 1% noise, mapped against the plain slab, puts the lump's centre
// within one element spacing (1) and its stiffness ratio within 10%; the plain slab's own scan
// shows no lump. Every one of the 7 x 7 grid's presses touches the surface.
TEST(FitMap, FindsTheTumourAndNothingOnThePlainSlab) {
  const Model plain = LoadShippedModel("slab_40x40");
  const FitOptions o = Options({});
  const MapResult tumour =
      FitMap(plain, ScriptedTrace(LoadShippedModel("slab_40x40_tumour"), Script::kScan, 0.01, 11), o);
  ASSERT_TRUE(tumour.ok) << tumour.message;
  EXPECT_EQ(tumour.points.size(), size_t{kScanGrid * kScanGrid});
  EXPECT_NEAR(tumour.background, 1.0, 0.01);
  ASSERT_TRUE(tumour.lump.found);
  EXPECT_LT(std::hypot(tumour.lump.x - 20, tumour.lump.y - 17), 1.0)
      << "centre " << tumour.lump.x << ", " << tumour.lump.y;
  EXPECT_NEAR(tumour.lump.ratio / 8, 1.0, 0.1) << "ratio " << tumour.lump.ratio;
  std::printf("tumour: centre %.3f, %.3f +- %.2g, radius %.3f, ratio %.3f +- %.2g, %d replays, %.2f s\n", tumour.lump.x,
              tumour.lump.y, tumour.lump.xy_sigma, tumour.lump.radius, tumour.lump.ratio, tumour.lump.ratio_sigma,
              tumour.replays, tumour.seconds);
  const MapResult none = FitMap(plain, ScriptedTrace(plain, Script::kScan, 0.01, 11), o);
  ASSERT_TRUE(none.ok) << none.message;
  EXPECT_EQ(none.points.size(), size_t{kScanGrid * kScanGrid});
  EXPECT_FALSE(none.lump.found) << "a lump at " << none.lump.x << ", " << none.lump.y << " x " << none.lump.ratio;
  for (const MapPoint& p : none.points) EXPECT_NEAR(p.scale, 1.0, 0.05) << p.x << ", " << p.y;
  // A palpation is one press: no map.
  const MapResult one = FitMap(plain, ScriptedTrace(plain, Script::kPalpate, 0.0, 7), o);
  EXPECT_FALSE(one.ok);
  EXPECT_NE(one.message.find("holds 1 separate presses; a map needs at least 3"), std::string::npos) << one.message;
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
  // A tweezers' run: its closed column, 0 or 1.
  const std::string pluck = dir + "/fit-pluck.csv", bad_closed = dir + "/fit-bad-closed.csv";
  std::ofstream(pluck) << "t,x,y,z,fx,fy,fz,active_atoms,substeps,compute_us,closed\n"
                       << "0.001000,1,2,3,0.1,0.2,0.3,5,1,2.5,0\n0.002000,1,2,2.9,0.1,0.2,0.4,5,1,2.5,1\n";
  std::ofstream(bad_closed) << "t,x,y,z,fx,fy,fz,closed\n0.001,1,2,3,0,0,0,0\n0.002,1,2,3,0,0,0,yes\n";
  ASSERT_TRUE(ReadTraceCsv(pluck, &t, &error)) << error;
  ASSERT_EQ(t.closed.size(), 2u);
  EXPECT_EQ(t.closed[0], 0);
  EXPECT_EQ(t.closed[1], 1);
  EXPECT_FALSE(ReadTraceCsv(bad_closed, &t, &error));
  EXPECT_NE(error.find("fit-bad-closed.csv:3: column 8 (closed) is not 0 or 1"), std::string::npos) << error;
  ASSERT_TRUE(ReadTraceCsv(good, &t, &error)) << error;
  EXPECT_TRUE(t.closed.empty());
}

}  // namespace
}  // namespace idms::fit
