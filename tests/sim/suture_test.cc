// The needle through the far side and the suture thread (sim/src/suture.cc, issue 32): the tip
// leaves the tissue, the needle drawn through leaves the thread in two punctures, the thread slides
// through them and its knotted end does not, a tie draws two punctures together and holds them,
// the thread parts above its strength, determinism, no allocation, bad parameters refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "alloc_counter.h"
#include "idms/sim/edit.h"
#include "idms/sim/generate.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"
#include "step_test_util.h"

namespace idms {
namespace {

// Above atom 10 of the hex fragment, (1.5, 1.732, 0): an inner atom of the top surface. The slab
// is 0.816 deep (its apex layer); nothing is below it.
constexpr double kX = 1.5, kY = 1.732;
constexpr double kTip = 0.25;  // PierceNeedle's tip radius
constexpr double kNeedleLength = 3;

// The pierce's needle (PierceNeedle), shorter and sliding more easily, drawing a thread.
ToolCommand SutureNeedle(double z, double thread_length) {
  ToolCommand c = PierceNeedle();
  c.pos[0] = kX, c.pos[1] = kY, c.pos[2] = z;
  c.axis[0] = 0, c.axis[1] = 0, c.axis[2] = -1;
  c.needle.length = kNeedleLength;
  c.needle.puncture_force = 0.5;
  c.needle.mu = 0.2;
  c.needle.grip = 0.2;
  c.suture.length = thread_length;
  c.suture.segments = 24;
  c.suture.mass = 0.01;
  c.suture.drag = 1;  // its pull while sliding at 1 unit / s: 0.01 force units
  return c;
}

struct Tick {
  double z = 0;
  double force[3] = {0, 0, 0};
  ToolReport tool;
  SutureReport suture;
};

// The needle straight down through the slab from z0 at speed v for `seconds`.
std::vector<Tick> DrawThrough(const Model& model, State& state, Workspace& ws, double z0, double speed, double seconds,
                              double thread_length, double strength = 0) {
  const double dt = ws.options.dt_s;
  const auto n = static_cast<int64_t>(std::llround(seconds / dt));
  std::vector<Tick> ticks;
  ticks.reserve(n);
  ToolInput in;
  in.num_tools = 1;
  for (int64_t i = 0; i < n; ++i) {
    Tick k;
    k.z = z0 - speed * (i + 1) * dt;
    in.tools[0] = SutureNeedle(k.z, thread_length);
    in.tools[0].suture.strength = strength;
    const StepReport r = Step(model, state, ws, in);
    k.tool = r.tools[0];
    k.suture = r.suture;
    std::copy(r.tools[0].force, r.tools[0].force + 3, k.force);
    ticks.push_back(k);
  }
  return ticks;
}

double Norm3(const double* a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); }

class SutureTest : public ::testing::Test {
 protected:
  const Model model_ = GenerateSlab(SlabOptions{});
  State state_ = MakeState(model_);
  Workspace ws_ = MakeWorkspace(model_, StepOptions{});
};

// Down through the slab: the tip punctures the top, leaves through the bottom, and the needle
// drawn on through leaves its thread in the entry and then the exit; the needle is free again.
TEST_F(SutureTest, DrawnThroughItLeavesTheThreadInTheEntryAndTheExit) {
  const double speed = 1.0;
  const std::vector<Tick> ticks = DrawThrough(model_, state_, ws_, kTip + 0.05, speed, 5.0, 6.0);
  int punctured = -1, exited = -1, through = -1, first_hole = -1;
  for (size_t i = 0; i < ticks.size(); ++i) {
    const Tick& k = ticks[i];
    if (punctured < 0 && k.tool.punctured) punctured = static_cast<int>(i);
    if (exited < 0 && k.tool.exited) exited = static_cast<int>(i);
    if (through < 0 && k.tool.drawn_through) through = static_cast<int>(i);
    if (first_hole < 0 && k.suture.new_punctures > 0) first_hole = static_cast<int>(i);
  }
  ASSERT_GT(punctured, 0);
  ASSERT_GT(exited, punctured);
  ASSERT_GT(first_hole, exited);
  ASSERT_GT(through, first_hole);
  // The tip left below the apex layer (0.816 deep) plus about the capture radius.
  EXPECT_LT(ticks[exited].z, -0.816);
  EXPECT_GT(ticks[exited].z, -0.816 - 0.7 - 0.1);
  // The entry passed when the tail reached the surface, the exit when it reached the bottom.
  EXPECT_NEAR(ticks[first_hole].z + kNeedleLength, 0, 0.2);
  EXPECT_NEAR(ticks[through].z + kNeedleLength, -0.816 - 0.35, 0.5);
  const SutureState& ss = state_.suture;
  ASSERT_EQ(ss.num_punctures, 2);
  EXPECT_FALSE(ticks.back().tool.punctured);
  EXPECT_EQ(ticks.back().suture.punctures, 2);
  // The thread runs through both: its nearest point is at each puncture (the hold's stretch small).
  for (int j = 0; j < 2; ++j) {
    double p[3], c[3];
    ASSERT_TRUE(internal::AnchorPoint(state_, ss.punctures[j].atoms, ss.punctures[j].w, p));
    const int32_t i = static_cast<int32_t>(ss.punctures[j].s);
    const double f = ss.punctures[j].s - i;
    for (int a = 0; a < 3; ++a) c[a] = (1 - f) * ss.pos[3 * i + a] + f * ss.pos[3 * (i + 1) + a];
    const double d[3] = {p[0] - c[0], p[1] - c[1], p[2] - c[2]};
    EXPECT_LT(Norm3(d), 0.05) << j;
  }
  // The entry is above the exit, and the thread slid on through both as the needle went on.
  EXPECT_GT(ss.punctures[0].s, ss.punctures[1].s);
  EXPECT_GT(ss.punctures[1].s, 1.0);
  EXPECT_EQ(TotalWarnings(state_.warnings), 0);
}

// Drawn on until its far end reaches the entry: the knotted end does not pass; the thread pulls the
// tissue after the needle and the hand feels it.
TEST_F(SutureTest, TheKnottedEndDoesNotPassAndTheHandFeelsThePull) {
  const double speed = 1.0;
  const std::vector<Tick> ticks = DrawThrough(model_, state_, ws_, kTip + 0.05, speed, 10.5, 6.0);
  const SutureState& ss = state_.suture;
  ASSERT_EQ(ss.num_punctures, 2);
  // The entry holds the thread's last node (its far end): past it nothing slides.
  EXPECT_GT(ss.punctures[0].s, ss.num_nodes - 1.05);
  double entry[3];
  ASSERT_TRUE(internal::AnchorPoint(state_, ss.punctures[0].atoms, ss.punctures[0].w, entry));
  EXPECT_LT(entry[2], -0.2);  // the top surface drawn down after the needle
  const Tick& last = ticks.back();
  EXPECT_GT(last.suture.pull, 0.5);
  EXPECT_GT(last.force[2], 0.5);  // on the hand: up, toward the tissue it drags
  EXPECT_GT(last.suture.max_tension, 0.5);
  // Before the end reached the entry the thread slid freely: almost no pull.
  const size_t sliding = static_cast<size_t>(std::llround(5.0 / ws_.options.dt_s));
  EXPECT_LT(ticks[sliding].suture.pull, 0.05) << ticks[sliding].suture.pull;
  EXPECT_FALSE(last.suture.broke);
  EXPECT_EQ(ss.broken, -1);
}

// A thread weaker than that pull parts: the event, the segment, and no pull on the hand after.
TEST_F(SutureTest, AThreadPartsAboveItsStrength) {
  const std::vector<Tick> ticks = DrawThrough(model_, state_, ws_, kTip + 0.05, 1.0, 10.5, 6.0, /*strength=*/0.3);
  int broke = -1;
  for (size_t i = 0; i < ticks.size(); ++i) {
    if (ticks[i].suture.broke) {
      EXPECT_EQ(broke, -1) << "a second break event at " << i;
      broke = static_cast<int>(i);
    }
  }
  ASSERT_GT(broke, 0);
  EXPECT_GT(ticks[broke].suture.max_tension, 0.3);
  EXPECT_GE(state_.suture.broken, 0);
  EXPECT_LT(ticks.back().suture.pull, 0.01);
  EXPECT_LT(std::fabs(ticks.back().force[2]), 0.01);
}

// A soft slab (elements and home springs a tenth of the fragment's) slit through at x = 3.75, and
// one stitch across the slit as two straight bites leave it: in at the top of side A, out through
// A's wall, in through B's wall, out at the top of B. The thread runs straight between the
// punctures (a straight needle's bites), from the needle's tail far above B down through them and
// on up out of A.
class SutureTieTest : public ::testing::Test {
 protected:
  static constexpr double kSlit = 3.75;
  static SlabOptions Soft() {
    SlabOptions o;
    o.rows = 7;
    o.cols = 8;
    o.k = 1.5;
    o.home_k = 1.5;
    return o;
  }
  void SetUp() override {
    // The slit: every element across x = kSlit removed as the scalpel's cuts are.
    for (int32_t e = 0; e < model_.num_elems; ++e) {
      const double x0 = model_.atom_pos_eq[3 * model_.elem_atoms[2 * e]];
      const double x1 = model_.atom_pos_eq[3 * model_.elem_atoms[2 * e + 1]];
      if ((x0 < kSlit) != (x1 < kSlit)) ws_.elem_cut[e] = 1, ws_.pending_cuts[ws_.num_pending_cuts++] = e;
    }
    ASSERT_GT(ApplyPendingEdits(model_, state_, ws_).elements_removed, 0);
    const double y0 = 3 * 0.866;  // a middle row
    a_top_ = Nearest({2.5, y0, 0});
    a_wall_ = Nearest({kSlit - 0.25, 2.887, -0.816}, -1);  // an apex row, both walls
    b_wall_ = Nearest({kSlit + 0.75, 2.887, -0.816}, +1);
    b_top_ = Nearest({5.0, y0, 0});
  }
  // The free atom nearest p at rest (side: -1 left of the slit only, +1 right, 0 either).
  int32_t Nearest(std::array<double, 3> p, int side = 0) const {
    int32_t best = -1;
    double best_d = 1e300;
    for (int32_t i = 0; i < model_.num_atoms; ++i) {
      const double* q = &model_.atom_pos_eq[3 * i];
      if (model_.atom_fixed[i] || (side < 0 && q[0] > kSlit) || (side > 0 && q[0] < kSlit)) continue;
      const double d = (q[0] - p[0]) * (q[0] - p[0]) + (q[1] - p[1]) * (q[1] - p[1]) + (q[2] - p[2]) * (q[2] - p[2]);
      if (d < best_d) best_d = d, best = i;
    }
    return best;
  }
  std::array<double, 3> At(int32_t atom) const {
    return {state_.atom_pos[3 * atom], state_.atom_pos[3 * atom + 1], state_.atom_pos[3 * atom + 2]};
  }
  // Lays the thread (a needle far above B), then puts it through the four punctures.
  void Stitch() {
    Step(model_, state_, ws_, Input(false));
    SutureState& ss = state_.suture;
    ASSERT_EQ(ss.num_nodes, 97);
    const std::array<double, 3> tail = {ss.pos[0], ss.pos[1], ss.pos[2]};
    const int32_t holes[4] = {b_top_, b_wall_, a_wall_, a_top_};
    std::vector<std::array<double, 3>> path = {tail};
    for (int32_t h : holes) path.push_back(At(h));
    std::array<double, 3> up = At(a_top_);
    up[2] += 40;
    path.push_back(up);
    // Nodes at the rest spacing along the path; each puncture at its arc position.
    double at = 0;  // arc length at path[k]
    size_t k = 0;
    for (int32_t i = 0; i < ss.num_nodes; ++i) {
      const double u = i * ss.seg_len;
      double len = 0;
      while (k + 1 < path.size()) {
        const auto& p = path[k];
        const auto& q = path[k + 1];
        len = std::sqrt((q[0] - p[0]) * (q[0] - p[0]) + (q[1] - p[1]) * (q[1] - p[1]) + (q[2] - p[2]) * (q[2] - p[2]));
        if (u <= at + len || k + 2 == path.size()) break;
        at += len;
        ++k;
      }
      const double f = len > 0 ? (u - at) / len : 0;
      for (int c = 0; c < 3; ++c) ss.pos[3 * i + c] = path[k][c] + f * (path[k + 1][c] - path[k][c]);
    }
    std::fill(ss.vel.begin(), ss.vel.end(), 0.0);
    double arc = 0;
    for (int j = 0; j < 4; ++j) {
      const auto& p = path[j];
      const auto& q = path[j + 1];
      arc += std::sqrt((q[0] - p[0]) * (q[0] - p[0]) + (q[1] - p[1]) * (q[1] - p[1]) + (q[2] - p[2]) * (q[2] - p[2]));
      SuturePuncture& pu = ss.punctures[j];
      pu.atoms[0] = holes[j], pu.w[0] = 1, pu.s = arc / ss.seg_len;
      pu.order = j == 0 ? 0 : -1;  // each further along the thread than the one before
    }
    ss.num_punctures = 4;
  }
  ToolInput Input(bool tie) const {
    ToolInput in;
    in.num_tools = 1;
    in.tools[0] = SutureNeedle(2, 24);
    in.tools[0].pos[0] = 5.0, in.tools[0].pos[1] = 3 * 0.866;
    in.tools[0].suture.segments = 96;
    in.tools[0].suture.tie_force = tie_force_;
    in.tools[0].tie = tie;
    return in;
  }
  // The slit's width at the stitch: its two walls' punctures apart.
  double Gap() const {
    const auto a = At(a_wall_), b = At(b_wall_);
    return std::sqrt((b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]));
  }
  // Steps `seconds` with the tie command on from `tie_at` s on.
  std::vector<SutureReport> Run(double seconds, double tie_at) {
    std::vector<SutureReport> out;
    const auto n = static_cast<int64_t>(std::llround(seconds / ws_.options.dt_s));
    for (int64_t i = 0; i < n; ++i)
      out.push_back(Step(model_, state_, ws_, Input(i * ws_.options.dt_s >= tie_at)).suture);
    return out;
  }
  Model model_ = GenerateSlab(Soft());
  State state_ = MakeState(model_);
  Workspace ws_ = MakeWorkspace(model_, StepOptions{});
  int32_t a_top_ = -1, a_wall_ = -1, b_wall_ = -1, b_top_ = -1;
  double tie_force_ = 2;
};

