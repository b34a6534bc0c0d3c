// idms-sim run, end to end: the real binary on the shipped hex fragment, its presets, the
// documented CSV, and bad arguments.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

namespace {

struct Output {
  int status = -1;
  std::string text;
};

Output RunSim(const std::string& args) {
  const std::string command = std::string(IDMS_BIN_DIR) + "/idms-sim " + args + " 2>&1";
  Output out;
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return out;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) out.text.append(buf, n);
  out.status = pclose(pipe);
  return out;
}

const std::string kHex = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";

// A regression guard, not a reproduction: the script's press depth was chosen so that the peak
// is the thesis's 1.7 N (fig. 6-2), and onset at z = 1.5 is the geometry of a 1.5-unit sphere
// meeting a surface atom at z = 0. What is not calibrated (the force-depth curve of fig. 6-3,
// the shapes and time scales) is compared in docs/thesis-comparison.md.
TEST(RunCli, PalpationKeepsItsCalibratedOnsetAndPeakOnTheThesisPreset) {
  const std::string csv = testing::TempDir() + "/palpate.csv";
  const Output out = RunSim("run --preset thesis --model " + kHex + " --script palpate --csv " + csv + " --json");
  ASSERT_EQ(out.status, 0) << out.text;
  const auto j = nlohmann::json::parse(out.text);
  EXPECT_EQ(j["integrator"], "euler");
  EXPECT_EQ(j["local_radius"].get<double>(), 2.25);
  EXPECT_NEAR(j["onset_z"].get<double>(), 1.5, 0.01);
  EXPECT_NEAR(j["max_fz"].get<double>(), 1.7, 0.15);
  EXPECT_EQ(j["warnings"].get<int64_t>(), 0);
  EXPECT_EQ(j["ticks"].get<int64_t>(), 5500);
  // Figure 6-3: the loading curve is close to linear.
  EXPECT_GT(j["stiffness_fit"]["r2"].get<double>(), 0.95);
  EXPECT_GT(j["stiffness_fit"]["k"].get<double>(), 0);

  std::ifstream in(csv);
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header, "t,x,y,z,fx,fy,fz,active_atoms,substeps,compute_us");
  int64_t rows = 0;
  for (std::string line; std::getline(in, line);) ++rows;
  EXPECT_EQ(rows, 5500);
}

// Every entry point steps with the error-against-run-time choice unless told otherwise: symplectic
// Euler with a window of 2 tool radii; --integrator and --local-radius still win over the preset.
TEST(RunCli, TheDefaultStepIsSymplecticEulerWithTwoRadiiAndOptionsWin) {
  Output out = RunSim("run --model " + kHex + " --script palpate --json");
  ASSERT_EQ(out.status, 0) << out.text;
  auto j = nlohmann::json::parse(out.text);
  EXPECT_EQ(j["preset"], "default");
  EXPECT_EQ(j["integrator"], "symplectic");
  EXPECT_EQ(j["local_radius"].get<double>(), 3.0);
  EXPECT_EQ(j["warnings"].get<int64_t>(), 0);
  EXPECT_NEAR(j["onset_z"].get<double>(), 1.5, 0.01);  // geometry, whatever the step
  out = RunSim("run --preset thesis --integrator rk4 --tool sphere:r=1 --model " + kHex + " --script palpate --json");
  ASSERT_EQ(out.status, 0) << out.text;
  j = nlohmann::json::parse(out.text);
  EXPECT_EQ(j["integrator"], "rk4");
  EXPECT_EQ(j["local_radius"].get<double>(), 1.5) << "1.5 radii of the r = 1 sphere";
}

// docs/figures (scripts/thesis-figures.sh) are the thesis preset's: every figure in their JSON but
// the timings comes out the same to the last bit.
TEST(RunCli, TheThesisPresetReproducesDocsFigures) {
  for (const char* script : {"palpate", "stroke-slow", "stroke-fast", "pluck"}) {
    std::ifstream in(std::string(IDMS_SOURCE_DIR) + "/docs/figures/" + script + ".json");
    ASSERT_TRUE(in) << script;
    nlohmann::json expected = nlohmann::json::parse(in);
    const Output out = RunSim(std::string("run --preset thesis --model ") + kHex + " --script " + script + " --json");
    ASSERT_EQ(out.status, 0) << out.text;
    nlohmann::json got = nlohmann::json::parse(out.text);
    for (const char* timing : {"compute_us", "compute_cpu_us", "element_updates_per_s"}) {
      expected.erase(timing), got.erase(timing);
    }
    EXPECT_EQ(got, expected) << script;
  }
}

