// Full mode's fused pass (Workspace::fused): element forces (eqs. 4.3-4.9), their per-atom
// sums and the integration of each free atom (eqs. 4.13-4.15, or symplectic Euler) in one sweep,
// with the general path's arithmetic in the general path's order, so it gives the same bits.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#if defined(__linux__)
#include <sys/mman.h>
#endif
#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "full_step_internal.h"
#include "idms/sim/check.h"
#include "idms/sim/integrate.h"
#include "idms/sim/model.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms::internal {
namespace {

// An atom's three components and a fourth lane, as one vector: GCC and Clang vector extensions
// when the target has registers that wide (float: SSE or NEON; double: AVX), else four plain
// values that the compiler keeps in registers (a 32-byte vector type emulated on SSE2 goes
// through memory: half the speed). Lane-wise IEEE arithmetic either way, so the same bits as the
// general path's scalar code.
#if defined(IDMS_SIM_REAL_FLOAT) || defined(__AVX__)
using V4 = Real __attribute__((vector_size(4 * sizeof(Real))));

inline V4 Make4(Real x, Real y, Real z) { return V4{x, y, z, 0}; }
[[maybe_unused]] inline Real X(const V4& v) { return v[0]; }
[[maybe_unused]] inline Real Y(const V4& v) { return v[1]; }
[[maybe_unused]] inline Real Z(const V4& v) { return v[2]; }
inline V4 Load4(const Real* p) {
  V4 v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}
inline void Store4(Real* p, V4 v) { std::memcpy(p, &v, sizeof(v)); }
inline void Store3(Real* p, V4 v) { std::memcpy(p, &v, 3 * sizeof(Real)); }
// A row of the batch scratch: lanes 0-2, and lane 3 too where that is cheaper.
inline void StoreRow(Real* p, V4 v) { Store4(p, v); }

// Atom a's xyz from a (num_atoms x 3) array; the 4th lane reads the next atom's x, except for the
// last atom, whose array ends there.
inline V4 LoadAtom(const Real* base, int32_t a, int32_t last) {
  if (a != last) [[likely]]
    return Load4(base + 3 * a);
  return Make4(base[3 * a], base[3 * a + 1], base[3 * a + 2]);
}
#else
struct V4 {
  Real x, y, z;
  friend V4 operator+(V4 a, V4 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
  friend V4 operator-(V4 a, V4 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
  friend V4 operator*(Real s, V4 a) { return {s * a.x, s * a.y, s * a.z}; }
  V4& operator+=(V4 b) { return *this = *this + b; }
  V4& operator-=(V4 b) { return *this = *this - b; }
};

inline V4 Make4(Real x, Real y, Real z) { return V4{x, y, z}; }
inline Real X(const V4& v) { return v.x; }
inline Real Y(const V4& v) { return v.y; }
inline Real Z(const V4& v) { return v.z; }
inline V4 Load4(const Real* p) { return V4{p[0], p[1], p[2]}; }
inline void Store4(Real* p, V4 v) { p[0] = v.x, p[1] = v.y, p[2] = v.z, p[3] = 0; }
inline void Store3(Real* p, V4 v) { p[0] = v.x, p[1] = v.y, p[2] = v.z; }
inline void StoreRow(Real* p, V4 v) { Store3(p, v); }
inline V4 LoadAtom(const Real* base, int32_t a, int32_t) { return Load4(base + 3 * a); }
#endif

// x - x is 0 for finite x and NaN otherwise: true when lanes 0-2 of such a difference are all 0
// (lane 3 belongs to the next atom).
inline bool Finite3(V4 diff) {
#if defined(__SSE__) && defined(IDMS_SIM_REAL_FLOAT)
  const __m128 v = std::bit_cast<__m128>(diff);
  return (_mm_movemask_ps(_mm_cmpeq_ps(v, _mm_setzero_ps())) & 7) == 7;
#else
  return X(diff) == 0 && Y(diff) == 0 && Z(diff) == 0;
#endif
}

// Lanes 0-2 of v to dst with non-temporal stores (floats: one 8-byte and one 4-byte store).
[[maybe_unused]] inline void StreamStore3(Real* dst, V4 v) {
#if defined(__SSE2__) && defined(IDMS_SIM_REAL_FLOAT)
  const __m128i bits = _mm_castps_si128(std::bit_cast<__m128>(v));
  _mm_stream_si64(reinterpret_cast<long long*>(dst), _mm_cvtsi128_si64(bits));
  StreamStore(dst + 2, Z(v));
#else
  StreamStore(dst, X(v)), StreamStore(dst + 1, Y(v)), StreamStore(dst + 2, Z(v));
#endif
}

// Lane-wise max(acc, |d|): how far the atoms integrated so far moved, per component.
inline V4 MaxAbs(V4 acc, V4 d) {
#if defined(IDMS_SIM_REAL_FLOAT) || defined(__AVX__)
  const V4 a = d < 0 ? -d : d;
  return acc > a ? acc : a;
#else
  return V4{std::max(acc.x, std::fabs(d.x)), std::max(acc.y, std::fabs(d.y)), std::max(acc.z, std::fabs(d.z))};
#endif
}

inline void StreamFence() {
#if defined(__SSE2__)
  _mm_sfence();
#endif
}

// The per-batch temporaries, views into FusedPass::scratch. s' (and v_other - v_g) is one 4-wide
// row per element, written by phase 1 with one vector store and transposed by phase 2; the force
// comes back by component, which phase 3 loads with three scalar loads. Rejected: components
// for s' too (three scalar stores in phase 1; 5% slower at 10^6 atoms), and rows for the force
// (phase 2's transposes cost more than they save in phase 3; 8% slower).
struct Batch {
  Real* s4;            // (kBatch x 4) s' = p_other - p_g; lane 3 is not read
  Real* dv4;           // (kBatch x 4) v_other - v_g (analytic rate)
  Real *ex, *ey, *ez;  // (kBatch) the element's force on g (eq. 4.9, g's frame)
  Real* prev_len;      // (kBatch) eq. 4.6 inputs when they are gathered
  Real* prev_rate;     // (kBatch)
  Real* fresh;         // (kBatch) 1 = continue the filter, 0 = restart it
  Real* new_len;       // (kBatch) eq. 4.6 outputs when they are scattered
  Real* new_rate;      // (kBatch)
  Real* end_len2;      // (kBatch) |s'|^2 at the tick's end, of an earlier batch (energy check)
  Real *k, *b, *leq;   // (kBatch) gathered model values (CrossForces, CrossElasticAfter)
};

Batch BatchViews(Real* p) {
  Batch b;
  b.s4 = p, b.dv4 = p + 4 * kBatch;
  b.ex = p + 8 * kBatch, b.ey = p + 9 * kBatch, b.ez = p + 10 * kBatch;
  b.prev_len = p + 11 * kBatch, b.prev_rate = p + 12 * kBatch, b.fresh = p + 13 * kBatch;
  b.new_len = p + 14 * kBatch, b.new_rate = p + 15 * kBatch;
  b.end_len2 = p + 16 * kBatch;
  b.k = p + 17 * kBatch, b.b = p + 18 * kBatch, b.leq = p + 19 * kBatch;
  return b;
}
constexpr int32_t kScratchPerElement = 20;
constexpr int32_t kMaxSections = 64;

// How far a substep got: atoms [0, atoms) by slot and elements [0, elems) by walk index have
// been written (and copied). ok = false: it stopped at a non-finite input, or at the end of the
// batch in which a result was not finite.
struct Progress {
  int32_t atoms = 0;
  int32_t elems = 0;
  bool ok = true;
  // The energy check's sums (Substep's `before` / `after`): kinetic energy at the substep's
  // start and end, elastic energy at its start (with sum k |l - l_eq| and sum k) and end, and
  // the largest |x|, |y|, |z| of a free atom at its start.
  double kinetic_before = 0, kinetic_after = 0;
  double elastic_before = 0, stretch_k = 0, sum_k = 0, elastic_after = 0;
  double abs_pos = 0;
  // A bound on how far any atom moved in the substep (|p_new - p|), for Workspace::reach_slack.
  double moved = 0;
};

// The pass reads each atom's position and force accumulator first at the front of its window,
// the highest atom a batch reaches; Gather prefetches both up to kPrefetchAtoms past it. Only in
// double and past the caches: at 10^5 and 10^6 atoms double gains 9-10% (the hardware prefetcher
// falls behind 24- and 32-byte rows), float loses 3-6% at 10^5 and gains nothing at 10^6
// (idms-step-throughput-bench, alternating builds; 16 to 64 atoms ahead gave the same).
constexpr int32_t kPrefetchAtoms = 32;
constexpr bool kPrefetchReal = sizeof(Real) == 8;
inline bool WantPrefetch(const Model& m) { return kPrefetchReal && m.num_atoms >= (int32_t{1} << 16); }

// Float builds on SSE write the atoms' rollback copy as two 4-wide rows per slot
// (FusedPass::backup_rows), one non-temporal vector store each.
#if defined(IDMS_SIM_REAL_FLOAT) && defined(__SSE__)
constexpr bool kRowBackup = true;
inline void StreamRow(Real* dst, V4 v) { _mm_stream_ps(dst, std::bit_cast<__m128>(v)); }  // dst 16-byte aligned
#else
constexpr bool kRowBackup = false;
[[maybe_unused]] inline void StreamRow(Real* dst, V4 v) { StreamStore3(dst, v); }  // kRowBackup is off
#endif

// A degenerate element's push (DegenerateElement in forces.cc): k l_eq along its rest direction,
// atom 0 pushed along -f, atom 1 along +f. w: its walk index, e: its id. False: no push (k l_eq <= 0).
inline bool DegeneratePush(const Model& m, const FusedPass& fp, int32_t w, int32_t e, V4* f) {
  const Real push = fp.elem_k[w] * fp.elem_leq[w];
  if (push <= 0) return false;
  const int32_t a0 = m.elem_atoms[2 * e], a1 = m.elem_atoms[2 * e + 1];
  Real dir[3];
  for (int c = 0; c < 3; ++c)
    dir[c] = static_cast<Real>((m.atom_pos_eq[3 * a1 + c] - m.atom_pos_eq[3 * a0 + c]) / m.elem_leq[e]);
  *f = push * Make4(dir[0], dir[1], dir[2]);
  return true;
}

// One substep over every free atom in slot order. Group i holds the elements whose lowest free
// endpoint is atom g = active[i]; they are visited after every earlier group, so once group i is
// done g has all of its forces (no later element touches g) and is integrated in place. Element
// forces are formed in g's frame, s' = p_other - p_g: s' = +-s of eq. 4.3 exactly, so l, the
// rate and every force are the general path's bits, and each atom's sum is formed in the same
// order (field and tool forces first, then the elements in walk order).
//
// The walk goes in batches of kBatch elements, each in three phases: (1) gather s' (and the
// filter inputs that need an index or a stamp), (2) eqs. 4.4-4.9 for the whole batch, vectorised
// (full_step_batch.cc), (3) the sums and integrations in walk order. A batch may only read atoms
// whose group has not ended, so no atom moves under a later batch.
//
// kEnergy: the substep also forms the energy check's sums (Progress) on the way: the kinetic
// energy of each atom as it is integrated, the elastic energy at the substep's start from phase
// 2's lengths (`before`), and at its end (`after`) from the lengths of each batch whose atoms have
// all been integrated, formed again a bandwidth behind the front (in renumbered models the atoms
// and element arrays are still in cache there), so the check costs no pass of its own.
//
// kSections: one section of a sectioned walk (FusedPass::Section), on its own thread: elements
// whose other endpoint lies past the section (or is fixed) read it from the tick-start copy, and
// leave its sum alone (CrossForces added to it before the sweep).
template <bool kSymplectic, Rate kRate, bool kIdentity, bool kEnergy, bool kSections>
class Substep {
 public:
  static constexpr bool kFilter = IsFiltered(kRate);
  // Filter inputs read in place (else gathered in phase 1), outputs written in place.
  static constexpr bool kDirectIn = kIdentity && kRate == Rate::kFiltered;
  static constexpr bool kDirectOut = kIdentity;

  Substep(const Model& m, State& s, Workspace& ws, Real T, bool backup, bool before, bool after, int32_t section)
      : m_(m),
        s_(s),
        ws_(ws),
        fp_(*ws.fused),
        b_(BatchViews(ws.fused->scratch.data() + static_cast<size_t>(section) * kScratchPerElement * kBatch)),
        T_(T),
        backup_(backup),
        before_(kEnergy && before),
        after_(kEnergy && after) {
    if constexpr (kSections) {
      const FusedPass::Section& sec = ws.fused->section[section];
      slot_begin_ = sec.slot_begin, slot_end_ = sec.slot_end, w_begin_ = sec.w_begin, w_end_ = sec.w_end;
      bound_ = static_cast<uint32_t>(sec.bound);
      own_last_ = sec.bound == INT32_MAX ? last_ : sec.bound - 1;
      ready_ = fp_.section_ready.data() + sec.ready_begin;
      ghost_pos_ = ws.fused->ghost_pos.data(), ghost_vel_ = ws.fused->ghost_vel.data();
    } else {
      slot_end_ = ws.num_active, w_end_ = ws.num_elems;
    }
    trail_ = w_begin_;
    if constexpr (kSections) prefetched_ = slot_begin_ < slot_end_ ? ws.active[slot_begin_] : 0;
  }

  Progress Run() {
    const int32_t n = slot_end_, ne = w_end_;
    Progress out;
    out.atoms = slot_begin_, out.elems = w_begin_;
    if (n == slot_begin_) return out.atoms = n, out.elems = ne, out;
    // Locals, not members, in the loops: to the compiler the vector stores (memcpy) may write
    // anything, so it would reload each member after every one of them (7% at 10^6 atoms).
    const int32_t* const group_end = fp_.group_end.data();
    const int32_t* const other = fp_.other.data();
    const int32_t* const active = ws_.active.data();
    const Real *const ex = b_.ex, *const ey = b_.ey, *const ez = b_.ez;
    Real* const force = force_;
    const AtomIo atom_io = MakeAtomIo();
    const uint32_t bound = bound_;
    int32_t slot = slot_begin_;
    int32_t g = active[slot];
    V4 acc = Load4(force + 4 * g);  // g's sum so far: field, tools, earlier groups
    V4 check = Make4(0, 0, 0);      // the integrated atoms' x - x: 0 while every result is finite
    V4 moved = Make4(0, 0, 0);      // the largest |p_new - p| so far, per component
    [[maybe_unused]] Kinetic kinetic;
    for (int32_t w0 = w_begin_; w0 < ne;) {
      // Batches at multiples of kBatch (a section's first one may be shorter; see Forces).
      const int32_t w_end = std::min((w0 / kBatch + 1) * kBatch, ne), nb = w_end - w0;
      out.elems = w0;
      if (!Gather(w0, nb)) return Stop(out, slot);
      Forces(w0, nb);
      out.elems = w_end;
      // 3. Sums in walk order. The inner loop runs to the next event: the end of g's group (g is
      // integrated), a degenerate element (its own branch) or the end of the batch, so it tests
      // nothing per element but the fixed endpoint. Results are checked once per batch: a
      // non-finite one stops the pass there, and the atoms written after it are restored too.
      const int32_t* const batch_other = other + w0;
      int32_t j = 0, next_degenerate = PopDegenerate();  // batch indices
      for (;;) {
        const int32_t stop = std::min(std::min(group_end[slot] - w0, next_degenerate), nb);
        for (; j < stop; ++j) {
          const V4 e = Make4(ex[j], ey[j], ez[j]);
          acc += e;
          // A free endpoint of this section (fixed ones are ~id < 0, so above `bound` unsigned).
          const int32_t raw = batch_other[j];
          if (static_cast<uint32_t>(raw) < bound) Store4(force + 4 * raw, Load4(force + 4 * raw) - e);
        }
        if (j == nb) break;
        if (group_end[slot] - w0 <= j) {
          Integrate(atom_io, slot, g, acc, check, moved, kinetic);
          g = active[++slot];
          acc = Load4(force + 4 * g);
          continue;
        }
        if (!Degenerate(w0 + j, g, batch_other[j], acc)) return Stop(out, slot);
        ++j, next_degenerate = PopDegenerate();
      }
      if (!Finite3(check)) return Stop(out, slot);
      if constexpr (kEnergy) {
        FlushKinetic(kinetic, out);
        if (after_) ElasticAfter(slot, w_end, out);
      }
      w0 = w_end;
    }
    // The last group, and free atoms after it whose elements all lie in earlier groups.
    for (;;) {
      Integrate(atom_io, slot, g, acc, check, moved, kinetic);
      if (++slot == n) break;
      g = active[slot];
      acc = Load4(force + 4 * g);
    }
    if (!Finite3(check)) return Stop(out, n);
    out.atoms = n;
    out.moved = std::sqrt(double(X(moved)) * X(moved) + double(Y(moved)) * Y(moved) + double(Z(moved)) * Z(moved));
    if constexpr (kEnergy) {
      FlushKinetic(kinetic, out);
      if (after_) ElasticAfter(n, ne, out);
      out.elastic_before = energy_[0], out.stretch_k = energy_[1], out.sum_k = energy_[2];
      out.abs_pos = kinetic.abs_pos;
    }
    return out;
  }

 private:
  // The batch's next degenerate element (batch index), taken from degenerate_; kBatch if none.
  int32_t PopDegenerate() {
    for (int32_t i = 0; i < kMaskWords; ++i) {
      if (uint64_t& bits = degenerate_[i]; bits != 0) {
        const int32_t j = 64 * i + std::countr_zero(bits);
        bits &= bits - 1;
        return j;
      }
    }
    return kBatch;
  }

  Progress Stop(Progress out, int32_t slot) {
    out.atoms = slot;
    out.ok = false;
    return out;
  }

  // 1. s' for each element of the batch, one flat loop (each element names its group's atom:
  // a loop per group exits at a different count each time, and the flat loop was 2-4% faster in
  // float); the eq. 4.6 inputs by element id, with the stale rule, when they cannot be read in
  // place. False: a non-finite filter state (the general path repairs it).
  bool Gather(int32_t w0, int32_t nb) {
    // Locals, as in Run.
    const int32_t* const other = fp_.other.data() + w0;
    const int32_t* const group_atom = fp_.elem_g.data() + w0;
    const Real *const pos = pos_, *const vel = vel_;
    Real *const s4 = b_.s4, *const dv4 = b_.dv4;
    const int32_t own_last = own_last_;
    [[maybe_unused]] const int32_t* const elems = ws_.elems.data();
    [[maybe_unused]] const Real *const elem_len = s_.elem_len.data(), *const elem_rate = s_.elem_rate.data();
    [[maybe_unused]] Real *const prev_len = b_.prev_len, *const prev_rate = b_.prev_rate, *const fresh_in = b_.fresh;
    [[maybe_unused]] Real* const backup_len = backup_ ? ws_.backup_elem_len.data() : nullptr;
    [[maybe_unused]] Real* const backup_rate = ws_.backup_elem_rate.data();
    int32_t hi = 0;  // the highest atom the batch reads (the front of the pass's window)
    for (int32_t j = 0; j < nb; ++j) {
      const int32_t raw = other[j], g = group_atom[j];
      if constexpr (kPrefetchReal) hi = std::max(hi, raw);
      StoreRow(s4 + 4 * j, Other(pos, ghost_pos_, raw) - LoadAtom(pos, g, own_last));
      if constexpr (kRate == Rate::kAnalytic)
        StoreRow(dv4 + 4 * j, Other(vel, ghost_vel_, raw) - LoadAtom(vel, g, own_last));
      if constexpr (kFilter && !kDirectIn) {
        const int32_t w = w0 + j;
        const int32_t e = kIdentity ? w : elems[w];
        const Real old_len = elem_len[e], old_rate = elem_rate[e];
        if (!(std::isfinite(old_len) && std::isfinite(old_rate))) [[unlikely]]
          return false;
        const bool fresh = old_len != kFilterRestart;
        prev_len[j] = old_len;
        prev_rate[j] = old_rate;
        fresh_in[j] = fresh ? Real(1) : Real(0);
        if (backup_len) StreamStore(backup_len + w, old_len), StreamStore(backup_rate + w, old_rate);
      }
    }
    if (prefetch_) Prefetch(hi);
    return true;
  }

  // The energy check's kinetic sums over the atoms integrated since the last flush, as m |v|^2 / T,
  // and the largest |x| + |y| + |z| at the start. Scalars: three more 4-wide accumulators beside
  // acc and check spilled to the stack in every integration.
  struct Kinetic {
    Real before = 0, after = 0, abs_pos = 0;
  };

  // Into double once per batch (a float summing 10^6 atoms would lose the small ones).
  void FlushKinetic(Kinetic& k, Progress& out) const {
    const double half_t = 0.5 * T_;
    out.kinetic_before += half_t * k.before;
    out.kinetic_after += half_t * k.after;
    k.before = k.after = 0;
  }

  // The end-of-tick elastic energy of the batches from trail_ up to w_end whose free endpoints
  // are all integrated (their slots below `slot`): |s'|^2 from the new positions (a gather per
  // element: about a quarter of a substep's time, so only in the tick's last substep), summed by
  // BatchElastic. Rejected: rows of s' transposed as in phase 2 (no faster).
  void ElasticAfter(int32_t slot, int32_t w_end, Progress& out) {
    const int32_t* const ready = ready_;
    while (trail_ < w_end && ready[(trail_ - w_begin_) / kBatch] < slot) {
      const int32_t nb = std::min(kBatch, w_end_ - trail_);
      const int32_t* const other = fp_.other.data() + trail_;
      const int32_t* const group_atom = fp_.elem_g.data() + trail_;
      const Real* const pos = pos_;
      Real* const len2 = b_.end_len2;
      [[maybe_unused]] const Real* const leq = fp_.elem_leq.data() + trail_;
      for (int32_t j = 0; j < nb; ++j) {
        const int32_t raw = other[j];
        if constexpr (kSections) {
          // A later section's atom may not have its end-of-tick position yet: RunSections adds
          // these elements once every section is done.
          if (raw >= 0 && static_cast<uint32_t>(raw) >= bound_) {
            len2[j] = leq[j] * leq[j];
            continue;
          }
        }
        const V4 d = Other(pos, ghost_pos_, raw) - LoadAtom(pos, group_atom[j], own_last_);
        len2[j] = X(d) * X(d) + Y(d) * Y(d) + Z(d) * Z(d);
      }
      out.elastic_after +=
          BatchElastic(ws_.options.fused_avx2, nb, len2, fp_.elem_k.data() + trail_, fp_.elem_leq.data() + trail_);
      trail_ += nb;
    }
  }

  // The lines of position and force from the last prefetched atom to kPrefetchAtoms past hi.
  void Prefetch(int32_t hi) {
    const int32_t to = std::min(hi + kPrefetchAtoms, last_);
    constexpr int32_t kLine = 64 / sizeof(Real);
    for (; prefetched_ <= to; prefetched_ += kLine / 4) {  // a force row is 4 wide
      __builtin_prefetch(pos_ + 3 * prefetched_);
      __builtin_prefetch(force_ + 4 * prefetched_, 1);
    }
  }

  // 2. eqs. 4.4-4.9 over the batch (BatchForces), with the rollback copy of the filter state when
  // it is read in place; the filter state advances (a degenerate element's is marked to restart
  // in phase 3), scattered by element id when the ids are not the walk order. The degenerate
  // elements go to degenerate_.
  void Forces(int32_t w0, int32_t nb) {
    Real* len = kDirectOut ? s_.elem_len.data() + w0 : b_.new_len;
    Real* rate = kDirectOut ? s_.elem_rate.data() + w0 : b_.new_rate;
    bool copy = kFilter && kDirectIn && backup_;
    if constexpr (kSections) {
      // A section's first batch may start anywhere; the vector code streams the copy 16 bytes at a
      // time from the batch's start, which must then be aligned (as every later batch's is).
      if (copy && w0 % kBatch != 0) {
        for (int32_t j = 0; j < nb; ++j) {
          StreamStore(ws_.backup_elem_len.data() + w0 + j, len[j]);
          StreamStore(ws_.backup_elem_rate.data() + w0 + j, rate[j]);
        }
        copy = false;
      }
    }
    const BatchIo io{.n = nb,
                     .inv_t = Real(1) / T_,
                     .lambda = static_cast<Real>(ws_.options.lambda),
                     .k = fp_.elem_k.data() + w0,
                     .b = fp_.elem_b.data() + w0,
                     .leq = fp_.elem_leq.data() + w0,
                     .s4 = b_.s4,
                     .dv4 = b_.dv4,
                     .prev_len = b_.prev_len,
                     .prev_rate = b_.prev_rate,
                     .fresh = b_.fresh,
                     .len = len,
                     .rate = rate,
                     .backup_len = copy ? ws_.backup_elem_len.data() + w0 : nullptr,
                     .backup_rate = copy ? ws_.backup_elem_rate.data() + w0 : nullptr,
                     .ex = b_.ex,
                     .ey = b_.ey,
                     .ez = b_.ez,
                     .degenerate = degenerate_,
                     .energy = before_ ? energy_ : nullptr};
    BatchForces(kRate, kDirectIn, ws_.options.fused_avx2, io);
    if constexpr (kFilter && !kDirectOut) {
      for (int32_t j = 0; j < nb; ++j) {
        const int32_t id = ws_.elems[w0 + j];
        s_.elem_len[id] = b_.new_len[j];
        s_.elem_rate[id] = b_.new_rate[j];
      }
    }
  }

  // A degenerate element's push (DegenerateElement in forces.cc, in g's frame). False: the rate
  // phase 2 formed from its filter state is not finite, so that state was not (or overflowed):
  // the general path repairs it. Elsewhere a non-finite filter state makes the result non-finite,
  // which stops the pass anyway.
  bool Degenerate(int32_t w, int32_t g, int32_t raw, V4& acc) {
    const int32_t e = kIdentity ? w : ws_.elems[w];
    if constexpr (kFilter) {
      if (!std::isfinite(s_.elem_rate[e])) return false;
      // Its rate would be noise: the filter restarts at the next update (forces.cc does the same).
      s_.elem_len[e] = kFilterRestart;
      s_.elem_rate[e] = 0;
    }
    V4 f;
    if (!DegeneratePush(m_, fp_, w, e, &f)) return true;
    const int32_t a0 = m_.elem_atoms[2 * e];
    const int32_t o = raw ^ (raw >> 31);
    const bool mine = static_cast<uint32_t>(raw) < bound_;  // free, and in this section
    if (g == a0) {
      acc -= f;
      if (mine) Store4(force_ + 4 * o, Load4(force_ + 4 * o) + f);
    } else {
      acc += f;
      if (mine) Store4(force_ + 4 * o, Load4(force_ + 4 * o) - f);
    }
    return true;
  }

  // The other endpoint's row (raw as FusedPass::other). kSections: the tick-start copy when it
  // lies past this section; a fixed one from `own` without the 4th lane (the next atom's x, which
  // another section may be writing); else from `own`.
  V4 Other(const Real* own, [[maybe_unused]] const Real* ghost, int32_t raw) const {
    const int32_t o = raw ^ (raw >> 31);  // ~raw for a fixed atom
    if constexpr (kSections) {
      if (static_cast<uint32_t>(raw) >= bound_) {
        if (raw < 0) return Make4(own[3 * o], own[3 * o + 1], own[3 * o + 2]);
        return LoadAtom(ghost, o, last_);
      }
      return LoadAtom(own, o, own_last_);
    }
    return LoadAtom(own, o, last_);
  }

  // Eqs. 4.13-4.15 (or symplectic Euler) for atom g of slot i, with its rollback copy. check
  // collects x - x of the results, for Run to test once per batch (a test and branch per atom
  // cost 3%); moved the largest displacement per component (the tools' reach, Workspace::reach).
  // Integrate's arrays and constants, as locals of Run (see there).
  struct AtomIo {
    Real *pos, *vel, *force;
    const Real* t_over_m;           // by slot
    const Real* external;           // Workspace::atom_force_external, or null
    Real *backup_pos, *backup_vel;  // by slot; null: no rollback copy in this substep
    Real* backup_rows;              // by slot, 8 each (kRowBackup); null as backup_pos
    Real T;
    int32_t last;
    bool before, after;  // form the kinetic sums at the substep's start, at its end (kEnergy)
  };
  AtomIo MakeAtomIo() const {
    return {pos_,
            vel_,
            force_,
            fp_.atom_t_over_m.data(),
            ExternalForces(m_, ws_),
            backup_ ? ws_.backup_pos.data() : nullptr,
            ws_.backup_vel.data(),
            backup_ ? ws_.fused->backup_rows.data() : nullptr,
            T_,
            own_last_,
            before_,
            after_};
  }

  static void Integrate(const AtomIo& io, int32_t i, int32_t g, V4 acc, V4& check, V4& moved,
                        [[maybe_unused]] Kinetic& k) {
    const V4 p = LoadAtom(io.pos, g, io.last), v = LoadAtom(io.vel, g, io.last);
    const Real t_over_m = io.t_over_m[i];
    if (io.external) acc += LoadAtom(io.external, g, io.last);  // last in the sum, as forces.cc adds it
    V4 np, nv;
    if constexpr (kSymplectic) {
      nv = v + t_over_m * acc;
      np = p + io.T * nv;
    } else {
      np = p + io.T * v;
      nv = v + t_over_m * acc;
    }
    check += (np - np) + (nv - nv);
    moved = MaxAbs(moved, np - p);
    if constexpr (kEnergy) {
      // Only the sums this substep needs (a tick of two substeps needs one in each).
      const Real m_over_t = Real(1) / t_over_m;
      if (io.before) {
        k.before += m_over_t * (X(v) * X(v) + Y(v) * Y(v) + Z(v) * Z(v));
        k.abs_pos = std::max(k.abs_pos, std::fabs(X(p)) + std::fabs(Y(p)) + std::fabs(Z(p)));
      }
      if (io.after) k.after += m_over_t * (X(nv) * X(nv) + Y(nv) * Y(nv) + Z(nv) * Z(nv));
    }
    if constexpr (kRowBackup) {
      if (io.backup_rows) StreamRow(io.backup_rows + 8 * i, p), StreamRow(io.backup_rows + 8 * i + 4, v);
    } else if (io.backup_pos) {
      StreamStore3(io.backup_pos + 3 * i, p), StreamStore3(io.backup_vel + 3 * i, v);
    }
    Store3(io.pos + 3 * g, np);
    Store3(io.vel + 3 * g, nv);
    // Cleared for the next tick, whose field forces are then zero unless the scene has some.
    Store4(io.force + 4 * g, Make4(0, 0, 0));
  }

  const Model& m_;
  State& s_;
  Workspace& ws_;
  const FusedPass& fp_;
  const Batch b_;
  const Real T_;
  const bool backup_;
  const bool before_, after_;  // form the energy check's sums at the start, at the end
  Real* const pos_ = s_.atom_pos.data();
  Real* const vel_ = s_.atom_vel.data();
  Real* const force_ = ws_.fused->force.data();
  const int32_t last_ = m_.num_atoms - 1;
  const bool prefetch_ = WantPrefetch(m_);
  int32_t prefetched_ = 0;                // Prefetch has covered the atoms before this one
  uint64_t degenerate_[kMaskWords] = {};  // the batch's degenerate elements not yet taken
  double energy_[3] = {0, 0, 0};          // BatchIo::energy at the substep's start
  int32_t trail_ = 0;                     // ElasticAfter has summed the elements before this
  // The section (all of the walk without kSections).
  int32_t slot_begin_ = 0, slot_end_ = 0, w_begin_ = 0, w_end_ = 0;
  uint32_t bound_ = INT32_MAX;  // free atoms from here on belong to later sections
  int32_t own_last_ = last_;    // the highest atom whose 4-wide row this section may load from State
  const int32_t* ready_ = fp_.batch_ready.data();
  const Real* ghost_pos_ = nullptr;
  const Real* ghost_vel_ = nullptr;
};

template <bool kSymplectic, Rate kRate, bool kIdentity, bool kEnergy, bool kSections>
Progress RunSubstep(const Model& m, State& s, Workspace& ws, Real T, bool backup, bool before, bool after,
                    int32_t section) {
  return Substep<kSymplectic, kRate, kIdentity, kEnergy, kSections>(m, s, ws, T, backup, before, after, section).Run();
}

using SubstepFn = Progress (*)(const Model&, State&, Workspace&, Real, bool, bool, bool, int32_t);

// Sections only in renumbered models (identity): BuildSections makes one section otherwise.
template <bool kSymplectic, bool kIdentity, bool kEnergy, bool kSections>
SubstepFn PickRate(Rate rate) {
  constexpr bool kSec = kSections && kIdentity;
  switch (rate) {
    case Rate::kNone:
      return RunSubstep<kSymplectic, Rate::kNone, kIdentity, kEnergy, kSec>;
    case Rate::kAnalytic:
      return RunSubstep<kSymplectic, Rate::kAnalytic, kIdentity, kEnergy, kSec>;
    case Rate::kFiltered:
      return RunSubstep<kSymplectic, Rate::kFiltered, kIdentity, kEnergy, kSec>;
  }
  return nullptr;
}

template <bool kEnergy, bool kSections>
SubstepFn PickScheme(bool symplectic, Rate rate, bool identity) {
  if (symplectic) {
    return identity ? PickRate<true, true, kEnergy, kSections>(rate) : PickRate<true, false, kEnergy, false>(rate);
  }
  return identity ? PickRate<false, true, kEnergy, kSections>(rate) : PickRate<false, false, kEnergy, false>(rate);
}

SubstepFn PickSubstep(bool symplectic, Rate rate, bool identity, bool energy, bool sections) {
  if (sections) {
    return energy ? PickScheme<true, true>(symplectic, rate, identity)
                  : PickScheme<false, true>(symplectic, rate, identity);
  }
  return energy ? PickScheme<true, false>(symplectic, rate, identity)
                : PickScheme<false, false>(symplectic, rate, identity);
}

// Back to the tick's start from the rollback copy: the atoms (slots [atom_begin, atoms)) and
// elements (walk [elem_begin, elems)) a failed substep had written (all of them after the first
// substep).
void RestoreWritten(State& s, Workspace& ws, int32_t atoms, int32_t elems, bool filter, int32_t atom_begin = 0,
                    int32_t elem_begin = 0) {
  StreamFence();
  for (int32_t i = atom_begin; i < atoms; ++i) {
    const int32_t a = ws.active[i];
    for (int c = 0; c < 3; ++c)
      if constexpr (kRowBackup) {
        s.atom_pos[3 * a + c] = ws.fused->backup_rows[8 * i + c],
                           s.atom_vel[3 * a + c] = ws.fused->backup_rows[8 * i + 4 + c];
      } else {
        s.atom_pos[3 * a + c] = ws.backup_pos[3 * i + c], s.atom_vel[3 * a + c] = ws.backup_vel[3 * i + c];
      }
  }
  if (!filter) return;
  for (int32_t w = elem_begin; w < elems; ++w) {
    const int32_t e = ws.elems[w];
    s.elem_len[e] = ws.backup_elem_len[w];
    s.elem_rate[e] = ws.backup_elem_rate[w];
  }
}

// The walk in StepOptions::threads sections of about as many elements each (FusedPass::Section),
// their cross elements and the atoms those read; one section in a model that is not renumbered
// (the sections need the walk in element order), or where a section would have fewer than four
// batches. Allocates where the sizes grow (a new topology, not a tick).
void BuildSections(const Model& m, Workspace& ws) {
  FusedPass& fp = *ws.fused;
  const int32_t n = ws.num_active, ne = ws.num_elems;
  int32_t want = std::clamp(ws.options.threads, 1, kMaxSections);
  want = std::min(want, std::max(1, ne / (4 * kBatch)));
  if (!fp.identity || n < 2) want = 1;
  fp.sections = 1;
  if (want == 1) return;  // allocates nothing
  // Slot boundaries: section t ends with the group in which the walk passes ne (t + 1) / want.
  std::vector<int32_t> cut = {0};
  for (int32_t t = 1; t < want; ++t) {
    const int64_t target = static_cast<int64_t>(ne) * t / want;
    const int32_t slot = static_cast<int32_t>(std::lower_bound(fp.group_end.begin(), fp.group_end.begin() + n, target) -
                                              fp.group_end.begin()) +
                         1;
    if (slot > cut.back() && slot < n) cut.push_back(slot);
  }
  cut.push_back(n);
  fp.sections = static_cast<int32_t>(cut.size()) - 1;
  if (fp.sections == 1) return;
  for (int32_t i = 0; i + 1 < n; ++i) IDMS_CHECK(ws.active[i] < ws.active[i + 1]);  // full mode: atom order
  const int32_t ns = fp.sections;
  fp.section.assign(ns, {});
  std::vector<int32_t> section_of_slot(n);
  for (int32_t t = 0; t < ns; ++t) {
    FusedPass::Section& sec = fp.section[t];
    sec.slot_begin = cut[t], sec.slot_end = cut[t + 1];
    sec.w_begin = sec.slot_begin == 0 ? 0 : fp.group_end[sec.slot_begin - 1];
    sec.w_end = fp.group_end[sec.slot_end - 1];
    sec.bound = sec.slot_end < n ? ws.active[sec.slot_end] : INT32_MAX;
    std::fill(section_of_slot.begin() + sec.slot_begin, section_of_slot.begin() + sec.slot_end, t);
  }
  IDMS_CHECK(fp.section.back().w_end == ne);
  // Cross elements by target section (a counting sort keeps walk order within each), the atoms
  // they read once each, and each section's batch_ready without the cross elements' far
  // endpoints.
  std::vector<int32_t> count(ns + 1, 0);
  std::vector<uint8_t> seen(m.num_atoms, 0);
  fp.section_ready.clear();
  for (int32_t t = 0; t < ns; ++t) {
    FusedPass::Section& sec = fp.section[t];
    sec.ready_begin = static_cast<int32_t>(fp.section_ready.size());
    int32_t ready = 0;
    for (int32_t w = sec.w_begin; w < sec.w_end; ++w) {
      const int32_t raw = fp.other[w], slot = ws.atom_slot[fp.elem_g[w]];
      ready = std::max(ready, slot);
      if (raw < 0) {
        // fixed: read in place
      } else if (raw >= sec.bound) {
        ++count[section_of_slot[ws.atom_slot[raw]] + 1];
      } else {
        ready = std::max(ready, ws.atom_slot[raw]);
      }
      if ((w + 1 - sec.w_begin) % kBatch == 0 || w + 1 == sec.w_end) fp.section_ready.push_back(ready);
    }
  }
  for (int32_t t = 0; t < ns; ++t) count[t + 1] += count[t];
  fp.cross.assign(count[ns], 0);
  for (int32_t t = 0; t < ns; ++t) fp.section[t].cross_begin = count[t], fp.section[t].cross_end = count[t + 1];
  for (int32_t w = 0; w < ne; ++w) {
    const int32_t raw = fp.other[w];
    if (raw < 0) continue;
    const int32_t target = section_of_slot[ws.atom_slot[raw]];
    if (target != section_of_slot[ws.atom_slot[fp.elem_g[w]]]) fp.cross[count[target]++] = w;
  }
  fp.ghost_atoms.clear();
  for (int32_t t = 0; t < ns; ++t) {
    FusedPass::Section& sec = fp.section[t];
    sec.ghost_begin = static_cast<int32_t>(fp.ghost_atoms.size());
    for (int32_t c = sec.cross_begin; c < sec.cross_end; ++c) {
      const int32_t a = fp.other[fp.cross[c]];
      if (!seen[a]) seen[a] = 1, fp.ghost_atoms.push_back(a);
    }
    sec.ghost_end = static_cast<int32_t>(fp.ghost_atoms.size());
  }
  const size_t rows = 3 * static_cast<size_t>(m.num_atoms);
  if (fp.ghost_pos.size() != rows) fp.ghost_pos.assign(rows, Real(0)), fp.ghost_vel.assign(rows, Real(0));
  const size_t scratch = static_cast<size_t>(ns) * kScratchPerElement * kBatch;
  if (fp.scratch.size() < scratch) fp.scratch.assign(scratch, Real(0));
  fp.pool.Ensure(ns);
}

// The cross elements into section u, before the sweep (on u's thread): the tick-start copies
// of the atoms other sections read from u,
// and the cross elements' forces on u's atoms, in walk order, as Substep would add them: each
// such atom's sum then continues in u's sweep exactly as in one section's. Reads only tick-start
// state, which no thread writes until every section has done this; writes only u's atoms' sums,
// u's copies and u's scratch. The filter state is left alone (the sweep advances it).
void CrossForces(const Model& m, State& s, Workspace& ws, int32_t u, Real T, Rate rate) {
  FusedPass& fp = *ws.fused;
  const FusedPass::Section& sec = fp.section[u];
  const Real *const pos = s.atom_pos.data(), *const vel = s.atom_vel.data();
  auto copy = [&](int32_t from, int32_t to) {
    for (int32_t i = from; i < to; ++i) {
      const int32_t a = fp.ghost_atoms[i];
      for (int c = 0; c < 3; ++c) fp.ghost_pos[3 * a + c] = pos[3 * a + c], fp.ghost_vel[3 * a + c] = vel[3 * a + c];
    }
  };
  copy(sec.ghost_begin, sec.ghost_end);
  const Batch b = BatchViews(fp.scratch.data() + static_cast<size_t>(u) * kScratchPerElement * kBatch);
  Real* const force = fp.force.data();
  const int32_t last = m.num_atoms - 1;
  uint64_t degenerate[kMaskWords];
  for (int32_t c0 = sec.cross_begin; c0 < sec.cross_end; c0 += kBatch) {
    const int32_t nb = std::min(kBatch, sec.cross_end - c0);
    for (int32_t j = 0; j < nb; ++j) {
      const int32_t w = fp.cross[c0 + j], o = fp.other[w], g = fp.elem_g[w];
      StoreRow(b.s4 + 4 * j, LoadAtom(pos, o, last) - LoadAtom(pos, g, last));
      if (rate == Rate::kAnalytic) StoreRow(b.dv4 + 4 * j, LoadAtom(vel, o, last) - LoadAtom(vel, g, last));
      b.k[j] = fp.elem_k[w], b.b[j] = fp.elem_b[w], b.leq[j] = fp.elem_leq[w];
      if (IsFiltered(rate)) {
        const Real old_len = s.elem_len[w];  // identity: element w
        b.prev_len[j] = old_len, b.prev_rate[j] = s.elem_rate[w];
        b.fresh[j] = old_len != kFilterRestart ? Real(1) : Real(0);
      }
    }
    const BatchIo io{.n = nb,
                     .inv_t = Real(1) / T,
                     .lambda = static_cast<Real>(ws.options.lambda),
                     .k = b.k,
                     .b = b.b,
                     .leq = b.leq,
                     .s4 = b.s4,
                     .dv4 = b.dv4,
                     .prev_len = b.prev_len,
                     .prev_rate = b.prev_rate,
                     .fresh = b.fresh,
                     .len = b.new_len,
                     .rate = b.new_rate,
                     .backup_len = nullptr,
                     .backup_rate = nullptr,
                     .ex = b.ex,
                     .ey = b.ey,
                     .ez = b.ez,
                     .degenerate = degenerate,
                     .energy = nullptr};
    BatchForces(rate, /*direct_in=*/false, ws.options.fused_avx2, io);
    for (int32_t j = 0; j < nb; ++j) {
      const int32_t w = fp.cross[c0 + j], o = fp.other[w];
      if ((degenerate[j / 64] >> (j % 64) & 1) == 0) {
        Store4(force + 4 * o, Load4(force + 4 * o) - Make4(b.ex[j], b.ey[j], b.ez[j]));
        continue;
      }
      // Substep::Degenerate's push on the far endpoint.
      V4 f;
      if (!DegeneratePush(m, fp, w, w, &f)) continue;
      Store4(force + 4 * o, fp.elem_g[w] == m.elem_atoms[2 * w] ? Load4(force + 4 * o) + f : Load4(force + 4 * o) - f);
    }
  }
}

// The end-of-tick elastic energy of every cross element (Substep::ElasticAfter leaves them out),
// once every section is done.
double CrossElasticAfter(const Model& m, const State& s, Workspace& ws) {
  FusedPass& fp = *ws.fused;
  const Batch b = BatchViews(fp.scratch.data());
  const Real* const pos = s.atom_pos.data();
  const int32_t last = m.num_atoms - 1, total = static_cast<int32_t>(fp.cross.size());
  double sum = 0;
  for (int32_t c0 = 0; c0 < total; c0 += kBatch) {
    const int32_t nb = std::min(kBatch, total - c0);
    for (int32_t j = 0; j < nb; ++j) {
      const int32_t w = fp.cross[c0 + j];
      const V4 d = LoadAtom(pos, fp.other[w], last) - LoadAtom(pos, fp.elem_g[w], last);
      b.end_len2[j] = X(d) * X(d) + Y(d) * Y(d) + Z(d) * Z(d);
      b.k[j] = fp.elem_k[w], b.leq[j] = fp.elem_leq[w];
    }
    sum += BatchElastic(ws.options.fused_avx2, nb, b.end_len2, b.k, b.leq);
  }
  return sum;
}

// One substep of a sectioned walk: CrossForces, then the sections' sweeps, each on its thread.
struct SectionsRun {
  const Model* m;
  State* s;
  Workspace* ws;
  Real T;
  Rate rate;
  bool backup, before, after;
  SubstepFn substep;
  Progress progress[kMaxSections];
};

void CrossTask(void* context, int32_t u) {
  SectionsRun& r = *static_cast<SectionsRun*>(context);
  CrossForces(*r.m, *r.s, *r.ws, u, r.T, r.rate);
}

void SweepTask(void* context, int32_t t) {
  SectionsRun& r = *static_cast<SectionsRun*>(context);
  r.progress[t] = r.substep(*r.m, *r.s, *r.ws, r.T, r.backup, r.before, r.after, t);
  StreamFence();  // the rollback copy's non-temporal stores, before the join publishes them
}

// The sections' progress as one: sums in section order, the largest of the maxima; not ok if
// any section stopped. atoms / elems are not used (RunFused restores section by section).
Progress RunSections(SectionsRun& r) {
  FusedPass& fp = *r.ws->fused;
  WorkerPool& pool = fp.pool.Ensure(fp.sections);
  pool.Run(CrossTask, &r);
  pool.Run(SweepTask, &r);
  Progress p;
  for (int32_t t = 0; t < fp.sections; ++t) {
    const Progress& q = r.progress[t];
    p.ok = p.ok && q.ok;
    p.kinetic_before += q.kinetic_before, p.kinetic_after += q.kinetic_after;
    p.elastic_before += q.elastic_before, p.stretch_k += q.stretch_k, p.sum_k += q.sum_k;
    p.elastic_after += q.elastic_after;
    p.abs_pos = std::max(p.abs_pos, q.abs_pos), p.moved = std::max(p.moved, q.moved);
  }
  if (p.ok && r.after) p.elastic_after += CrossElasticAfter(*r.m, *r.s, *r.ws);
  return p;
}

// The pass's arrays from the live lists: groups by lowest free endpoint (the order
// BuildActiveSet appends elements in), the other endpoint, model values as Real, and the
// tool-free stable step. No allocation: every array was sized for the whole model.
void BuildFusedPass(const Model& m, Workspace& ws) {
  FusedPass& fp = *ws.fused;
  const int32_t n = ws.num_active, ne = ws.num_elems;
  std::fill(fp.group_end.begin(), fp.group_end.begin() + n, 0);
  fp.identity = true;
  int32_t last_slot = 0, ready = 0;
  for (int32_t w = 0; w < ne; ++w) {
    const int32_t e = ws.elems[w];
    const int32_t a0 = m.elem_atoms[2 * e], a1 = m.elem_atoms[2 * e + 1];
    const bool free0 = !m.atom_fixed[a0], free1 = !m.atom_fixed[a1];
    const int32_t g = free0 && free1 ? std::min(a0, a1) : (free0 ? a0 : a1);
    const int32_t o = g == a0 ? a1 : a0;
    const int32_t slot = ws.atom_slot[g];
    IDMS_CHECK(slot >= last_slot);  // the walk visits groups in slot order
    last_slot = slot;
    ++fp.group_end[slot];
    fp.other[w] = m.atom_fixed[o] ? ~o : o;
    fp.elem_g[w] = g;
    fp.elem_k[w] = static_cast<Real>(m.elem_k[e]);
    fp.elem_b[w] = static_cast<Real>(m.elem_b[e]);
    fp.elem_leq[w] = static_cast<Real>(m.elem_leq[e]);
    fp.identity = fp.identity && e == w;
    // The highest free endpoint's slot in this batch and every earlier one (Substep::ElasticAfter).
    ready = std::max(ready, m.atom_fixed[o] ? slot : std::max(slot, ws.atom_slot[o]));
    if ((w + 1) % kBatch == 0 || w + 1 == ne) fp.batch_ready[w / kBatch] = ready;
  }
  int32_t end = 0;
  for (int32_t i = 0; i < n; ++i) end += fp.group_end[i], fp.group_end[i] = end;
  // The minimum stable step without tools (extra_k is 0 between steps).
  const Integrator integrator = ws.options.integrator;
  const LengthRate rate = UsesFilter(ws.options, integrator) ? LengthRate::kFiltered : LengthRate::kAnalytic;
  fp.dt_free = std::numeric_limits<double>::infinity();
  fp.dt_free_count = 0;
  for (int32_t i = 0; i < n; ++i) {
    const int32_t a = ws.active[i];
    const AtomBound bound{m.atom_omega2[a] + ws.atom_extra_k[a] / m.atom_mass[a],
                          m.atom_damp[a] + ws.options.air_damping};
    const double dt = StableDt(integrator, bound, rate, ws.options.lambda);
    if (dt < fp.dt_free) {
      fp.dt_free = dt, fp.dt_free_count = 1;
    } else if (dt == fp.dt_free) {
      ++fp.dt_free_count;
    }
  }
  fp.t_over_m_of = 0;
  fp.topology_version = m.topology_version;
  BuildSections(m, ws);
}

}  // namespace

bool FusedEligible(const Model& m, const Workspace& ws) {
  const StepOptions& o = ws.options;
  const bool euler = o.integrator == Integrator::kExplicitEuler || o.integrator == Integrator::kSymplecticEuler;
  // A needle inside, or a suture's punctures, stiffen atoms beyond the tools' reach, which the
  // pass's stable-step cache and ClearExtraK do not cover: the general kernel takes those ticks.
  return o.full && o.fused_pass && euler && ws.num_pending_cuts == 0 && ws.fused != nullptr &&
         static_cast<int32_t>(ws.fused->group_end.size()) == m.num_atoms && !NeedleInside(ws) && !ws.suture_on;
}

void SizeFusedPass(const Model& m, Workspace& ws) {
  ws.fused.Emplace();
  FusedPass& fp = *ws.fused;
  fp.group_end.assign(m.num_atoms, 0);
  fp.atom_t_over_m.assign(m.num_atoms, Real(0));
  fp.other.assign(m.num_elems, 0);
  fp.elem_g.assign(m.num_elems, 0);
  fp.elem_k.assign(m.num_elems, Real(0));
  fp.elem_b.assign(m.num_elems, Real(0));
  fp.elem_leq.assign(m.num_elems, Real(0));
  fp.force.assign(4 * static_cast<size_t>(m.num_atoms), Real(0));
  fp.scratch.assign(kScratchPerElement * kBatch, Real(0));
  fp.batch_ready.assign(m.num_elems / kBatch + 1, 0);
  if constexpr (kRowBackup) fp.backup_rows.assign(8 * static_cast<size_t>(m.num_atoms), Real(0));
}

HugeRange HugePageInterior(const void* data, size_t bytes) {
  constexpr uintptr_t kHuge = uintptr_t{2} << 20;
  const uintptr_t start = reinterpret_cast<uintptr_t>(data);
  if (data == nullptr || bytes < kHuge || start > UINTPTR_MAX - bytes) return {};
  const uintptr_t begin = (start + kHuge - 1) & ~(kHuge - 1), end = (start + bytes) & ~(kHuge - 1);
  if (end <= begin) return {};
  return {begin, end - begin};
}

namespace {

// MADV_COLLAPSE (Linux 6.1) copies the range into huge pages now, whatever the system's THP
// setting ("madvise" on Debian); glibc 2.36's headers predate it.
#if defined(__linux__) && !defined(MADV_COLLAPSE)
constexpr int MADV_COLLAPSE = 25;
#endif

// Bytes of v the kernel put on huge pages (0 where it declined, or off Linux).
template <class T>
int64_t AdviseHuge(const std::vector<T>& v) {
#if defined(__linux__)
  const HugeRange r = HugePageInterior(v.data(), v.size() * sizeof(T));
  if (r.length == 0) return 0;
  // The contents stay as they are; failure (an older kernel, no free huge page) only costs speed.
  return madvise(reinterpret_cast<void*>(r.begin), r.length, MADV_COLLAPSE) == 0 ? static_cast<int64_t>(r.length) : 0;
#else
  (void)v;
  return 0;
#endif
}

}  // namespace

void EnsureFullLive(const Model& m, State& s, Workspace& ws) {
  FusedPass& fp = *ws.fused;
  if (fp.live && fp.topology_version == m.topology_version) return;
  EndFullLive(ws);
  BuildActiveSet(m, s, ws);
  BuildFusedPass(m, ws);
  fp.live = true;
}

void EndFullLive(Workspace& ws) {
  if (ws.fused == nullptr || !ws.fused->live) return;
  ClearTickScratch(ws);
  ws.fused->live = false;
  ws.fused->force_zero = false;
}

void ClearExtraK(Workspace& ws) {
  bool contact = false;
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    const ActiveTool& at = ws.tools[t];
    contact = contact || IsContactTool(at.kind);
    if (at.grasp_atom >= 0) ws.atom_extra_k[at.grasp_atom] = 0;
    for (int i = 0; i < kAnchorAtoms && at.anchor_atoms[i] >= 0; ++i) ws.atom_extra_k[at.anchor_atoms[i]] = 0;
  }
  if (!contact) return;
  for (int32_t i = 0; i < ws.num_reach; ++i) ws.atom_extra_k[ws.reach[i]] = 0;
}

double FullPredictStableDt(const Model& m, const Workspace& ws, Integrator integrator) {
  const FusedPass& fp = *ws.fused;
  const LengthRate rate = UsesFilter(ws.options, integrator) ? LengthRate::kFiltered : LengthRate::kAnalytic;
  const double air = ws.options.air_damping, lambda = ws.options.lambda;
  auto dt_of = [&](int32_t a, double extra_k) {
    const AtomBound bound{m.atom_omega2[a] + extra_k / m.atom_mass[a], m.atom_damp[a] + air};
    return StableDt(integrator, bound, rate, lambda);
  };
  // Only atoms a tool stiffens (within reach, which include grasped atoms) differ from the cache;
  // the cached minimum stands when some untouched atom still reaches it.
  double dt = fp.dt_free;
  int32_t touched_at_min = 0;
  bool contact = false;
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    contact = contact || IsContactTool(ws.tools[t].kind);
  }
  if (integrator == ws.options.integrator && !contact) return dt;
  if (integrator == ws.options.integrator) {
    for (int32_t i = 0; i < ws.num_reach; ++i) {
      const int32_t a = ws.reach[i];
      if (ws.atom_extra_k[a] == 0 || m.atom_fixed[a]) continue;
      touched_at_min += dt_of(a, 0.0) == fp.dt_free;
      dt = std::min(dt, dt_of(a, ws.atom_extra_k[a]));
    }
    if (touched_at_min < fp.dt_free_count) return dt;
  }
  dt = std::numeric_limits<double>::infinity();
  for (int32_t i = 0; i < ws.num_active; ++i) dt = std::min(dt, dt_of(ws.active[i], ws.atom_extra_k[ws.active[i]]));
  return dt;
}

