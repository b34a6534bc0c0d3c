// Golden bits, as Box2D pins its EXPECTED_HASH: each integrator's run of the thesis's four
// interactions on the hex fragment, local and full, hashed over what the thesis's state is (atom
// positions and velocities, the eq. 4.6 filter's lengths and rates, time) and every device force.
// A compiler, flag or code change that moves one bit fails here, loudly. A change that is meant to
// move the bits (a new default, a different operation order) updates the table on purpose: run
// `build/bin/sim_tests --gtest_filter='StepGolden.*'`, check the reason in the commit message, and
// paste the printed hashes.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "idms/sim/interaction_script.h"
#include "idms/sim/model_io.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "step_test_util.h"
#include "warning_guard.h"

namespace idms {
namespace {

struct Fnv {
  uint64_t h = 1469598103934665603ull;
  void Mix(const void* data, size_t bytes) {
    const unsigned char* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 1099511628211ull;
  }
};

// The four scripts of chapter 6 back to back, each from rest, the state hashed after each.
uint64_t GoldenRun(Integrator integrator, bool full) {
  const Model model = test::LoadShippedModel("hex_4x5_home");
  StepOptions o;
  o.integrator = integrator;
  o.full = full;
  Fnv fnv;
  for (Script script : {Script::kPalpate, Script::kStrokeSlow, Script::kStrokeFast, Script::kPluck}) {
    State s = MakeState(model);
    test::WarningGuard warnings(
        s, std::string(IntegratorName(integrator)) + (full ? " full " : " local ") + ScriptName(script));
    Workspace ws = MakeWorkspace(model, o);
    ToolCommand tool;
    tool.kind = script == Script::kPluck ? ToolKind::kTweezers : ToolKind::kSphere;
    const ScriptGeometry g = MakeScriptGeometry(model, tool.radius);
    ToolInput input;
    input.num_tools = 1;
    const int64_t ticks = static_cast<int64_t>(ScriptDuration(script) / o.dt_s + 0.5);
    for (int64_t n = 1; n <= ticks; ++n) {
      const ScriptSample sample = SampleScript(script, g, static_cast<double>(n) * o.dt_s);
      for (int c = 0; c < 3; ++c) tool.pos[c] = sample.pos[c];
      tool.closed = sample.closed;
      input.tools[0] = tool;
      const StepReport r = Step(model, s, ws, input);
      fnv.Mix(r.tools[0].force, sizeof(r.tools[0].force));
      fnv.Mix(s.atom_pos.data(), s.atom_pos.size() * sizeof(s.atom_pos[0]));
      fnv.Mix(s.atom_vel.data(), s.atom_vel.size() * sizeof(s.atom_vel[0]));
    }
    for (int32_t e = 0; e < model.num_elems; ++e) {
      // What the next update reads: a restart (l_{n-1} = l, rate 0) whatever the stored values.
      const bool restarts = s.elem_len[e] == kFilterRestart;
      const Real filter[2] = {restarts ? Real(-1) : s.elem_len[e], restarts ? Real(0) : s.elem_rate[e]};
      fnv.Mix(filter, sizeof(filter));
    }
    fnv.Mix(&s.time_s, sizeof(s.time_s));
  }
  return fnv.h;
}

const char* EnumName(Integrator integrator) {
  switch (integrator) {
    case Integrator::kExplicitEuler:
      return "kExplicitEuler";
    case Integrator::kSymplecticEuler:
      return "kSymplecticEuler";
    case Integrator::kRk4:
      return "kRk4";
    case Integrator::kImplicitEuler:
      return "kImplicitEuler";
  }
  return "?";
}

struct Golden {
  Integrator integrator;
  bool full;
  uint64_t hash;
};

// x86-64, GCC as built by scripts/build.sh (-O2, -ffp-contract=off in libidms_sim).
constexpr Golden kGolden[] = {
    {Integrator::kExplicitEuler, false, 0x71ded687377b393bull},
    {Integrator::kSymplecticEuler, false, 0xbd1a9ab2d9dffa7full},
    {Integrator::kRk4, false, 0xc85d82c016a5a30aull},
    {Integrator::kImplicitEuler, false, 0xe42a0afb1c5acdf6ull},
    {Integrator::kExplicitEuler, true, 0xb4cecd37686f68e9ull},
    {Integrator::kSymplecticEuler, true, 0xcdf89790d8a979c1ull},
    {Integrator::kRk4, true, 0x77338ba9c4da8adaull},
    {Integrator::kImplicitEuler, true, 0x48b19527da3ffa01ull},
};

TEST(StepGolden, TheThesisInteractionsKeepTheirBitsPerIntegrator) {
  for (const Golden& golden : kGolden) {
    const uint64_t hash = GoldenRun(golden.integrator, golden.full);
    std::printf("    {Integrator::%s, %s, 0x%016llxull},\n", EnumName(golden.integrator),
                golden.full ? "true" : "false", static_cast<unsigned long long>(hash));
    EXPECT_EQ(hash, golden.hash) << IntegratorName(golden.integrator) << (golden.full ? " full" : " local")
                                 << ": the bits moved (see the top of this file for how to update on purpose)";
  }
}

}  // namespace
}  // namespace idms