// The strokes at the thesis's speeds (6.1.2): the fast one crosses three times and each crossing
// reaches the text's "almost 2 N" of |f_x| with f_y up "dramatically" from the slow stroke's; the
// slow one's f_x opposes the motion while accelerating; the mean f_z stays "similar".
TEST(RunCli, TheStrokesAtTheThesisSpeedsGiveItsLateralForces) {
  const auto run = [](const char* script) {
    const Output out = RunSim(std::string("run --preset thesis --model ") + kHex + " --script " + script + " --json");
    EXPECT_EQ(out.status, 0) << out.text;
    return nlohmann::json::parse(out.text);
  };
  const auto slow = run("stroke-slow"), fast = run("stroke-fast"), gentle = run("stroke-gentle");
  ASSERT_EQ(slow["crossings"].size(), 1u);
  ASSERT_EQ(fast["crossings"].size(), 3u);
  ASSERT_EQ(gentle["crossings"].size(), 1u);
  EXPECT_LT(slow["crossings"][0]["mean_fx_accelerating"].get<double>(), 0);
  for (const auto& c : fast["crossings"]) {
    EXPECT_GT(c["max_abs_fx"].get<double>(), 1.6);
    EXPECT_LT(c["max_abs_fx"].get<double>(), 2.1);
    EXPECT_GT(c["max_abs_fy"].get<double>(), 2 * slow["crossings"][0]["max_abs_fy"].get<double>());
    EXPECT_NEAR(c["mean_fz"].get<double>(), slow["crossings"][0]["mean_fz"].get<double>(), 0.35);
  }
  // Thirteen times slower, the gentle stroke's lateral force is the discrete surface's alone.
  EXPECT_LT(gentle["crossings"][0]["max_abs_fx"].get<double>(), 0.4);
  for (const auto* j : {&slow, &fast, &gentle}) EXPECT_EQ((*j)["warnings"].get<int64_t>(), 0);
}

TEST(RunCli, PluckForceDropsToZeroWhenTheTweezersOpen) {
  const std::string csv = testing::TempDir() + "/pluck.csv";
  const Output out = RunSim("run --model " + kHex + " --script pluck --csv " + csv + " --json");
  ASSERT_EQ(out.status, 0) << out.text;
  // Thesis 6.1.3 / fig. 6-8: pulled up while grasped (f_z < 0 on the device), zero after opening at t = 4 s.
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);
  double min_fz_held = 0, max_abs_after = 0;
  int64_t rows_after = 0;
  while (std::getline(in, line)) {
    double t, x, y, z, fx, fy, fz;
    ASSERT_EQ(std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf,%lf,%lf,%lf", &t, &x, &y, &z, &fx, &fy, &fz), 7);
    if (t > 3.0 && t < 3.99) min_fz_held = std::min(min_fz_held, fz);
    if (t > 4.01) ++rows_after, max_abs_after = std::max({max_abs_after, std::abs(fx), std::abs(fy), std::abs(fz)});
  }
  EXPECT_LT(min_fz_held, -0.5);
  EXPECT_GT(rows_after, 900) << "the script runs on past the release";
  EXPECT_EQ(max_abs_after, 0.0);
}