bool RunFused(const Model& m, State& s, Workspace& ws, Integrator integrator, int32_t substeps, StageTimes* times,
              FusedEnergy* energy) {
  const StepOptions& o = ws.options;
  const Real T = static_cast<Real>(o.dt_s / substeps);
  const bool filter = m.has_damping && UsesFilter(o, integrator);
  const bool field = o.gravity || o.air_damping > 0;  // the external forces come in Integrate
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    std::fill(ws.tools[t].tick_force, ws.tools[t].tick_force + 3, 0.0);
    std::fill(ws.tools[t].tick_friction, ws.tools[t].tick_friction + 3, 0.0);
    ws.tools[t].tick_fn = 0;
  }
  // T / m by slot: one division per atom when T changes rather than in every substep.
  if (ws.fused->t_over_m_of != T) {
    for (int32_t i = 0; i < ws.num_active; ++i) {
      ws.fused->atom_t_over_m[i] = T / static_cast<Real>(m.atom_mass[ws.active[i]]);
    }
    ws.fused->t_over_m_of = T;
  }
  // Only a sectioned pass sets up its 64 sections' progress (not every one-thread tick).
  std::optional<SectionsRun> sections;
  for (int32_t k = 0; k < substeps; ++k) {
    // The energy check's sums: at the tick's start in the first substep, at its end in the last.
    const bool before = energy && k == 0, after = energy && k == substeps - 1;
    Progress p;
    {
      StageTimer timer(&times->forces_ns);
      // Field and tool forces first, as EvaluateForces adds them; then the sweep.
      if (field || !ws.fused->force_zero) FieldForces(m, s, ws, ws.fused->force.data(), 4);
      ToolForces(s, ws, ws.fused->force.data(), 4);
      for (int32_t t = 0; t < ws.num_tools; ++t) {
        for (int c = 0; c < 3; ++c) ws.tools[t].tick_force[c] += 1.0 / substeps * ws.tools[t].eval_force[c];
        for (int c = 0; c < 3; ++c) ws.tools[t].tick_friction[c] += 1.0 / substeps * ws.tools[t].eval_friction[c];
        ws.tools[t].tick_fn += 1.0 / substeps * ws.tools[t].eval_fn;
      }
      ws.fused->force_zero = false;
      const Rate rate = !m.has_damping ? Rate::kNone : filter ? Rate::kFiltered : Rate::kAnalytic;
      const bool sectioned = ws.fused->sections > 1;
      const SubstepFn substep =
          PickSubstep(integrator == Integrator::kSymplecticEuler, rate, ws.fused->identity, before || after, sectioned);
      if (sectioned) {
        if (!sections) sections.emplace();
        sections->m = &m, sections->s = &s, sections->ws = &ws, sections->T = T, sections->rate = rate;
        sections->backup = k == 0, sections->before = before, sections->after = after, sections->substep = substep;
        p = RunSections(*sections);
      } else {
        p = substep(m, s, ws, T, /*backup=*/k == 0, before, after, 0);
      }
    }
    if (before) {
      energy->kinetic_before = p.kinetic_before;
      energy->elastic_before = p.elastic_before;
      // ActiveEnergy's rounding noise, sum of k (|l - l_eq| + dl) dl with dl = eps (|p|_1 + 1) for
      // the largest |p|_1 of a free atom, as ActiveEnergy bounds it.
      const double dl = 4 * std::numeric_limits<Real>::epsilon() * (p.abs_pos + 1);
      energy->noise_before = dl * p.stretch_k + dl * dl * p.sum_k;
    }
    if (after) energy->kinetic_after = p.kinetic_after, energy->elastic_after = p.elastic_after;
    ws.reach_slack -= p.moved;  // the tools' next loops see whether an atom may have come in
    if (!p.ok && ws.fused->sections > 1 && k == 0) {
      for (int32_t t = 0; t < ws.fused->sections; ++t) {
        const FusedPass::Section& sec = ws.fused->section[t];
        const Progress& q = sections->progress[t];
        RestoreWritten(s, ws, q.atoms, q.elems, filter, sec.slot_begin, sec.w_begin);
      }
      return false;
    }
    if (!p.ok) {
      RestoreWritten(s, ws, k == 0 ? p.atoms : ws.num_active, k == 0 ? p.elems : ws.num_elems, filter);
      return false;
    }
    ws.fused->force_zero = true;
  }
  StreamFence();
  return true;
}