TEST_F(SutureTieTest, ATieDrawsTheSlitTogetherAndHoldsIt) {
  Stitch();
  const double open = Gap();
  EXPECT_GT(open, 0.4);
  // Untied, half a second: the thread lies as it was put, the slit stays open.
  Run(0.5, 1e9);
  EXPECT_NEAR(Gap(), open, 0.05 * open);
  // Tied: one tie event, then the walls drawn together; released, 2 s later still held.
  const std::vector<SutureReport> tied = Run(1.0, 0.0);
  EXPECT_TRUE(tied.front().tied);
  EXPECT_EQ(std::count_if(tied.begin(), tied.end(), [](const SutureReport& r) { return r.tied; }), 1);
  EXPECT_EQ(tied.back().ties, 1);
  const double closed = Gap();
  // Released, it holds: 5 s later the slit is still within a tenth of its open width.
  double widest = closed;
  for (int i = 0; i < 10; ++i) {
    Run(0.5, 1e9);
    EXPECT_LT(Gap(), 0.1 * open) << "at " << 0.5 * (i + 1) << " s";
    widest = std::max(widest, Gap());
  }
  std::printf("[ figures  ] a tie across the slit: open %.4f, tied %.4f (%.1f %%), at most %.4f (%.1f %%) over 5 s\n",
              open, closed, 100 * closed / open, widest, 100 * widest / open);
  EXPECT_NEAR(Gap(), closed, 0.05 * open);
  EXPECT_EQ(state_.suture.num_ties, 1);
  EXPECT_EQ(state_.suture.stitch_start, 4);
  EXPECT_EQ(TotalWarnings(state_.warnings), 0);
}

