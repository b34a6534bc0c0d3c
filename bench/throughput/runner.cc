// Full-model step throughput for one precision; see runner.h. Compiled once per precision:
// RUNNER_NAME is RunThroughputDouble or RunThroughputFloat.
#include "runner.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "idms/sim/generate.h"
#include "idms/sim/reorder.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"

namespace {

// Bytes the fused pass moves per step, counted from its layout: each array it streams once,
// read-modify-write arrays twice (the line comes in and goes back out), the rollback copy once
// (non-temporal stores, no read for ownership), read-only arrays once.
double StreamedBytes(const idms::Model& m, const idms::Workspace& ws) {
  using idms::Real;
  const double r = sizeof(Real);
  // Per element of the walk: its two endpoints (the group's atom and the other, int32 each),
  // element id when the ids are not the walk order (int32), k, b, l_eq; the eq. 4.6 length and
  // rate read and written, and copied.
  const bool filter = m.has_damping;
  const double per_elem =
      4 + 4 + (idms::GetFusedPassStatus(ws).identity ? 0 : 4) + 3 * r + (filter ? 2 * 2 * r + 2 * r : 0);
  // Per free atom: slot -> atom id and group end (int32 each), mass; position and velocity read
  // and written; the 4-wide force accumulator read and written; position and velocity copied
  // (as two 4-wide rows where the pass writes them so: FusedPassStatus::row_backup).
  const double copy = idms::GetFusedPassStatus(ws).row_backup ? 2 * 4 * r : 2 * 3 * r;
  const double per_free = 4 + 4 + r + 2 * 3 * r + 2 * 3 * r + 2 * 4 * r + copy;
  // Per fixed atom that some element ties to a free one: its position, read.
  int64_t fixed_used = 0;
  for (int32_t a = 0; a < m.num_atoms; ++a) fixed_used += m.atom_fixed[a] && m.atom_elem_num[a] > 0;
  return per_elem * ws.num_elems + per_free * ws.num_active + 3 * r * static_cast<double>(fixed_used);
}

}  // namespace

ThroughputResult RUNNER_NAME(int64_t atoms, double seconds, int reps, ThroughputVariant variant) {
  using namespace idms;
  const int32_t side = static_cast<int32_t>(std::lround(std::sqrt(atoms / 3.0)));
  Model model = GenerateSlab(SlabOptions{.rows = side, .cols = side, .decimals = -1});
  if (variant.reorder) model = ReorderForLocality(model);
  StepOptions options;
  options.full = true;
  options.integrator = Integrator::kSymplecticEuler;
  options.stability.predict = false;
  options.stability.energy_check = variant.energy_check;
  options.threads = variant.threads;
  State state = MakeState(model);
  Workspace workspace = MakeWorkspace(model, options);
  workspace.options.fused_pass = variant.fused;
  // A deformed start, so every element carries force.
  for (int32_t i = 0; i < model.num_atoms; ++i) {
    if (!model.atom_fixed[i]) state.atom_pos[3 * i + 2] += static_cast<Real>(0.01 * std::sin(0.37 * i));
  }
  const ToolInput input;  // no tools: the element network alone
  if (variant.huge_pages) AdviseHugePages(state, workspace);
  for (int k = 0; k < 3; ++k) Step(model, state, workspace, input);  // builds the fused pass's lists

  const double bytes_per_elem = StreamedBytes(model, workspace) / model.num_elems;
  std::vector<double> rates, ratios, triads;
  ThroughputResult r;
  const int64_t warnings_before = TotalWarnings(state.warnings);
  for (int rep = 0; rep < reps; ++rep) {
    const double triad = variant.wall ? TriadSampleThreads(variant.threads) : TriadSample();
    const auto now = variant.wall ? WallSeconds : ThreadCpuSeconds;
    int64_t steps = 0;
    const double start = now();
    double elapsed = 0;
    while (elapsed < seconds) {
      for (int k = 0; k < 10; ++k) Step(model, state, workspace, input);
      steps += 10;
      elapsed = now() - start;
    }
    rates.push_back(static_cast<double>(model.num_elems) * steps / elapsed);
    ratios.push_back(rates.back() * bytes_per_elem / triad);
    triads.push_back(triad);
    r.ns_per_step = 1e9 * elapsed / steps;
  }
  auto median = [](std::vector<double>& v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  r.timed_warnings = TotalWarnings(state.warnings) - warnings_before;
  r.atoms = model.num_atoms;
  r.elements = model.num_elems;
  r.elem_updates_per_s = median(rates);
  r.bound_ratio = median(ratios);
  r.triad_bytes_per_s = median(triads);
  r.identity = GetFusedPassStatus(workspace).identity;
  r.huge_mib = static_cast<double>(GetFusedPassStatus(workspace).huge_bytes) / (1 << 20);
  r.bytes_per_elem = bytes_per_elem;
  r.sections = GetFusedPassStatus(workspace).sections;
  return r;
}