void RestoreFused(const Model& m, State& s, Workspace& ws) {
  const bool filter = m.has_damping && UsesFilter(ws.options, ws.options.integrator);
  RestoreWritten(s, ws, ws.num_active, ws.num_elems, filter);
}

FusedPassPtr::FusedPassPtr() = default;
FusedPassPtr::~FusedPassPtr() = default;
FusedPassPtr::FusedPassPtr(const FusedPassPtr& other)
    : p_(other.p_ ? std::make_unique<FusedPass>(*other.p_) : nullptr) {}
FusedPassPtr::FusedPassPtr(FusedPassPtr&& other) noexcept = default;
FusedPassPtr& FusedPassPtr::operator=(const FusedPassPtr& other) {
  if (this != &other) p_ = other.p_ ? std::make_unique<FusedPass>(*other.p_) : nullptr;
  return *this;
}
FusedPassPtr& FusedPassPtr::operator=(FusedPassPtr&& other) noexcept = default;
void FusedPassPtr::Emplace() { p_ = std::make_unique<FusedPass>(); }

bool FusedLive(const Workspace& ws) { return ws.fused != nullptr && ws.fused->live; }

void ResetFused(Workspace& ws) {
  if (ws.fused != nullptr) ws.fused->live = ws.fused->force_zero = false;
}

}  // namespace idms::internal