// A knot drawn harder than this soft tissue bears crushes the stitch, but the thread stays whole:
// its punctures keep their order along it, and nothing goes non-finite.
TEST_F(SutureTieTest, AnOverTightKnotKeepsThePuncturesInOrder) {
  tie_force_ = 4;
  Stitch();
  Run(3.0, 0.0);
  const SutureState& ss = state_.suture;
  for (int32_t j = 1; j < ss.num_punctures; ++j) EXPECT_GE(ss.punctures[j].s, ss.punctures[j - 1].s) << j;
  EXPECT_LE(ss.ties[0].s_a, ss.punctures[0].s);
  EXPECT_GE(ss.ties[0].s_b, ss.punctures[3].s);
  for (const WarningKind& k : WarningKinds(state_.warnings)) EXPECT_EQ(k.count, 0) << k.name;
}

// A tie with no stitch to knot (fewer than two punctures since the last) is refused and counted
// in the report, not made.
TEST_F(SutureTieTest, ATieWithoutAStitchIsRefused) {
  Stitch();
  state_.suture.num_punctures = 1;
  const std::vector<SutureReport> r = Run(0.01, 0.0);
  EXPECT_TRUE(r.front().tie_refused);
  EXPECT_FALSE(r.front().tied);
  EXPECT_EQ(state_.suture.num_ties, 0);
}