// The pierce: a needle tilted 30 degrees goes in along its axis, punctures once, and comes out;
// while it is in, the device force resists it along its axis in the plane of the tilt.
TEST(RunCli, ThePierceGoesInAlongItsTiltedAxisOnceAndComesOut) {
  const std::string csv = testing::TempDir() + "/pierce.csv";
  const Output out = RunSim("run --model " + kHex + " --script pierce --csv " + csv + " --json");
  ASSERT_EQ(out.status, 0) << out.text;
  const nlohmann::json j = nlohmann::json::parse(out.text);
  EXPECT_EQ(j["needle"]["punctures"], 1) << j.dump();
  EXPECT_GT(j["needle"]["punctured_s"].get<double>(), 1.0);
  EXPECT_LT(j["needle"]["punctured_s"].get<double>(), 6.5);
  EXPECT_GT(j["needle"]["max_inserted"].get<double>(), 1.0);
  EXPECT_FALSE(j["needle"]["inside_at_end"].get<bool>());
  EXPECT_EQ(j["warnings"], 0);
  // At the deepest hold (6.5-7.5 s) the force points back up the axis (-sin 30, 0, cos 30).
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);
  int held = 0;
  while (std::getline(in, line)) {
    double t, x, y, z, fx, fy, fz;
    ASSERT_EQ(std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf,%lf,%lf,%lf", &t, &x, &y, &z, &fx, &fy, &fz), 7);
    if (t < 6.6 || t > 7.4) continue;
    // In the plane of the tilt (y: the captured atoms' lateral pull, uneven on this mesh).
    const double f = std::sqrt(fx * fx + fz * fz);
    ASSERT_GT(f, 0.5) << t;
    EXPECT_GT((-0.5 * fx + std::sqrt(0.75) * fz) / f, 0.99) << t << ": " << fx << ", " << fy << ", " << fz;
    ++held;
  }
  EXPECT_GT(held, 700);
}

// The stitch: the needle goes in once, out through the bottom, is drawn through, and leaves its
// thread in the entry and the exit; the button ties it; the summary says so.
TEST(RunCli, TheStitchDrawsTheThreadThroughAndTiesIt) {
  const Output out = RunSim("run --model " + kHex + " --script stitch --json");
  ASSERT_EQ(out.status, 0) << out.text;
  const nlohmann::json j = nlohmann::json::parse(out.text);
  EXPECT_EQ(j["needle"]["punctures"], 1) << j.dump();
  EXPECT_EQ(j["needle"]["exits"], 1);
  EXPECT_EQ(j["needle"]["drawn_through"], 1);
  EXPECT_FALSE(j["needle"]["inside_at_end"].get<bool>());
  EXPECT_EQ(j["suture"]["punctures"], 2);
  EXPECT_EQ(j["suture"]["ties"], 1);
  EXPECT_EQ(j["suture"]["ties_refused"], 0);
  EXPECT_EQ(j["suture"]["breaks"], 0);
  EXPECT_EQ(j["suture"]["nodes"], 65);
  EXPECT_GT(j["suture"]["max_tension"].get<double>(), 1.8);  // the knot at its tie force, 2
  EXPECT_EQ(j["warnings"], 0);
  // A needle's script refuses another tool.
  EXPECT_NE(RunSim("run --model " + kHex + " --script stitch --tool sphere:r=1").status, 0);
}