namespace idms {

FusedPassStatus GetFusedPassStatus(const Workspace& ws) {
  FusedPassStatus status;
  if (ws.fused == nullptr) return status;
  status.live = ws.fused->live;
  status.identity = ws.fused->identity;
  status.huge_bytes = ws.fused->huge_bytes;
  status.row_backup = internal::kRowBackup;
  status.sections = ws.fused->sections;
  status.cross_elements = ws.fused->sections > 1 ? static_cast<int64_t>(ws.fused->cross.size()) : 0;
  return status;
}

int64_t AdviseHugePages(const State& s, Workspace& ws) {
  using internal::AdviseHuge;
  if (ws.fused == nullptr) return 0;
  internal::FusedPass& fp = *ws.fused;
  const int64_t bytes =
      AdviseHuge(fp.other) + AdviseHuge(fp.elem_k) + AdviseHuge(fp.elem_b) + AdviseHuge(fp.elem_leq) +
      AdviseHuge(fp.force) + AdviseHuge(fp.group_end) + AdviseHuge(fp.atom_t_over_m) + AdviseHuge(ws.active) +
      AdviseHuge(ws.elems) + AdviseHuge(ws.backup_elem_len) + AdviseHuge(ws.backup_elem_rate) +
      (internal::kRowBackup ? AdviseHuge(fp.backup_rows) : AdviseHuge(ws.backup_pos) + AdviseHuge(ws.backup_vel)) +
      AdviseHuge(s.atom_pos) + AdviseHuge(s.atom_vel) + AdviseHuge(s.elem_len) + AdviseHuge(s.elem_rate);
  fp.huge_bytes += bytes;
  return bytes;
}

}  // namespace idms