// FNV-1a over the thread's nodes, punctures and ties.
uint64_t HashSuture(const SutureState& ss) {
  uint64_t h = 1469598103934665603ull;
  auto mix = [&h](const void* data, size_t bytes) {
    const unsigned char* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 1099511628211ull;
  };
  mix(ss.pos.data(), sizeof(ss.pos));
  mix(ss.vel.data(), sizeof(ss.vel));
  for (int32_t j = 0; j < ss.num_punctures; ++j) mix(&ss.punctures[j].s, sizeof(double));
  mix(&ss.num_ties, sizeof(ss.num_ties));
  mix(&ss.broken, sizeof(ss.broken));
  return h;
}

// Same inputs, same bits, with a needle through and a thread in the tissue; and from a snapshot.
TEST_F(SutureTest, IsDeterministic) {
  State a = MakeState(model_), b = MakeState(model_);
  Workspace wa = MakeWorkspace(model_, StepOptions{}), wb = MakeWorkspace(model_, StepOptions{});
  const std::vector<Tick> ta = DrawThrough(model_, a, wa, kTip + 0.05, 1.0, 6.0, 6.0);
  const std::vector<Tick> tb = DrawThrough(model_, b, wb, kTip + 0.05, 1.0, 6.0, 6.0);
  ASSERT_EQ(a.suture.num_punctures, 2);
  EXPECT_EQ(test::HashState(a), test::HashState(b));
  EXPECT_EQ(HashSuture(a.suture), HashSuture(b.suture));
  for (size_t i = 0; i < ta.size(); ++i) {
    for (int c = 0; c < 3; ++c) ASSERT_EQ(ta[i].force[c], tb[i].force[c]) << i;
  }
  State snapshot = a;
  Workspace fresh = MakeWorkspace(model_, StepOptions{});
  DrawThrough(model_, a, wa, -5.7, 1.0, 1.0, 6.0);
  DrawThrough(model_, snapshot, fresh, -5.7, 1.0, 1.0, 6.0);
  EXPECT_EQ(test::HashState(a), test::HashState(snapshot));
  EXPECT_EQ(HashSuture(a.suture), HashSuture(snapshot.suture));
}