// The suture (issue 32) on the shipped soft slab: the scalpel opens an incision through the slab,
// the needle places three stitches across it and ties each; the stitched rows' gap falls from its
// open width to at most a tenth of it and stays there while the hand holds still for 5 s. The CSV
// carries the gap per tick.
TEST(RunCli, TheSutureClosesTheIncisionItMade) {
  const std::string csv = testing::TempDir() + "/suture.csv";
  const Output out = RunSim("run --model " + std::string(IDMS_SOURCE_DIR) +
                            "/models/suture_slab --script suture --csv " + csv + " --json");
  ASSERT_EQ(out.status, 0) << out.text;
  const nlohmann::json j = nlohmann::json::parse(out.text);
  EXPECT_EQ(j["incision"]["rows"], 7) << j.dump();
  EXPECT_GT(j["incision"]["elements_cut"].get<int>(), 20);
  const double open = j["gap_open"].get<double>();
  EXPECT_NEAR(open, 1.0, 0.05);  // the cut runs between two columns of the unit grid
  EXPECT_LE(j["gap_final"].get<double>(), 0.1 * open);
  EXPECT_LE(j["gap_widest_held"].get<double>(), 0.1 * open);
  EXPECT_GT(j["gap_incision_final"].get<double>(), j["gap_final"].get<double>());  // the unstitched ends gape
  EXPECT_EQ(j["stitches"], 3);
  EXPECT_EQ(j["ties"], 3);
  EXPECT_EQ(j["needle"]["punctures"], 6);  // down through A, up through B, three times
  EXPECT_EQ(j["needle"]["drawn_through"], 6);
  EXPECT_EQ(j["suture"]["punctures"], 12);
  EXPECT_EQ(j["suture"]["breaks"], 0);
  EXPECT_EQ(j["warnings"], 0);
  // The hand feels the thread through the eye's spring, the needle's lateral stiffness (3), not the
  // holes' (30, 1.16 N steps): a regression guard on the steps (issue 32's goal, 0.102 N, is not met).
  EXPECT_LT(j["needle"]["max_force_step"].get<double>(), 0.6);
  // The gap column: open when the needle first comes, closed at the end.
  std::ifstream in(csv);
  std::string header, line, last;
  std::getline(in, header);
  EXPECT_EQ(header.substr(header.rfind(',') + 1), "gap");
  while (std::getline(in, line)) last = line;
  EXPECT_NEAR(std::stod(last.substr(last.rfind(',') + 1)), j["gap_final"].get<double>(), 1e-5);
}

TEST(RunCli, EveryIntegratorRunsTheStrokeWithoutWarnings) {
  for (const char* integrator : {"euler", "symplectic", "rk4", "implicit"}) {
    const Output out = RunSim("run --model " + kHex + " --script stroke-slow --integrator " + integrator + " --json");
    ASSERT_EQ(out.status, 0) << integrator << ": " << out.text;
    const auto j = nlohmann::json::parse(out.text);
    EXPECT_EQ(j["warnings"].get<int64_t>(), 0) << integrator;
    EXPECT_GT(j["max_fz"].get<double>(), 0.5) << integrator;
  }
}

TEST(RunCli, BadArgumentsAreClearErrors) {
  Output out = RunSim("run --model " + kHex + " --script poke");
  EXPECT_NE(out.status, 0);
  EXPECT_NE(
      out.text.find(
          "--script 'poke': expected palpate, stroke-slow, stroke-fast, pluck, stroke-gentle, scan, pierce, stitch, "
          "suture or drag[:fraction=F,...]"),
      std::string::npos)
      << out.text;
  out = RunSim("run --model " + kHex + " --tool sphere:r=-1");
  EXPECT_NE(out.status, 0);
  EXPECT_NE(out.text.find("bad item 'r=-1'"), std::string::npos) << out.text;
  out = RunSim("run --model /nonexistent/model");
  EXPECT_NE(out.status, 0);
  EXPECT_NE(out.text.find("/nonexistent/model.fem: cannot open: no such file"), std::string::npos) << out.text;
  out = RunSim("run --model " + kHex + " --full --local-radius 3");
  EXPECT_NE(out.status, 0);
  EXPECT_NE(out.text.find("--local-radius excludes --full"), std::string::npos) << out.text;
  out = RunSim("run --model " + kHex + " --preset fast");
  EXPECT_NE(out.status, 0);
  EXPECT_NE(out.text.find("--preset 'fast': expected default or thesis"), std::string::npos) << out.text;
  out = RunSim("run --model " + kHex + " --local-radius 1");
  EXPECT_NE(out.status, 0);
  EXPECT_NE(out.text.find("expected at least the tool's radius"), std::string::npos) << out.text;
}

}  // namespace

