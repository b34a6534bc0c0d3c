// A test fails on numerical warnings it did not declare (STYLE: "a fixture fails on unexpected
// warnings"): WarningGuard names each counter of State::warnings that moved while it was alive.
#pragma once

#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <source_location>
#include <string>
#include <utility>

#include "idms/sim/state.h"

namespace idms::test {

// A warning kind, as a member of WarningCounters: &WarningCounters::rollback.
using WarningField = int64_t WarningCounters::*;

// Each kind with its name and meaning, in IDMS_WARNINGS order (the order of WarningKinds).
struct WarningInfo {
  WarningField field;
  const char* name;
  const char* meaning;
};
#define IDMS_WARNING_INFO(name, meaning) WarningInfo{&WarningCounters::name, #name, meaning},
inline constexpr std::array<WarningInfo, kNumWarningKinds> kWarningInfo = {{IDMS_WARNINGS(IDMS_WARNING_INFO)}};
#undef IDMS_WARNING_INFO

// Declare it after the State (or other owner of the counters) it watches, so that it is checked
// before they go:
//   State s = MakeState(model);
//   test::WarningGuard warnings(s);                    // no warning of any kind, or the test fails
//   warnings.Expect(&WarningCounters::rollback);       // at least one rollback, any number
//   warnings.Allow(&WarningCounters::device_force_clamped);  // any number, none included
// At the end of its scope (or at Check) it fails the test once, at the line it was declared,
// naming every kind that moved without being declared ("rollback +3 (meaning)") and every kind
// expected that did not reach its count. Counts are taken relative to the construction, so
// warnings a test provoked on purpose before it are not counted.
class WarningGuard {
 public:
  explicit WarningGuard(const WarningCounters& counters, std::string context = {},
                        std::source_location where = std::source_location::current())
      : counters_(&counters), before_(counters), context_(std::move(context)), where_(where) {
    expected_.fill(kUnexpected);
  }
  explicit WarningGuard(const State& state, std::string context = {},
                        std::source_location where = std::source_location::current())
      : WarningGuard(state.warnings, std::move(context), where) {}
  WarningGuard(const WarningGuard&) = delete;
  WarningGuard& operator=(const WarningGuard&) = delete;
  ~WarningGuard() {
    if (!checked_) Check();
  }

  // Warnings of `kind` are expected: at least `at_least` of them (any number above).
  WarningGuard& Expect(WarningField kind, int64_t at_least = 1) {
    expected_[Index(kind)] = at_least;
    return *this;
  }
  // Warnings of `kind` may occur, any number of them, none included.
  WarningGuard& Allow(WarningField kind) { return Expect(kind, 0); }

  // The failures as one message, "" when every change was declared.
  std::string Unexpected() const {
    std::string out;
    for (size_t i = 0; i < kWarningInfo.size(); ++i) {
      const WarningInfo& k = kWarningInfo[i];
      const int64_t moved = (*counters_).*k.field - before_.*k.field;
      if (expected_[i] == kUnexpected && moved != 0) {
        out += std::string(out.empty() ? "" : ", ") + k.name + " " + (moved > 0 ? "+" : "") + std::to_string(moved) +
               " (" + k.meaning + ")";
      } else if (expected_[i] != kUnexpected && moved < expected_[i]) {
        out += std::string(out.empty() ? "" : ", ") + k.name + " " + std::to_string(moved) + ", expected at least " +
               std::to_string(expected_[i]);
      }
    }
    return out;
  }

  // Checks now (e.g. before the counters go out of scope); the destructor then does not.
  void Check() {
    checked_ = true;
    const std::string unexpected = Unexpected();
    if (unexpected.empty()) return;
    ADD_FAILURE_AT(where_.file_name(), static_cast<int>(where_.line()))
        << "numerical warnings" << (context_.empty() ? "" : " (" + context_ + ")") << ": " << unexpected;
  }

 private:
  static constexpr int64_t kUnexpected = -1;

  static size_t Index(WarningField kind) {
    for (size_t i = 0; i < kWarningInfo.size(); ++i) {
      if (kWarningInfo[i].field == kind) return i;
    }
    return 0;  // unreachable: every WarningField is one of the IDMS_WARNINGS members
  }

  const WarningCounters* counters_;
  WarningCounters before_;
  std::array<int64_t, kNumWarningKinds> expected_{};
  std::string context_;
  std::source_location where_;
  bool checked_ = false;
};

}  // namespace idms::test