// With the needle through and the thread sliding, the step allocates nothing.
TEST_F(SutureTest, StepAllocatesNothingWithAThread) {
  DrawThrough(model_, state_, ws_, kTip + 0.05, 1.0, 4.0, 6.0);
  ASSERT_GE(state_.suture.num_punctures, 1);
  ToolInput in;
  in.num_tools = 1;
  const int64_t before = test::AllocationCount();
  for (int i = 1; i <= 300; ++i) {
    in.tools[0] = SutureNeedle(kTip + 0.05 - 4.0 - i * 1e-3, 6.0);
    Step(model_, state_, ws_, in);
  }
  EXPECT_EQ(test::AllocationCount(), before);
}

// Bad parameters: the boundary's check names the field; the step holds the last valid pose.
TEST_F(SutureTest, BadParametersAreRefusedNamingTheField) {
  std::string error;
  ToolCommand c = SutureNeedle(1, 6);
  EXPECT_TRUE(ValidateSuture(c, &error)) << error;
  struct Bad {
    void (*set)(SutureParams&);
    const char* error;
  };
  const Bad bad[] = {
      {[](SutureParams& p) { p.segments = 0; }, "suture.segments must be an integer in 1..128, got 0"},
      {[](SutureParams& p) { p.segments = 129; }, "suture.segments must be an integer in 1..128, got 129"},
      {[](SutureParams& p) { p.length = -1; }, "suture.length must be a finite number >= 0 (0 = no thread), got -1"},
      {[](SutureParams& p) { p.mass = 0; }, "suture.mass must be a finite number > 0, got 0"},
      {[](SutureParams& p) { p.tie_force = std::nan(""); }, "suture.tie_force must be a finite number > 0, got nan"},
      {[](SutureParams& p) { p.strength = std::numeric_limits<double>::infinity(); },
       "suture.strength must be a finite number >= 0 (0 = unbreakable), got inf"},
  };
  for (const Bad& b : bad) {
    ToolCommand t = c;
    b.set(t.suture);
    EXPECT_FALSE(ValidateSuture(t, &error));
    EXPECT_EQ(error, b.error);
    // The step: bad input, the last valid pose held, no thread laid from it.
    State s = MakeState(model_);
    Workspace ws = MakeWorkspace(model_, StepOptions{});
    ToolInput in;
    in.num_tools = 1;
    in.tools[0] = t;
    Step(model_, s, ws, in);
    EXPECT_EQ(s.warnings.bad_tool_input, 1);
    EXPECT_EQ(s.suture.num_nodes, 0);
  }
}

