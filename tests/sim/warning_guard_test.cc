// The test fixture of tests/common/warning_guard.h: it fails a test on every warning kind that
// moved undeclared, names it, and holds declared kinds to their counts.
#include "warning_guard.h"

#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>

#include <cmath>

#include "idms/sim/model.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "step_test_util.h"

namespace idms {
namespace {

TEST(WarningGuard, EveryKindHasAName) {
  const WarningCounters zero;
  const auto kinds = WarningKinds(zero);
  ASSERT_EQ(test::kWarningInfo.size(), kinds.size());
  for (size_t i = 0; i < kinds.size(); ++i) EXPECT_STREQ(test::kWarningInfo[i].name, kinds[i].name);
}

TEST(WarningGuard, QuietWhenNothingMoved) {
  WarningCounters w;
  w.rollback = 5;  // before the guard: not its business
  test::WarningGuard guard(w);
  EXPECT_EQ(guard.Unexpected(), "");
}

TEST(WarningGuard, FailsNamingEachUndeclaredKind) {
  EXPECT_NONFATAL_FAILURE(
      {
        WarningCounters w;
        test::WarningGuard guard(w, "the context");
        w.rollback += 3;
        w.cg_not_converged += 1;
      },
      "numerical warnings (the context): rollback +3 (an attempt failed the finiteness/energy check and was "
      "undone), cg_not_converged +1");
}

TEST(WarningGuard, DeclaredKindsPassAndMissingOnesFail) {
  WarningCounters w;
  {
    test::WarningGuard guard(w);
    guard.Expect(&WarningCounters::rollback, 2).Allow(&WarningCounters::device_force_clamped);
    w.rollback += 2;
  }
  EXPECT_NONFATAL_FAILURE(
      {
        test::WarningGuard guard(w);
        guard.Expect(&WarningCounters::unrecovered);
      },
      "unrecovered 0, expected at least 1");
}

TEST(WarningGuard, CatchesARealStepWarning) {
  // A non-finite tool position is held and counted (bad_tool_input): the guard sees it.
  const Model model = test::OneSpring(15, 0.2, 0.002);
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, test::FullOptions(Integrator::kSymplecticEuler, 1e-3));
  EXPECT_NONFATAL_FAILURE(
      {
        test::WarningGuard guard(s);
        Step(model, s, ws, test::SphereAt(std::nan(""), 0, 0));
      },
      "bad_tool_input +1");
  test::WarningGuard guard(s);
  guard.Expect(&WarningCounters::bad_tool_input);
  Step(model, s, ws, test::SphereAt(std::nan(""), 0, 0));
}

}  // namespace
}  // namespace idms
