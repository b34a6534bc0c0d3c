// idms-sim run, end to end: the real binary on the shipped hex fragment reproduces the thesis's
// palpation onset and peak, writes the documented CSV, and rejects bad arguments.
#include <cstdio>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

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

TEST(RunCli, PalpationReproducesThesisOnsetAndPeak) {
  const std::string csv = testing::TempDir() + "/palpate.csv";
  const Output out = RunSim("run --model " + kHex + " --script palpate --csv " + csv + " --json");
  ASSERT_EQ(out.status, 0) << out.text;
  const auto j = nlohmann::json::parse(out.text);
  // Thesis 6.1.1: f_z becomes nonzero at z ~ 1.5 (the MIO radius) and peaks near 1.7 N.
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

TEST(RunCli, PluckForceDropsToZeroWhenTheTweezersOpen) {
  const std::string csv = testing::TempDir() + "/pluck.csv";
  const Output out = RunSim("run --model " + kHex + " --script pluck --csv " + csv + " --json");
  ASSERT_EQ(out.status, 0) << out.text;
  // Thesis 6.1.3 / fig. 6-8: pulled up while grasped (f_z < 0 on the device), zero after opening at t = 4 s.
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);
  double min_fz_held = 0, max_abs_after = 0;
  while (std::getline(in, line)) {
    double t, x, y, z, fx, fy, fz;
    ASSERT_EQ(std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf,%lf,%lf,%lf", &t, &x, &y, &z, &fx, &fy, &fz), 7);
    if (t > 3.0 && t < 3.99) min_fz_held = std::min(min_fz_held, fz);
    if (t > 4.01) max_abs_after = std::max({max_abs_after, std::abs(fx), std::abs(fy), std::abs(fz)});
  }
  EXPECT_LT(min_fz_held, -0.5);
  EXPECT_EQ(max_abs_after, 0.0);
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
  EXPECT_NE(out.text.find("--script 'poke': expected palpate, stroke-slow, stroke-fast or pluck"), std::string::npos) << out.text;
  out = RunSim("run --model " + kHex + " --tool sphere:r=-1");
  EXPECT_NE(out.status, 0);
  EXPECT_NE(out.text.find("bad item 'r=-1'"), std::string::npos) << out.text;
  out = RunSim("run --model /nonexistent/model");
  EXPECT_NE(out.status, 0);
  EXPECT_NE(out.text.find("/nonexistent/model.fem: cannot open: no such file"), std::string::npos) << out.text;
  out = RunSim("run --model " + kHex + " --full --local-radius 3");
  EXPECT_NE(out.status, 0);
}

}  // namespace
