// The full-model throughput runner, compiled twice: against libidms_sim (double) and against
// libidms_sim_f32 (float, namespace renamed), so one bench prints both side by side.
#pragma once

#include <cstdint>

// How a run is set up.
struct ThroughputVariant {
  bool reorder = true;        // renumber the slab first (ReorderForLocality, as `idms-sim reorder`)
  bool fused = true;          // full mode's fused pass (false: the general path, StepOptions::fused_pass = false)
  bool huge_pages = true;     // AdviseHugePages (the pass's arrays on 2 MiB pages where the kernel agrees)
  bool energy_check = false;  // StabilityOptions::energy_check (the pass then forms the energies)
  // StepOptions::threads. With wall = true the rates are per wall-clock second and each
  // repetition's triad runs on `threads` threads too (a sectioned pass's CPU time is on several).
  int threads = 1;
  bool wall = false;
};

struct ThroughputResult {
  int64_t atoms = 0, elements = 0;
  double elem_updates_per_s = 0;  // median over repetitions, thread CPU time
  double bytes_per_elem = 0;      // what the fused pass streams per element and step (see runner.cc)
  // Fraction of the memory-bandwidth bound: each repetition's rate over (the triad rate measured
  // just before it / bytes_per_elem); the median over repetitions. Pairing each repetition with its
  // own triad keeps the ratio steady while other tenants' traffic moves both.
  double bound_ratio = 0;
  double triad_bytes_per_s = 0;  // median of the triads paired with the repetitions
  double ns_per_step = 0;
  bool identity = false;  // the fused pass read its element arrays without an index
  double huge_mib = 0;    // MiB of the pass's arrays the kernel put on huge pages (FusedPassStatus::huge_bytes)
  // Warnings counted while timed (a rollback or fallback there would time the general path).
  int64_t timed_warnings = 0;
  int sections = 1;  // FusedPassStatus::sections: threads the pass ran on
};

// Steps a full (local simulation off) slab of about `atoms` atoms with symplectic Euler for at
// least `seconds` of CPU time per repetition, `reps` times; returns the median rate.
ThroughputResult RunThroughputDouble(int64_t atoms, double seconds, int reps, ThroughputVariant variant);
ThroughputResult RunThroughputFloat(int64_t atoms, double seconds, int reps, ThroughputVariant variant);

// Bullet's btSoftBody on the same network (nodes = atoms, links = elements, one position-solver
// iteration); elements per second. Returns 0 when the bench was built without Bullet.
double RunBulletSoftBody(int64_t atoms, double seconds, int reps, int64_t* links);

// One STREAM triad a = b + s * c over arrays far larger than the caches, bytes/s as STREAM counts
// them (24 per double element: two reads, one write; the write's read for ownership is not
// counted), thread CPU time, median of a few passes. Taken before each repetition.
double TriadSample();
// The same triad split over `threads` threads in contiguous parts, wall clock.
double TriadSampleThreads(int threads);
// Wall-clock seconds (steady clock).
double WallSeconds();

// Seconds of CPU time this thread has used (the machine is shared: a descheduled run would
// otherwise count someone else's time).
double ThreadCpuSeconds();
