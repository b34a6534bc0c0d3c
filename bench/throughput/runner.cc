// Full-model step throughput for one precision; see runner.h. Compiled once per precision:
// RUNNER_NAME is RunThroughputDouble or RunThroughputFloat.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <vector>

#include "idms/sim/generate.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"
#include "runner.h"

ThroughputResult RUNNER_NAME(int64_t atoms, double seconds, int reps) {
  using namespace idms;
  const int32_t side = static_cast<int32_t>(std::lround(std::sqrt(atoms / 3.0)));
  const Model model = GenerateSlab(SlabOptions{.rows = side, .cols = side, .decimals = -1});
  StepOptions options;
  options.full = true;
  options.integrator = Integrator::kSymplecticEuler;
  options.stability.predict = false;
  options.stability.energy_check = false;
  State state = MakeState(model);
  Workspace workspace = MakeWorkspace(model, options);
  // A deformed start, so every element carries force.
  for (int32_t i = 0; i < model.num_atoms; ++i) {
    if (!model.atom_fixed[i]) state.atom_pos[3 * i + 2] += static_cast<Real>(0.01 * std::sin(0.37 * i));
  }
  const ToolInput input;  // no tools: the element network alone

  std::vector<double> rates;
  ThroughputResult r;
  for (int rep = 0; rep < reps; ++rep) {
    int64_t steps = 0;
    const auto start = std::chrono::steady_clock::now();
    double elapsed = 0;
    while (elapsed < seconds) {
      for (int k = 0; k < 10; ++k) Step(model, state, workspace, input);
      steps += 10;
      elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    }
    rates.push_back(static_cast<double>(model.num_elems) * steps / elapsed);
    r.ns_per_step = 1e9 * elapsed / steps;
  }
  std::sort(rates.begin(), rates.end());
  r.atoms = model.num_atoms;
  r.elements = model.num_elems;
  r.elem_updates_per_s = rates[rates.size() / 2];
  // Streamed once per step: element arrays (ids, k, b, l_eq read; filter length and rate read and
  // written) and atom arrays (position and velocity read and written, force written and read,
  // mass and boundary condition read).
  const double real = sizeof(Real);
  const double per_elem = 2 * 4 + 3 * 8 + 2 * 2 * real;
  const double per_atom = 2 * 3 * real + 2 * 3 * real + 2 * 3 * real + 8 + 1;
  r.bytes_per_elem = per_elem + per_atom * model.num_atoms / model.num_elems;
  return r;
}
