// Tests of the haptic-window stability analysis (thesis 4.2, eqs. 4.16-4.18) and of
// `idms-sim stability`, run as a real process.
#include "idms/sim/haptic_window.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>

#include "idms/sim/stability.h"

namespace idms {
namespace {

// Explicit Euler leaves the circle when the fastest overdamped mode of the window does.
// The window's modes are those of tridiag(-1, 3, -1): mu = 3 - sqrt(2), 3, 3 + sqrt(2), each an
// oscillator with omega^2 = k mu / m, c = b mu / m. Jury on z^2 - (2 - cT) z + 1 - cT + omega^2 T^2
// gives 4 - 2 c T + omega^2 T^2 > 0 and T < b / k; the first fails first for the nominal values:
// T* = (b - sqrt(b^2 - 4 k m / mu)) / k with mu = 3 + sqrt(2).
double ClosedFormEulerEdgeDt(const HapticWindowParams& p) {
  const double mu = 3 + std::sqrt(2.0);
  return (p.b - std::sqrt(p.b * p.b - 4 * p.k * p.m / mu)) / p.k;
}

double Radius(const Eigen::MatrixXd& a, Integrator integrator, double dt_s) {
  return AnalyzeStability(a, integrator, dt_s).spectral_radius;
}

Eigen::MatrixXd Oscillator(double omega2, double c) {
  Eigen::MatrixXd a(2, 2);
  a << 0, 1, -omega2, -c;
  return a;
}

TEST(HapticWindowTest, AMatchesEq417) {
  const HapticWindowParams p{.k = 15, .b = 0.45, .m = 0.002, .dt_s = 0.001};
  const double km = 7500, bm = 225;
  Eigen::MatrixXd expected(6, 6);
  expected << 0, 1, 0, 0, 0, 0,          //
      -3 * km, -3 * bm, km, bm, 0, 0,    //
      0, 0, 0, 1, 0, 0,                  //
      km, bm, -3 * km, -3 * bm, km, bm,  //
      0, 0, 0, 0, 0, 1,                  //
      0, 0, km, bm, -3 * km, -3 * bm;
  const Eigen::MatrixXd a = HapticWindowA(p);
  for (int i = 0; i < 6; ++i) {
    for (int j = 0; j < 6; ++j) EXPECT_NEAR(a(i, j), expected(i, j), 1e-12 * km) << "entry " << i << "," << j;
  }
}

TEST(HapticWindowTest, ContinuousEigenvaluesAreTheThreeModes) {
  // Nominal: every mode is overdamped (zeta = b sqrt(mu) / (2 sqrt(k m)) >= 1.6), so all real.
  const HapticWindowParams p;
  const StabilityReport r = AnalyzeHapticWindow(p, Integrator::kExplicitEuler);
  ASSERT_EQ(r.continuous.size(), 6u);
  std::multiset<double> expected;
  for (double mu : {3 - std::sqrt(2.0), 3.0, 3 + std::sqrt(2.0)}) {
    const double c = p.b * mu / p.m, w2 = p.k * mu / p.m, s = std::sqrt(c * c / 4 - w2);
    expected.insert(-c / 2 + s), expected.insert(-c / 2 - s);
  }
  auto it = expected.begin();
  std::multiset<double> got;
  for (const auto& l : r.continuous) {
    got.insert(l.real());
    EXPECT_NEAR(l.imag(), 0, 1e-9);
  }
  for (double g : got) EXPECT_NEAR(g, *it++, 1e-8 * 1000);
}

TEST(HapticWindowTest, NominalEulerIsStable) {
  const StabilityReport r = AnalyzeHapticWindow(HapticWindowParams{}, Integrator::kExplicitEuler);
  EXPECT_TRUE(r.stable);
  EXPECT_NEAR(r.spectral_radius, 0.965466, 1e-6);
  // eq. 4.18: every discrete pole is 1 + lambda T for some continuous lambda.
  for (const auto& lambda : r.continuous) {
    double nearest = 1e300;
    for (const auto& z : r.discrete) nearest = std::min(nearest, std::abs(z - (1.0 + lambda * 0.001)));
    EXPECT_LT(nearest, 1e-12) << lambda;
  }
}

TEST(HapticWindowTest, EulerIsUnstablePastTheClosedFormEdge) {
  HapticWindowParams p;
  const double edge = ClosedFormEulerEdgeDt(p);
  EXPECT_NEAR(edge, 0.00208624, 1e-8);
  p.dt_s = edge * 1.01;
  EXPECT_FALSE(AnalyzeHapticWindow(p, Integrator::kExplicitEuler).stable);
  p.dt_s = edge * 0.99;
  EXPECT_TRUE(AnalyzeHapticWindow(p, Integrator::kExplicitEuler).stable);
}

TEST(HapticWindowTest, BisectedEdgeMatchesEigenvalueEdge) {
  const HapticWindowParams p;
  const Eigen::MatrixXd a = HapticWindowA(p);
  const double bisected = StabilityLimitDt(a, Integrator::kExplicitEuler, 1.0);
  const double from_eigenvalues = EulerEdgeDt(AnalyzeStability(a, Integrator::kExplicitEuler, p.dt_s).continuous);
  EXPECT_NEAR(bisected, from_eigenvalues, 1e-7 * from_eigenvalues);
  EXPECT_NEAR(from_eigenvalues, ClosedFormEulerEdgeDt(p), 1e-10 * from_eigenvalues);
  // At the edge the fastest pole sits on z = -1.
  EXPECT_NEAR(Radius(a, Integrator::kExplicitEuler, from_eigenvalues), 1.0, 1e-9);
}

TEST(HapticWindowTest, StiffnessEdgeIsBOverT) {
  // Underdamped modes: |z|^2 = 1 - c T (1 - k T / b), so every mode reaches the circle at k = b / T.
  const HapticWindowParams nominal;
  const auto stable_at = [&](double k) {
    HapticWindowParams p = nominal;
    p.k = k;
    return AnalyzeHapticWindow(p, Integrator::kExplicitEuler).stable;
  };
  const std::vector<StabilityEdge> edges = FindStabilityEdges(stable_at, 15, 1000, 101);
  ASSERT_EQ(edges.size(), 1u);
  EXPECT_FALSE(edges[0].stable_above);
  EXPECT_NEAR(edges[0].value, nominal.b / nominal.dt_s, 1e-4);
}

TEST(HapticWindowTest, SymplecticOneDofEdgeIsStabilityHClosedForm) {
  for (const AtomBound bound : {AtomBound{1e4, 0}, AtomBound{7500, 50}, AtomBound{33107, 993}}) {
    const Eigen::MatrixXd a = Oscillator(bound.omega2, bound.c);
    const double t = SymplecticStableDt(bound);
    // The one-step matrix by hand: v' = (1 - cT) v - w2 T x, x' = x + T v'.
    const Eigen::MatrixXd m = OneStepMatrix(a, Integrator::kSymplecticEuler, t);
    EXPECT_NEAR(m(0, 0), 1 - bound.omega2 * t * t, 1e-12);
    EXPECT_NEAR(m(0, 1), t * (1 - bound.c * t), 1e-12);
    EXPECT_NEAR(m(1, 0), -bound.omega2 * t, 1e-9);
    EXPECT_NEAR(m(1, 1), 1 - bound.c * t, 1e-12);
    // On the boundary a pole sits at z = -1; just inside it is stable, just outside it is not.
    EXPECT_NEAR(Radius(a, Integrator::kSymplecticEuler, t), 1.0, 1e-9) << "omega2 " << bound.omega2;
    // Inside: det = 1 - cT, so undamped poles stay on the circle (marginal), damped ones inside.
    if (bound.c > 0) {
      EXPECT_TRUE(AnalyzeStability(a, Integrator::kSymplecticEuler, 0.999 * t).stable);
    } else {
      EXPECT_NEAR(Radius(a, Integrator::kSymplecticEuler, 0.999 * t), 1.0, 1e-9);
    }
    EXPECT_GT(Radius(a, Integrator::kSymplecticEuler, 1.001 * t), 1.0);
  }
}

TEST(HapticWindowTest, EulerOneDofEdgeIsStabilityHClosedForm) {
  // Underdamped (c^2 < 4 w2) and overdamped branches of EulerStableDt.
  for (const AtomBound bound : {AtomBound{1e4, 50}, AtomBound{33107, 993}}) {
    const Eigen::MatrixXd a = Oscillator(bound.omega2, bound.c);
    const double t = EulerStableDt(bound);
    EXPECT_NEAR(Radius(a, Integrator::kExplicitEuler, t), 1.0, 1e-9);
    EXPECT_NEAR(EulerEdgeDt(AnalyzeStability(a, Integrator::kExplicitEuler, t).continuous), t, 1e-12);
  }
}

TEST(HapticWindowTest, SymplecticWindowMatchesAHandStep) {
  const HapticWindowParams p{.k = 120, .b = 0.2, .m = 0.0015, .dt_s = 0.0007};
  const Eigen::MatrixXd a = HapticWindowA(p);
  Eigen::VectorXd x(6);
  x << 0.3, -1.0, 0.7, 2.0, -0.4, 0.5;
  // Velocities first from the old state (odd rows of A x), then positions with the new velocity.
  const Eigen::VectorXd ax = a * x;
  Eigen::VectorXd expected = x;
  for (int i = 0; i < 3; ++i) expected(2 * i + 1) = x(2 * i + 1) + p.dt_s * ax(2 * i + 1);
  for (int i = 0; i < 3; ++i) expected(2 * i) = x(2 * i) + p.dt_s * expected(2 * i + 1);
  const Eigen::VectorXd got = OneStepMatrix(a, Integrator::kSymplecticEuler, p.dt_s) * x;
  EXPECT_LT((got - expected).norm(), 1e-12);
}

TEST(HapticWindowTest, Rk4AndImplicitMatrices) {
  const HapticWindowParams p;
  const Eigen::MatrixXd at = HapticWindowA(p) * p.dt_s;
  const Eigen::MatrixXd id = Eigen::MatrixXd::Identity(6, 6);
  const Eigen::MatrixXd at2 = at * at, at3 = at2 * at, at4 = at3 * at;
  const Eigen::MatrixXd rk4 = id + at + at2 / 2 + at3 / 6 + at4 / 24;
  EXPECT_LT((OneStepMatrix(HapticWindowA(p), Integrator::kRk4, p.dt_s) - rk4).norm(), 1e-12);
  EXPECT_LT(((id - at) * OneStepMatrix(HapticWindowA(p), Integrator::kImplicitEuler, p.dt_s) - id).norm(), 1e-12);
}

TEST(HapticWindowTest, ImplicitIsStableForHugeSteps) {
  for (double dt : {0.01, 1.0, 1e3, 1e6}) {
    HapticWindowParams p;
    p.dt_s = dt;
    p.k = 1e5;
    EXPECT_TRUE(AnalyzeHapticWindow(p, Integrator::kImplicitEuler).stable) << "dt " << dt;
  }
  EXPECT_TRUE(std::isinf(StabilityLimitDt(HapticWindowA(HapticWindowParams{}), Integrator::kImplicitEuler, 1e3)));
}

TEST(HapticWindowTest, EigensolverConvergesWhereEigenDefaultsDoNot) {
  // Eigen's default iteration limit gives up on this RK4 matrix (found by a k sweep).
  HapticWindowParams p;
  p.k = 1 + 1999.0 * 77 / 399;
  const StabilityReport r = AnalyzeHapticWindow(p, Integrator::kRk4);
  EXPECT_TRUE(std::isfinite(r.spectral_radius));
  EXPECT_NEAR(r.spectral_radius, 0.836999, 1e-6);
  EXPECT_TRUE(r.stable);
}

TEST(HapticWindowTest, UnitCircleCountsAsUnstable) {
  // k = b = 0: every pole at z = 1 (a free, drifting mass), radius exactly 1.
  const StabilityReport r =
      AnalyzeHapticWindow({.k = 0, .b = 0, .m = 0.002, .dt_s = 0.001}, Integrator::kExplicitEuler);
  EXPECT_DOUBLE_EQ(r.spectral_radius, 1.0);
  EXPECT_FALSE(r.stable);
  EXPECT_FALSE(IsStableRadius(1.0 - kMarginalTol / 2));
  EXPECT_TRUE(IsStableRadius(1.0 - 2 * kMarginalTol));
}

TEST(HapticWindowTest, GershgorinPredictionIsTheMiddleRowBound) {
  // The middle mass's row: centre 3k/m, radius 2k/m (and the same for b) -> omega2 = 5k/m, c = 5b/m.
  const HapticWindowParams p;
  const AtomBound middle{5 * p.k / p.m, 5 * p.b / p.m};
  EXPECT_NEAR(*GershgorinStableDt(p, Integrator::kExplicitEuler), EulerStableDt(middle), 1e-15);
  EXPECT_NEAR(*GershgorinStableDt(p, Integrator::kSymplecticEuler), SymplecticStableDt(middle), 1e-15);
  EXPECT_FALSE(GershgorinStableDt(p, Integrator::kRk4).has_value());
  // Here mu = 5 bounds the true 3 + sqrt(2), so the prediction is conservative.
  EXPECT_LT(*GershgorinStableDt(p, Integrator::kExplicitEuler), ClosedFormEulerEdgeDt(p));
}

// ---- idms-sim stability as a process ----

struct RunResult {
  int exit_code = -1;
  std::string out, err;
};

std::string ReadAll(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

class StabilityCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("idms_stability_" + std::string(info->name()) + "_" + std::to_string(getpid()));
    std::filesystem::create_directories(dir_);
    ASSERT_TRUE(std::filesystem::exists(kBin)) << kBin << " is missing: build the idms-sim target first";
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  // Runs `env idms-sim args` with stdout and stderr captured in files under dir_.
  RunResult Run(const std::string& args, const std::string& env = "") const {
    const std::string out = (dir_ / "stdout").string(), err = (dir_ / "stderr").string();
    const std::string cmd = env + " '" + kBin + "' " + args + " >'" + out + "' 2>'" + err + "'";
    const int status = std::system(cmd.c_str());
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, ReadAll(out), ReadAll(err)};
  }

