// The full-model throughput runner, compiled twice: against libidms_sim (double) and against
// libidms_sim_f32 (float, namespace renamed), so one bench prints both side by side.
#pragma once

#include <cstdint>

struct ThroughputResult {
  int64_t atoms = 0, elements = 0;
  double elem_updates_per_s = 0;  // median over repetitions
  double bytes_per_elem = 0;      // the least the step must move per element (arrays streamed once)
  double ns_per_step = 0;
};

// Steps a full (local simulation off) slab of about `atoms` atoms with symplectic Euler for at
// least `seconds` per repetition, `reps` times; returns the median rate.
ThroughputResult RunThroughputDouble(int64_t atoms, double seconds, int reps);
ThroughputResult RunThroughputFloat(int64_t atoms, double seconds, int reps);

// Bullet's btSoftBody on the same network (nodes = atoms, links = elements, one position-solver
// iteration); elements per second. Returns 0 when the bench was built without Bullet.
double RunBulletSoftBody(int64_t atoms, double seconds, int reps, int64_t* links);
