// Full mode's fused pass inside: what full_step.cc shares with its vectorised phase
// (full_step_batch.cc). Nobody else includes it.
#pragma once

#include <bit>
#include <cstdint>
#include <vector>
#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "idms/sim/state.h"
#include "worker_pool.h"

namespace idms::internal {

// Full mode's fused kernel (full_step.cc): element forces, accumulation and integration in one
// sweep over the elements in the order the general kernel visits them (grouped by their lowest
// free endpoint), so each free atom is integrated as soon as its last element is done and every
// per-atom sum is formed in the same order: the same bits as the general kernel. Built from the
// Workspace's full-mode lists (see `live`) without allocating; arrays are in walk order unless
// noted. The Workspace owns it (Workspace::fused); nothing outside full_step*.cc reads it.
struct FusedPass {
  // The lists below, and ws.active / candidates / elems with their marks, hold the full-mode
  // sets across ticks (the between-steps invariant of the marks is suspended while live).
  bool live = false;
  uint64_t topology_version = 0;  // model version the arrays were built for
  bool identity = false;          // ws.elems[w] == w: element arrays need no indirection
  // `force` of every free atom is 0 (the pass leaves it so for the next tick).
  bool force_zero = false;
  std::vector<int32_t> group_end;              // (num_atoms) by active slot: one past its last element
  std::vector<int32_t> other;                  // (num_elems) endpoint that is not the group's atom; ~id if fixed
  std::vector<int32_t> elem_g;                 // (num_elems) the group's atom (the lower free endpoint)
  std::vector<Real> elem_k, elem_b, elem_leq;  // (num_elems) model values, as Real
  std::vector<Real> atom_t_over_m;             // (num_atoms) by active slot: T / Model::atom_mass
  Real t_over_m_of = 0;                        // the substep T of atom_t_over_m; 0 = not computed
  // The pass's force accumulator, (num_atoms x 4) with a zero 4th lane: one vector per atom.
  std::vector<Real> force;
  std::vector<Real> scratch;  // per-batch temporaries (full_step.cc)
  // (num_elems / batch + 1) per batch of the walk: the highest active slot of a free endpoint in
  // it or an earlier batch (the energy check forms a batch's end-of-tick lengths past it).
  std::vector<int32_t> batch_ready;
  // Float builds: the rollback copy of the atoms as two 4-wide rows per slot (position, velocity;
  // lane 3 not used), written with one non-temporal vector store each (else Workspace::backup_pos
  // and backup_vel).
  std::vector<Real> backup_rows;
  int64_t huge_bytes = 0;  // bytes AdviseHugePages moved to huge pages so far
  // StepOptions::threads: the walk in contiguous sections, one per thread (renumbered models; 1
  // otherwise). Section t holds the groups of active slots [slot_begin, slot_end) and so the walk
  // [w_begin, w_end); a section reads no atom of an earlier one, only the tick-start state of some
  // atoms of later ones, through the elements whose other endpoint lies past `bound` ("cross"
  // elements). Their forces on those atoms (which come first in those atoms' sums, since every
  // earlier section's group comes before) are added by the atoms' own section before the sweep,
  // which reads the atoms from a copy made then (`ghost_*`; fixed endpoints in place, three values
  // each: no thread reads a row another thread writes, not even as the 4th lane of a vector load).
  // The same bits as one section: each atom's sum is formed in walk order and no value is computed
  // differently.
  struct Section {
    int32_t slot_begin = 0, slot_end = 0;    // active slots
    int32_t w_begin = 0, w_end = 0;          // walk indices
    int32_t bound = 0;                       // the next section's first atom (INT32_MAX for the last)
    int32_t ready_begin = 0;                 // its batches' entries in section_ready
    int32_t cross_begin = 0, cross_end = 0;  // cross elements into this section, in `cross`
    int32_t ghost_begin = 0, ghost_end = 0;  // the atoms of this section they read, in ghost_atoms
  };
  int32_t sections = 1;
  std::vector<Section> section;
  std::vector<int32_t> cross;              // walk indices, by target section, in walk order
  std::vector<int32_t> ghost_atoms;        // by section
  std::vector<Real> ghost_pos, ghost_vel;  // (num_atoms x 3) tick-start copies of ghost_atoms
  std::vector<int32_t> section_ready;      // batch_ready by section, batches from w_begin
  WorkerPoolPtr pool;
  // Stable step of the configured integrator without tools (the minimum over free atoms), and
  // how many atoms reach it: a tick only re-examines the atoms a tool stiffens.
  double dt_free = 0;
  int32_t dt_free_count = 0;
};

// Where the eq. 4.8 length rate comes from in this pass.
enum class Rate : uint8_t {
  kNone,      // no element has b > 0: no rate, no filter
  kAnalytic,  // s^ . (v1 - v0)
  kFiltered,  // eq. 4.6, continued, or restarted where State::elem_len holds a restart mark
};

constexpr bool IsFiltered(Rate rate) { return rate == Rate::kFiltered; }

// Elements per batch: the batch's temporaries (16 values per element) stay in L1. 64 rather
// than 128: +10% in double at 10^6 atoms, float unchanged or better at 10^4 and 10^6
// (idms-step-throughput-bench, alternating builds); padding the temporaries apart instead gave
// nothing, 32 was no better. (256 was 16% slower than 128 at 10^6 atoms: the scratch's parts then
// start at the same offset of a 4 KiB page; see ForceMultiple in full_step_batch.cc.)
constexpr int32_t kBatch = 64;
constexpr int32_t kMaskWords = (kBatch + 63) / 64;

// Phase 2's inputs and outputs for a batch of n elements: views at the batch's first element.
// len and rate hold the eq. 4.6 state in place (direct input; kFilterRestart marks a filter to
// restart) or receive it (inputs then come gathered, with
// fresh = 0 restarting the filter: l_{n-1} = l, l'_{n-1} = 0).
struct BatchIo {
  int32_t n;
  Real inv_t, lambda;
  const Real *k, *b, *leq;                   // (n) model values
  const Real* s4;                            // (n x 4) rows: s' = p_other - p_g; lane 3 is not read
  const Real* dv4;                           // (n x 4) rows: v_other - v_g (analytic rate)
  const Real *prev_len, *prev_rate, *fresh;  // (n) gathered eq. 4.6 inputs
  Real *len, *rate;                          // (n) eq. 4.6 state
  // (n) the rollback copy of len and rate, written on the way (direct input), or null.
  Real *backup_len, *backup_rate;
  Real *ex, *ey, *ez;  // (n) the element's force on g (eq. 4.9, g's frame)
  // (kMaskWords) bit j: element j is degenerate (l <= kMinLength; its force is not used).
  uint64_t* degenerate;
  // Null, or the energy check's sums over the batch at these lengths, added to: [0] elastic
  // energy, sum of k (l - l_eq)^2 / 2; [1] sum of k |l - l_eq|; [2] sum of k.
  double* energy;
};

// Phase 2: eqs. 4.4-4.9 for a batch, vectorised, with the AVX2 code where allow_avx2 and the
// CPU has it (the same bits either way). direct_in: len and rate are read in place.
void BatchForces(Rate rate, bool direct_in, bool allow_avx2, const BatchIo& io);

// The energy check's end-of-tick elastic energy of n elements, sum of k (l - l_eq)^2 / 2 with
// l = sqrt(len2); vectorised as BatchForces.
double BatchElastic(bool allow_avx2, int32_t n, const Real* len2, const Real* k, const Real* leq);

// The rollback copy is written once and read only after a failure: non-temporal stores keep it
// from evicting the arrays the pass is still working on, and skip the read-for-ownership.
template <class T>
inline void StreamStore(T* dst, T value) {
#if defined(__SSE2__)
  if constexpr (sizeof(T) == 4) {
    _mm_stream_si32(reinterpret_cast<int*>(dst), std::bit_cast<int>(value));
  } else {
    static_assert(sizeof(T) == 8);
    _mm_stream_si64(reinterpret_cast<long long*>(dst), std::bit_cast<long long>(value));
  }
#else
  *dst = value;
#endif
}

}  // namespace idms::internal