  static inline const std::string kBin = IDMS_BIN_DIR "/idms-sim";
  std::filesystem::path dir_;
};

TEST_F(StabilityCliTest, JsonHasExactlyTheDocumentedKeys) {
  const RunResult r = Run("stability --k 15 --b 0.45 --m 0.002 --dt 0.001 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  std::set<std::string> keys;
  for (const auto& item : j.items()) keys.insert(item.key());
  EXPECT_EQ(keys, (std::set<std::string>{"integrator", "eigenvalues", "continuous_eigenvalues", "spectral_radius",
                                         "stable"}));
  EXPECT_EQ(j["integrator"], "euler");
  ASSERT_EQ(j["eigenvalues"].size(), 6u);
  for (const auto& pair : j["eigenvalues"]) EXPECT_EQ(pair.size(), 2u);
  EXPECT_NEAR(j["spectral_radius"].get<double>(), 0.965466, 1e-6);
  EXPECT_TRUE(j["stable"].get<bool>());
}

TEST_F(StabilityCliTest, UnstableAndImplicitVerdicts) {
  const nlohmann::json unstable = nlohmann::json::parse(Run("stability --dt 0.0025 --json").out);
  EXPECT_FALSE(unstable["stable"].get<bool>());
  EXPECT_GT(unstable["spectral_radius"].get<double>(), 1.0);
  const nlohmann::json implicit = nlohmann::json::parse(Run("stability --dt 10 --integrator implicit --json").out);
  EXPECT_EQ(implicit["integrator"], "implicit");
  EXPECT_TRUE(implicit["stable"].get<bool>());
}

TEST_F(StabilityCliTest, EveryIntegratorName) {
  for (const char* name : {"euler", "symplectic", "rk4", "implicit"}) {
    const RunResult r = Run(std::string("stability --integrator ") + name + " --json");
    ASSERT_EQ(r.exit_code, 0) << name << ": " << r.err;
    EXPECT_EQ(nlohmann::json::parse(r.out)["integrator"], name);
  }
}

TEST_F(StabilityCliTest, BadInputFailsWithAMessage) {
  const std::pair<const char*, const char*> cases[] = {
      {"stability --m 0", "--m must be > 0"},
      {"stability --m -0.002", "--m must be > 0"},
      {"stability --dt -1", "--dt must be > 0"},
      {"stability --k -15", "--k must be >= 0"},
      {"stability --b -0.1", "--b must be >= 0"},
      {"stability --integrator leapfrog", "unknown --integrator 'leapfrog'"},
      {"stability --sweep q 1 2 --out x", "must be one of k, b, m, dt"},
      {"stability --sweep k 400 15 --out x", "FROM < TO"},
      {"stability --sweep m 0 0.002 --out x", "--m must be > 0"},
      {"stability --sweep k 15 400", "needs --out"},
  };
  for (const auto& [args, message] : cases) {
    const RunResult r = Run(args);
    EXPECT_NE(r.exit_code, 0) << args;
    EXPECT_NE(r.err.find(message), std::string::npos) << args << " -> stderr: " << r.err;
    EXPECT_TRUE(r.out.empty()) << args;
  }
}

TEST_F(StabilityCliTest, SweepWritesCsvAndPng) {
  const std::string prefix = (dir_ / "k").string();
  const RunResult r = Run("stability --sweep k 15 1000 --steps 21 --json --out '" + prefix + "'");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // One row per value and eigenvalue, after a header naming the swept parameter.
  std::ifstream csv(prefix + ".csv");
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  EXPECT_EQ(line, "k,index,re,im,abs_z,spectral_radius,stable");
  int rows = 0;
  while (std::getline(csv, line)) ++rows;
  EXPECT_EQ(rows, 21 * 6);
  EXPECT_GT(std::filesystem::file_size(prefix + ".png"), 1000u);
  // The summary finds the k = b / T = 450 edge.
  const nlohmann::json j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j["edges"].size(), 1u);
  EXPECT_NEAR(j["edges"][0]["value"].get<double>(), 450.0, 1e-3);
}

TEST_F(StabilityCliTest, MissingGnuplotStillWritesTheCsv) {
  const std::string prefix = (dir_ / "b").string();
  const RunResult r = Run("stability --sweep b 0.1 0.9 --steps 5 --out '" + prefix + "'",
                          "IDMS_GNUPLOT=" + (dir_ / "no-such-gnuplot").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(std::filesystem::exists(prefix + ".csv"));
  EXPECT_FALSE(std::filesystem::exists(prefix + ".png"));
  EXPECT_NE(r.err.find("gnuplot not found"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace idms