// A scene without a thread carries none: nothing laid, no report.
TEST_F(SutureTest, NoThreadWithoutALength) {
  DrawThrough(model_, state_, ws_, kTip + 0.05, 1.0, 0.5, 0.0);
  EXPECT_EQ(state_.suture.num_nodes, 0);
  EXPECT_FALSE(ws_.suture_on);
}

// The scripted stitch on the hex fragment (idms-sim run --script stitch): one puncture, out through
// the bottom, drawn through (the thread left in the entry and the exit), tied; the knot draws the
// two punctures together; no warnings; and the device force steps no more at any tick than the
// needle's tip did pressing the surface before the puncture, by more than 10% (measured: 0.408 N
// after, 0.390 N while pressing).
TEST(StitchScript, PassesTheThreadThroughAndTiesIt) {
  const Model model = test::LoadShippedModel("hex_4x5_home");
  ToolCommand tool = StitchNeedle();
  const ScriptGeometry g = MakeScriptGeometry(model, tool.radius);
  State state = MakeState(model);
  Workspace ws = MakeWorkspace(model, StepOptions{});
  ToolInput in;
  in.num_tools = 1;
  const auto n = static_cast<int64_t>(std::llround(ScriptDuration(Script::kStitch) / ws.options.dt_s));
  int punctures = 0, exits = 0, draws = 0, thread_holes = 0, ties = 0, breaks = 0;
  bool was_in = false, was_out = false;
  double prev[3] = {0, 0, 0}, press_max = 0, after_max = 0, apart_before_tie = -1, last_tension = 0;
  auto apart = [&] {
    double a[3], b[3];
    const SutureState& ss = state.suture;
    internal::AnchorPoint(state, ss.punctures[0].atoms, ss.punctures[0].w, a);
    internal::AnchorPoint(state, ss.punctures[1].atoms, ss.punctures[1].w, b);
    const double d[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    return Norm3(d);
  };
  for (int64_t i = 0; i < n; ++i) {
    const double t = (i + 1) * ws.options.dt_s;
    const ScriptSample sample = SampleScript(Script::kStitch, g, t);
    std::copy(sample.pos, sample.pos + 3, tool.pos);
    NeedleAxisOf(sample.orientation, tool.axis);
    tool.tie = sample.closed;
    if (sample.closed && apart_before_tie < 0) apart_before_tie = apart();
    in.tools[0] = tool;
    const StepReport r = Step(model, state, ws, in);
    const ToolReport& tr = r.tools[0];
    punctures += tr.punctured && !was_in;
    exits += tr.exited && !was_out;
    was_in = tr.punctured, was_out = tr.exited;
    draws += tr.drawn_through;
    thread_holes += r.suture.new_punctures;
    ties += r.suture.tied;
    breaks += r.suture.broke;
    last_tension = r.suture.max_tension;
    const double d[3] = {tr.force[0] - prev[0], tr.force[1] - prev[1], tr.force[2] - prev[2]};
    (punctures == 0 ? press_max : after_max) = std::max(punctures == 0 ? press_max : after_max, Norm3(d));
    std::copy(tr.force, tr.force + 3, prev);
  }
  EXPECT_EQ(punctures, 1);
  EXPECT_EQ(exits, 1);
  EXPECT_EQ(draws, 1);
  EXPECT_EQ(thread_holes, 2);
  EXPECT_EQ(ties, 1);
  EXPECT_EQ(breaks, 0);
  EXPECT_EQ(TotalWarnings(state.warnings), 0);
  // The knot squeezed the fragment between the entry and the exit (its home springs hold the top:
  // 0.667 to 0.595 with the tie force of 2), and the loop pulls with the tie force.
  ASSERT_GT(apart_before_tie, 0.5);
  EXPECT_LT(apart(), 0.95 * apart_before_tie) << apart_before_tie;
  EXPECT_GT(last_tension, 0.9 * tool.suture.tie_force);
  EXPECT_GT(press_max, 0.1);
  EXPECT_LE(after_max, 1.1 * press_max) << "pressing " << press_max << ", after " << after_max;
}

}  // namespace
}  // namespace idms