namespace {

// Friction on the command line (issue 30): the drag script holds below mu_s f_n and slides above
// it, the CSV adds its columns after the ten, and bad coefficients are refused by name.
TEST(RunCli, DragHoldsBelowMuSAndSlidesAboveWithFrictionColumns) {
  const std::string csv = testing::TempDir() + "/drag.csv";
  Output out =
      RunSim("run --model " + kHex + " --script drag:fraction=0.5 --tool sphere:mu_s=0.6,mu_d=0.4 --json --csv " + csv);
  ASSERT_EQ(out.status, 0) << out.text;
  auto j = nlohmann::json::parse(out.text);
  EXPECT_EQ(j["friction"]["slip_ticks"].get<int64_t>(), 0);
  EXPECT_GT(j["friction"]["stick_ticks"].get<int64_t>(), 10000);
  std::ifstream in(csv);
  std::string header, line, last;
  std::getline(in, header);
  EXPECT_EQ(header, "t,x,y,z,fx,fy,fz,active_atoms,substeps,compute_us,ftx,fty,ftz,ft,fn,friction");
  while (std::getline(in, line)) last = line;
  EXPECT_EQ(last.substr(last.rfind(',') + 1), "stick");

  out = RunSim("run --model " + kHex + " --script drag:fraction=1.3 --tool sphere:mu_s=0.6,mu_d=0.4 --json");
  ASSERT_EQ(out.status, 0) << out.text;
  j = nlohmann::json::parse(out.text);
  EXPECT_GT(j["friction"]["slip_ticks"].get<int64_t>(), 5000);
  EXPECT_LE(j["friction"]["work_max_running_sum"].get<double>(), 1e-9);

  out = RunSim("run --model " + kHex + " --script stroke-slow --tool sphere:mu_s=0.4,mu_d=0.6");
  EXPECT_NE(out.status, 0);
  EXPECT_NE(out.text.find("mu_d must be <= mu_s (0.4), got 0.6"), std::string::npos) << out.text;
  out = RunSim("run --model " + kHex + " --script stroke-slow --tool sphere:mu_s=-1");
  EXPECT_NE(out.text.find("mu_s must be a finite number >= 0, got -1"), std::string::npos) << out.text;
  out = RunSim("run --model " + kHex + " --script stroke-slow --tool sphere:mu_s=nan");
  EXPECT_NE(out.text.find("bad item 'mu_s=nan'"), std::string::npos) << out.text;
  out = RunSim("run --model " + kHex + " --script drag:fraction=-1 --tool sphere:mu_s=0.5");
  EXPECT_NE(out.text.find("bad item 'fraction=-1'"), std::string::npos) << out.text;
}

// Every column of a CSV but compute_us (the 10th, how long the tick took).
std::string WithoutTimes(const std::string& path) {
  std::ifstream in(path);
  std::string line, out;
  while (std::getline(in, line)) {
    size_t at = 0;
    for (int comma = 0; comma < 9 && at != std::string::npos; ++comma) at = line.find(',', at + 1);
    out += line.substr(0, at) + "\n";
  }
  return out;
}

TEST(RunCli, FullModeOnSeveralThreadsGivesOneThreadsColumns) {
  const std::string dir = testing::TempDir();
  ASSERT_EQ(RunSim("generate slab --rows 24 --cols 24 --out " + dir + "/t_slab").status, 0);
  ASSERT_EQ(RunSim("reorder --model " + dir + "/t_slab --out " + dir + "/t_ordered").status, 0);
  std::string columns[2];
  for (const int threads : {1, 2}) {
    const std::string csv = dir + "/threads" + std::to_string(threads) + ".csv";
    const Output out = RunSim("run --model " + dir + "/t_ordered --full --threads " + std::to_string(threads) +
                              " --script palpate --ticks 2800 --json --csv " + csv);
    ASSERT_EQ(out.status, 0) << out.text;
    const auto j = nlohmann::json::parse(out.text);
    EXPECT_EQ(j["threads"], threads);
    EXPECT_GT(j["element_updates_per_s"].get<double>(), 0);
    EXPECT_GT(j["max_force"].get<double>(), 0.01) << "the press touched nothing";
    columns[threads - 1] = WithoutTimes(csv);
  }
  EXPECT_GT(columns[0].size(), 2800u * 20);
  EXPECT_EQ(columns[1], columns[0]);
  // --threads is full mode's.
  EXPECT_NE(RunSim("run --model " + dir + "/t_ordered --threads 2 --script pluck").status, 0);
  EXPECT_NE(RunSim("run --model " + dir + "/t_ordered --full --threads 0 --script pluck").status, 0);
}

}  // namespace
