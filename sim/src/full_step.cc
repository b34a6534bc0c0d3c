// Full mode's fused pass (Workspace::FullPass): element forces (eqs. 4.3-4.9), their per-atom
// sums and the integration of each free atom (eqs. 4.13-4.15, or symplectic Euler) in one sweep,
// with the general path's arithmetic in the general path's order, so it gives the same bits.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "idms/sim/check.h"
#include "idms/sim/integrate.h"
#include "idms/sim/model.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms::internal {
namespace {

// Where the eq. 4.8 length rate comes from in this pass.
enum class Rate : uint8_t {
  kNone,             // no element has b > 0: no rate, no filter
  kAnalytic,         // s^ . (v1 - v0)
  kFiltered,         // eq. 4.6; every element was updated in the previous substep, none degenerate
  kFilteredMarked,   // eq. 4.6; as kFiltered, but some carry a restart mark (kFilterRestart)
  kFilteredStamped,  // eq. 4.6, freshness read from each element's stamp (first fused substep)
};

constexpr bool IsFiltered(Rate rate) {
  return rate == Rate::kFiltered || rate == Rate::kFilteredMarked || rate == Rate::kFilteredStamped;
}

// An atom's three components and a fourth lane, as one vector: GCC and Clang vector extensions
// when the target has registers that wide (float: SSE or NEON; double: AVX), else four plain
// values that the compiler keeps in registers (a 32-byte vector type emulated on SSE2 goes
// through memory: half the speed). Lane-wise IEEE arithmetic either way, so the same bits as the
// general path's scalar code.
#if defined(IDMS_SIM_REAL_FLOAT) || defined(__AVX__)
using V4 = Real __attribute__((vector_size(4 * sizeof(Real))));

inline V4 Make4(Real x, Real y, Real z) { return V4{x, y, z, 0}; }
inline Real X(const V4& v) { return v[0]; }
inline Real Y(const V4& v) { return v[1]; }
inline Real Z(const V4& v) { return v[2]; }
inline V4 Load4(const Real* p) {
  V4 v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}
inline void Store4(Real* p, V4 v) { std::memcpy(p, &v, sizeof(v)); }
inline void Store3(Real* p, V4 v) { std::memcpy(p, &v, 3 * sizeof(Real)); }

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
inline V4 LoadAtom(const Real* base, int32_t a, int32_t) { return Load4(base + 3 * a); }
#endif

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

// Copies n values (dst 16-byte aligned) with non-temporal stores.
inline void StreamCopy(Real* dst, const Real* src, int32_t n) {
  int32_t j = 0;
#if defined(__SSE2__)
  constexpr int32_t kLanes = 16 / sizeof(Real);
  if (reinterpret_cast<uintptr_t>(dst) % 16 == 0) {
    for (; j + kLanes <= n; j += kLanes) {
      if constexpr (sizeof(Real) == 4) {
        _mm_stream_ps(reinterpret_cast<float*>(dst + j), _mm_loadu_ps(reinterpret_cast<const float*>(src + j)));
      } else {
        _mm_stream_pd(reinterpret_cast<double*>(dst + j), _mm_loadu_pd(reinterpret_cast<const double*>(src + j)));
      }
    }
  }
#endif
  for (; j < n; ++j) StreamStore(dst + j, src[j]);
}

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
inline void StreamStore3(Real* dst, V4 v) {
#if defined(__SSE2__) && defined(IDMS_SIM_REAL_FLOAT)
  const __m128i bits = _mm_castps_si128(std::bit_cast<__m128>(v));
  _mm_stream_si64(reinterpret_cast<long long*>(dst), _mm_cvtsi128_si64(bits));
  StreamStore(dst + 2, Z(v));
#else
  StreamStore(dst, X(v)), StreamStore(dst + 1, Y(v)), StreamStore(dst + 2, Z(v));
#endif
}

inline void StreamFence() {
#if defined(__SSE2__)
  _mm_sfence();
#endif
}

// Elements per batch: the batch's temporaries (15 values per element) stay in L1.
constexpr int32_t kBatch = 128;

// The per-batch temporaries, views into FullPass::scratch.
struct Batch {
  Real *dx, *dy, *dz;     // (kBatch) s' = p_other - p_g, by component (so phase 2 vectorises)
  Real *dvx, *dvy, *dvz;  // (kBatch) v_other - v_g (analytic rate)
  Real *ex, *ey, *ez;     // (kBatch) the element's force on g (eq. 4.9, g's frame)
  Real* l;                // (kBatch) eq. 4.4
  Real* prev_len;         // (kBatch) eq. 4.6 inputs when they are gathered
  Real* prev_rate;        // (kBatch)
  Real* fresh;            // (kBatch) 1 = continue the filter, 0 = restart it
  Real* new_len;          // (kBatch) eq. 4.6 outputs when they are scattered
  Real* new_rate;         // (kBatch)
};

Batch BatchViews(FullPass& fp) {
  Real* p = fp.scratch.data();
  Batch b;
  b.dx = p, b.dy = p + kBatch, b.dz = p + 2 * kBatch;
  b.dvx = p + 3 * kBatch, b.dvy = p + 4 * kBatch, b.dvz = p + 5 * kBatch;
  b.ex = p + 6 * kBatch, b.ey = p + 7 * kBatch, b.ez = p + 8 * kBatch;
  b.l = p + 9 * kBatch, b.prev_len = p + 10 * kBatch, b.prev_rate = p + 11 * kBatch;
  b.fresh = p + 12 * kBatch, b.new_len = p + 13 * kBatch, b.new_rate = p + 14 * kBatch;
  return b;
}
constexpr int32_t kScratchPerElement = 15;

// How far a substep got: atoms [0, atoms) by slot and elements [0, elems) by walk index have
// been written (and copied). ok = false: it stopped at a non-finite input or result.
struct Progress {
  int32_t atoms = 0;
  int32_t elems = 0;
  int32_t marks = 0;  // filters marked to restart (degenerate elements)
  bool ok = true;
};

// Phase 2's arrays, each a restrict parameter (GCC ignores restrict on locals and members), written
// once for the functions below.
#define IDMS_BATCH_PARAMS                                                                                             \
  int32_t n, Real inv_t, Real lambda, const Real *__restrict k, const Real *__restrict b, const Real *__restrict leq, \
      const Real *__restrict dx, const Real *__restrict dy, const Real *__restrict dz, const Real *__restrict dvx,    \
      const Real *__restrict dvy, const Real *__restrict dvz, const Real *__restrict prev_len,                        \
      const Real *__restrict prev_rate, const Real *__restrict fresh, Real *__restrict len, Real *__restrict rate_io, \
      Real *__restrict l_out, Real *__restrict ex, Real *__restrict ey, Real *__restrict ez
#define IDMS_BATCH_ARGS \
  n, inv_t, lambda, k, b, leq, dx, dy, dz, dvx, dvy, dvz, prev_len, prev_rate, fresh, len, rate_io, l_out, ex, ey, ez

// Phase 2 of a batch: eqs. 4.4-4.9 for n elements in contiguous arrays, as one loop the compiler
// vectorises. len and rate hold the eq. 4.6 state in place (kDirectIn; kFilterRestart marks a
// filter to restart, looked for only with kFilteredMarked) or receive it (inputs then come
// gathered, with fresh = 0 restarting the filter: l_{n-1} = l, l'_{n-1} = 0). A degenerate
// element's new state is replaced by a restart mark in phase 3.
template <Rate kRate, bool kDirectIn>
[[gnu::always_inline]] inline void BatchForcesBody(IDMS_BATCH_PARAMS) {
  constexpr bool kFilter = IsFiltered(kRate);
  for (int32_t j = 0; j < n; ++j) {
    const Real sx = dx[j], sy = dy[j], sz = dz[j];
    const Real l = std::sqrt(sx * sx + sy * sy + sz * sz);
    l_out[j] = l;
    [[maybe_unused]] Real rate = 0;
    if constexpr (kFilter) {
      Real pl, pr;
      if constexpr (kDirectIn && kRate == Rate::kFilteredMarked) {
        const Real old_len = len[j], old_rate = rate_io[j];
        const bool keep = old_len != kFilterRestart;
        pl = keep ? old_len : l;
        pr = keep ? old_rate : Real(0);
      } else if constexpr (kDirectIn) {
        pl = len[j], pr = rate_io[j];
      } else {
        const Real gathered_len = prev_len[j], gathered_rate = prev_rate[j];
        pl = fresh[j] != 0 ? gathered_len : l;
        pr = fresh[j] != 0 ? gathered_rate : Real(0);
      }
      rate = lambda * (l - pl) * inv_t + (Real(1) - lambda) * pr;
      len[j] = l;
      rate_io[j] = rate;
    }
    // eqs. 4.7-4.9 as a multiple of s'.
    const Real inv_l = Real(1) / l;
    Real mag = k[j] * (Real(1) - leq[j] * inv_l);
    if constexpr (kRate == Rate::kAnalytic) rate = (dvx[j] * sx + dvy[j] * sy + dvz[j] * sz) * inv_l;
    if constexpr (kRate != Rate::kNone) mag += b[j] * rate * inv_l;
    ex[j] = mag * sx, ey[j] = mag * sy, ez[j] = mag * sz;
  }
}

// Phase 2 for the baseline target (SSE2 on x86-64) and, on x86-64, a clone for AVX2 (8 floats or
// 4 doubles per instruction) chosen once at run time: the default build runs on any x86-64 and
// uses AVX2 where it exists. The same IEEE operations in both (no FMA: -ffp-contract=off), so the
// same bits. Rejected: -march=native (the binary must run on any CI machine); compiling the whole
// file twice (inline functions it shares with other files could be linked in their AVX2 form and
// fault on an older CPU); passing the arrays in a struct (GCC then loses their restrict and the
// loop runs 9% slower).
template <Rate kRate, bool kDirectIn>
void BatchForcesBase(IDMS_BATCH_PARAMS) {
  BatchForcesBody<kRate, kDirectIn>(IDMS_BATCH_ARGS);
}

#if defined(__x86_64__) && !defined(__AVX2__)
template <Rate kRate, bool kDirectIn>
[[gnu::target("avx2")]] void BatchForcesAvx2(IDMS_BATCH_PARAMS) {
  BatchForcesBody<kRate, kDirectIn>(IDMS_BATCH_ARGS);
}
#endif

template <Rate kRate, bool kDirectIn>
void BatchForces([[maybe_unused]] bool allow_avx2, IDMS_BATCH_PARAMS) {
#if defined(__x86_64__) && !defined(__AVX2__)
  static const bool avx2 = __builtin_cpu_supports("avx2");
  if (avx2 && allow_avx2) return BatchForcesAvx2<kRate, kDirectIn>(IDMS_BATCH_ARGS);
#endif
  BatchForcesBase<kRate, kDirectIn>(IDMS_BATCH_ARGS);
}
#undef IDMS_BATCH_PARAMS
#undef IDMS_BATCH_ARGS

// One substep over every free atom in slot order. Group i holds the elements whose lowest free
// endpoint is atom g = active[i]; they are visited after every earlier group, so once group i is
// done g has all of its forces (no later element touches g) and is integrated in place. Element
// forces are formed in g's frame, s' = p_other - p_g: s' = +-s of eq. 4.3 exactly, so l, the
// rate and every force are the general path's bits, and each atom's sum is formed in the same
// order (field and tool forces first, then the elements in walk order).
//
// The walk goes in batches of kBatch elements, each in three phases: (1) gather s' (and the
// filter inputs that need an index or a stamp), (2) eqs. 4.4-4.9 for the whole batch in
// contiguous arrays, which the compiler vectorises, (3) the sums and integrations in walk order.
// A batch may only read atoms whose group has not ended, so no atom moves under a later batch.
template <bool kSymplectic, Rate kRate, bool kIdentity>
class Substep {
 public:
  static constexpr bool kFilter = IsFiltered(kRate);
  // Filter inputs read in place (else gathered in phase 1), outputs written in place.
  static constexpr bool kDirectIn = kIdentity && (kRate == Rate::kFiltered || kRate == Rate::kFilteredMarked);
  static constexpr bool kDirectOut = kIdentity;

  Substep(const Model& m, State& s, Workspace& ws, Real T, bool backup)
      : m_(m), s_(s), ws_(ws), fp_(ws.full), b_(BatchViews(ws.full)), T_(T), backup_(backup) {}

  Progress Run() {
    const int32_t n = ws_.num_active, ne = ws_.num_elems;
    Progress out;
    if (n == 0) return out;
    int32_t slot = 0, gather_slot = 0;
    int32_t g = ws_.active[0];
    V4 acc = Load4(force_ + 4 * g);  // g's sum so far: field, tools, earlier groups
    for (int32_t w0 = 0; w0 < ne; w0 += kBatch) {
      const int32_t nb = std::min(kBatch, ne - w0);
      out.elems = w0;
      if (!Gather(w0, nb, gather_slot)) return Stop(out, slot);
      const bool degenerate = Forces(w0, nb);
      out.elems = w0 + nb;
      // 3. Sums in walk order; each atom is integrated when its group ends.
      for (int32_t w = w0; w < w0 + nb; ++w) {
        while (fp_.group_end[slot] <= w) {
          if (!Integrate(slot, g, acc)) return Stop(out, slot);
          g = ws_.active[++slot];
          acc = Load4(force_ + 4 * g);
        }
        const int32_t j = w - w0;
        const int32_t raw = fp_.other[w];
        if (degenerate && b_.l[j] <= kMinLength) [[unlikely]] {
          if (!Degenerate(w, g, raw, acc)) return Stop(out, slot);
          continue;
        }
        const V4 e = Make4(b_.ex[j], b_.ey[j], b_.ez[j]);
        acc += e;
        if (raw >= 0) Store4(force_ + 4 * raw, Load4(force_ + 4 * raw) - e);
      }
    }
    // The last group, and free atoms after it whose elements all lie in earlier groups.
    for (;;) {
      if (!Integrate(slot, g, acc)) return Stop(out, slot);
      if (++slot == n) break;
      g = ws_.active[slot];
      acc = Load4(force_ + 4 * g);
    }
    out.atoms = n;
    out.marks = marks_;
    return out;
  }

 private:
  Progress Stop(Progress out, int32_t slot) {
    out.atoms = slot;
    out.ok = false;
    return out;
  }

  // 1. s' for each element of the batch (g's position reloaded at each group start); the eq. 4.6
  // inputs by element id, with the stale rule, when they cannot be read in place. False: a
  // non-finite filter state (the general path repairs it).
  bool Gather(int32_t w0, int32_t nb, int32_t& slot) {
    const int32_t* group_end = fp_.group_end.data();
    const int32_t* other = fp_.other.data();
    int32_t w = w0;
    while (w < w0 + nb) {
      while (group_end[slot] <= w) ++slot;
      const int32_t g = ws_.active[slot];
      const V4 pg = LoadAtom(pos_, g, last_);
      [[maybe_unused]] V4 vg = Make4(0, 0, 0);
      if constexpr (kRate == Rate::kAnalytic) vg = LoadAtom(vel_, g, last_);
      const int32_t end = std::min(group_end[slot], w0 + nb);
      for (; w < end; ++w) {
        const int32_t raw = other[w];
        const int32_t o = raw ^ (raw >> 31);  // ~raw for a fixed atom
        const int32_t j = w - w0;
        const V4 d = LoadAtom(pos_, o, last_) - pg;
        b_.dx[j] = X(d), b_.dy[j] = Y(d), b_.dz[j] = Z(d);
        if constexpr (kRate == Rate::kAnalytic) {
          const V4 dv = LoadAtom(vel_, o, last_) - vg;
          b_.dvx[j] = X(dv), b_.dvy[j] = Y(dv), b_.dvz[j] = Z(dv);
        }
        if constexpr (kFilter && !kDirectIn) {
          const int32_t e = kIdentity ? w : ws_.elems[w];
          const Real old_len = s_.elem_len[e], old_rate = s_.elem_rate[e];
          if (!(std::isfinite(old_len) && std::isfinite(old_rate))) [[unlikely]]
            return false;
          bool fresh = old_len != kFilterRestart;
          if constexpr (kRate == Rate::kFilteredStamped) {
            const int64_t stamp = s_.elem_stamp[e];
            fresh = fresh && (stamp > s_.elem_stamp_floor ? stamp : s_.elem_stamp_floor) == s_.substep_clock - 1;
          }
          b_.prev_len[j] = old_len;
          b_.prev_rate[j] = old_rate;
          b_.fresh[j] = fresh ? Real(1) : Real(0);
          if (backup_) StreamStore(&ws_.backup_elem_len[w], old_len), StreamStore(&ws_.backup_elem_rate[w], old_rate);
        }
      }
    }
    return true;
  }

  // 2. eqs. 4.4-4.9 over the batch (BatchForces); the filter state advances (a degenerate
  // element's is marked to restart), scattered by element id when the ids are not the walk order.
  // Returns whether any element is degenerate.
  bool Forces(int32_t w0, int32_t nb) {
    Real* len = kDirectOut ? s_.elem_len.data() + w0 : b_.new_len;
    Real* rate = kDirectOut ? s_.elem_rate.data() + w0 : b_.new_rate;
    if (kFilter && kDirectIn && backup_) {
      StreamCopy(ws_.backup_elem_len.data() + w0, len, nb);
      StreamCopy(ws_.backup_elem_rate.data() + w0, rate, nb);
    }
    const Real inv_t = Real(1) / T_, lambda = static_cast<Real>(ws_.options.lambda);
    BatchForces<kRate, kDirectIn>(fp_.avx2, nb, inv_t, lambda, fp_.elem_k.data() + w0, fp_.elem_b.data() + w0,
                                  fp_.elem_leq.data() + w0, b_.dx, b_.dy, b_.dz, b_.dvx, b_.dvy, b_.dvz, b_.prev_len,
                                  b_.prev_rate, b_.fresh, len, rate, b_.l, b_.ex, b_.ey, b_.ez);
    if constexpr (kFilter && !kDirectOut) {
      for (int32_t j = 0; j < nb; ++j) {
        const int32_t id = ws_.elems[w0 + j];
        s_.elem_len[id] = b_.new_len[j];
        s_.elem_rate[id] = b_.new_rate[j];
      }
    }
    int32_t degenerate = 0;
    for (int32_t j = 0; j < nb; ++j) degenerate += b_.l[j] <= kMinLength;
    return degenerate > 0;
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
      ++marks_;
    }
    const Real push = fp_.elem_k[w] * fp_.elem_leq[w];
    if (push <= 0) return true;
    const int32_t a0 = m_.elem_atoms[2 * e], a1 = m_.elem_atoms[2 * e + 1];
    Real dir[3];
    for (int c = 0; c < 3; ++c)
      dir[c] = static_cast<Real>((m_.atom_pos_eq[3 * a1 + c] - m_.atom_pos_eq[3 * a0 + c]) / m_.elem_leq[e]);
    // Atom 0 is pushed along -dir, atom 1 along +dir.
    const V4 f = push * Make4(dir[0], dir[1], dir[2]);
    const int32_t o = raw ^ (raw >> 31);
    if (g == a0) {
      acc -= f;
      if (raw >= 0) Store4(force_ + 4 * o, Load4(force_ + 4 * o) + f);
    } else {
      acc += f;
      if (raw >= 0) Store4(force_ + 4 * o, Load4(force_ + 4 * o) - f);
    }
    return true;
  }

  // Eqs. 4.13-4.15 (or symplectic Euler) for atom g of slot i, with its rollback copy. False: a
  // result is not finite (nothing is written).
  bool Integrate(int32_t i, int32_t g, V4 acc) {
    const V4 p = LoadAtom(pos_, g, last_), v = LoadAtom(vel_, g, last_);
    const Real t_over_m = T_ / fp_.atom_mass[i];
    V4 np, nv;
    if constexpr (kSymplectic) {
      nv = v + t_over_m * acc;
      np = p + T_ * nv;
    } else {
      np = p + T_ * v;
      nv = v + t_over_m * acc;
    }
    if (!Finite3((np - np) + (nv - nv))) [[unlikely]]
      return false;
    if (backup_) StreamStore3(&ws_.backup_pos[3 * i], p), StreamStore3(&ws_.backup_vel[3 * i], v);
    Store3(pos_ + 3 * g, np);
    Store3(vel_ + 3 * g, nv);
    // Cleared for the next tick, whose field forces are then zero unless the scene has some.
    Store4(force_ + 4 * g, Make4(0, 0, 0));
    return true;
  }

  const Model& m_;
  State& s_;
  Workspace& ws_;
  const FullPass& fp_;
  const Batch b_;
  const Real T_;
  const bool backup_;
  Real* const pos_ = s_.atom_pos.data();
  Real* const vel_ = s_.atom_vel.data();
  Real* const force_ = ws_.full.force.data();
  const int32_t last_ = m_.num_atoms - 1;
  int32_t marks_ = 0;
};

template <bool kSymplectic, Rate kRate, bool kIdentity>
Progress RunSubstep(const Model& m, State& s, Workspace& ws, Real T, bool backup) {
  return Substep<kSymplectic, kRate, kIdentity>(m, s, ws, T, backup).Run();
}

using SubstepFn = Progress (*)(const Model&, State&, Workspace&, Real, bool);

template <bool kSymplectic, bool kIdentity>
SubstepFn PickRate(Rate rate) {
  switch (rate) {
    case Rate::kNone:
      return RunSubstep<kSymplectic, Rate::kNone, kIdentity>;
    case Rate::kAnalytic:
      return RunSubstep<kSymplectic, Rate::kAnalytic, kIdentity>;
    case Rate::kFiltered:
      return RunSubstep<kSymplectic, Rate::kFiltered, kIdentity>;
    case Rate::kFilteredMarked:
      return RunSubstep<kSymplectic, Rate::kFilteredMarked, kIdentity>;
    case Rate::kFilteredStamped:
      break;
  }
  return RunSubstep<kSymplectic, Rate::kFilteredStamped, kIdentity>;
}

SubstepFn PickSubstep(bool symplectic, Rate rate, bool identity) {
  if (symplectic) return identity ? PickRate<true, true>(rate) : PickRate<true, false>(rate);
  return identity ? PickRate<false, true>(rate) : PickRate<false, false>(rate);
}

// Back to the tick's start from the rollback copy: the atoms and elements a failed substep had
// written (all of them after the first substep).
void RestoreWritten(State& s, Workspace& ws, int32_t atoms, int32_t elems, bool filter) {
  StreamFence();
  for (int32_t i = 0; i < atoms; ++i) {
    const int32_t a = ws.active[i];
    for (int c = 0; c < 3; ++c)
      s.atom_pos[3 * a + c] = ws.backup_pos[3 * i + c], s.atom_vel[3 * a + c] = ws.backup_vel[3 * i + c];
  }
  if (!filter) return;
  for (int32_t w = 0; w < elems; ++w) {
    const int32_t e = ws.elems[w];
    s.elem_len[e] = ws.backup_elem_len[w];
    s.elem_rate[e] = ws.backup_elem_rate[w];
  }
}

// The pass's arrays from the live lists: groups by lowest free endpoint (the order
// BuildActiveSet appends elements in), the other endpoint, model values as Real, and the
// tool-free stable step. No allocation: every array was sized for the whole model.
void BuildFullPass(const Model& m, Workspace& ws) {
  FullPass& fp = ws.full;
  const int32_t n = ws.num_active, ne = ws.num_elems;
  std::fill(fp.group_end.begin(), fp.group_end.begin() + n, 0);
  fp.identity = true;
  int32_t last_slot = 0;
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
    fp.elem_k[w] = static_cast<Real>(m.elem_k[e]);
    fp.elem_b[w] = static_cast<Real>(m.elem_b[e]);
    fp.elem_leq[w] = static_cast<Real>(m.elem_leq[e]);
    fp.identity = fp.identity && e == w;
  }
  int32_t end = 0;
  for (int32_t i = 0; i < n; ++i) end += fp.group_end[i], fp.group_end[i] = end;
  // Masses by slot, and the minimum stable step without tools (extra_k is 0 between steps).
  const Integrator integrator = ws.options.integrator;
  const LengthRate rate = UsesFilter(ws.options, integrator) ? LengthRate::kFiltered : LengthRate::kAnalytic;
  fp.dt_free = std::numeric_limits<double>::infinity();
  fp.dt_free_count = 0;
  for (int32_t i = 0; i < n; ++i) {
    const int32_t a = ws.active[i];
    fp.atom_mass[i] = static_cast<Real>(m.atom_mass[a]);
    const AtomBound bound{ws.atom_omega2[a] + ws.atom_extra_k[a] / m.atom_mass[a],
                          ws.atom_damp[a] + ws.options.air_damping};
    const double dt = StableDt(integrator, bound, rate, ws.options.lambda);
    if (dt < fp.dt_free) {
      fp.dt_free = dt, fp.dt_free_count = 1;
    } else if (dt == fp.dt_free) {
      ++fp.dt_free_count;
    }
  }
  fp.topology_version = m.topology_version;
}

}  // namespace

bool FusedEligible(const Model& m, const Workspace& ws) {
  const StepOptions& o = ws.options;
  const bool euler = o.integrator == Integrator::kExplicitEuler || o.integrator == Integrator::kSymplecticEuler;
  return o.full && ws.full.enabled && euler && !o.stability.energy_check && ws.num_pending_cuts == 0 &&
         static_cast<int32_t>(ws.full.group_end.size()) == m.num_atoms;
}

void SizeFullPass(const Model& m, Workspace& ws) {
  FullPass& fp = ws.full;
  fp.group_end.assign(m.num_atoms, 0);
  fp.atom_mass.assign(m.num_atoms, Real(0));
  fp.other.assign(m.num_elems, 0);
  fp.elem_k.assign(m.num_elems, Real(0));
  fp.elem_b.assign(m.num_elems, Real(0));
  fp.elem_leq.assign(m.num_elems, Real(0));
  fp.force.assign(4 * static_cast<size_t>(m.num_atoms), Real(0));
  fp.scratch.assign(kScratchPerElement * kBatch, Real(0));
}

void EnsureFullLive(const Model& m, State& s, Workspace& ws) {
  FullPass& fp = ws.full;
  if (fp.live && fp.topology_version == m.topology_version) return;
  EndFullLive(ws);
  BuildActiveSet(m, s, ws);
  BuildFullPass(m, ws);
  fp.live = true;
}

void EndFullLive(Workspace& ws) {
  ws.full.restart_marks = -1;
  if (!ws.full.live) return;
  ClearTickScratch(ws);
  ws.full.live = false;
  ws.full.force_zero = false;
}

void ClearExtraK(Workspace& ws) {
  bool contact = false;
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    const ActiveTool& at = ws.tools[t];
    contact = contact || at.kind == ToolKind::kSphere || at.kind == ToolKind::kTweezers;
    if (at.grasp_atom >= 0) ws.atom_extra_k[at.grasp_atom] = 0;
  }
  if (!contact) return;
  for (int32_t i = 0; i < ws.num_candidates; ++i) ws.atom_extra_k[ws.candidates[i]] = 0;
}

double FullPredictStableDt(const Model& m, const Workspace& ws, Integrator integrator) {
  const FullPass& fp = ws.full;
  const LengthRate rate = UsesFilter(ws.options, integrator) ? LengthRate::kFiltered : LengthRate::kAnalytic;
  const double air = ws.options.air_damping, lambda = ws.options.lambda;
  auto dt_of = [&](int32_t a, double extra_k) {
    const AtomBound bound{ws.atom_omega2[a] + extra_k / m.atom_mass[a], ws.atom_damp[a] + air};
    return StableDt(integrator, bound, rate, lambda);
  };
  // Only atoms a tool stiffens (candidates, which include grasped atoms) differ from the cache;
  // the cached minimum stands when some untouched atom still reaches it.
  double dt = fp.dt_free;
  int32_t touched_at_min = 0;
  bool contact = false;
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    contact = contact || ws.tools[t].kind == ToolKind::kSphere || ws.tools[t].kind == ToolKind::kTweezers;
  }
  if (integrator == ws.options.integrator && !contact) return dt;
  if (integrator == ws.options.integrator) {
    for (int32_t i = 0; i < ws.num_candidates; ++i) {
      const int32_t a = ws.candidates[i];
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

bool RunFused(const Model& m, State& s, Workspace& ws, Integrator integrator, int32_t substeps, StageTimes* times) {
  const StepOptions& o = ws.options;
  const Real T = static_cast<Real>(o.dt_s / substeps);
  const bool filter = ws.any_damping && UsesFilter(o, integrator);
  const bool field = o.gravity || o.air_damping > 0 || !ws.atom_force_external.empty();
  const int64_t clock0 = s.substep_clock, floor0 = s.elem_stamp_floor;
  for (int32_t t = 0; t < ws.num_tools; ++t) std::fill(ws.tools[t].tick_force, ws.tools[t].tick_force + 3, 0.0);
  for (int32_t k = 0; k < substeps; ++k) {
    const int64_t t0 = NowNs();
    // Field and tool forces first, as EvaluateForces adds them; then the sweep.
    if (field || !ws.full.force_zero) FieldForces(m, s, ws, ws.full.force.data(), 4);
    ToolForces(s, ws, ws.full.force.data(), 4);
    for (int32_t t = 0; t < ws.num_tools; ++t) {
      for (int c = 0; c < 3; ++c) ws.tools[t].tick_force[c] += 1.0 / substeps * ws.tools[t].eval_force[c];
    }
    ws.full.force_zero = false;
    // The filter's freshness: every element's when the last substep was this pass (then only
    // the elements it found degenerate carry a restart mark), else from the stamps.
    Rate rate = Rate::kFilteredStamped;
    if (!ws.any_damping) {
      rate = Rate::kNone;
    } else if (!filter) {
      rate = Rate::kAnalytic;
    } else if (s.elem_stamp_floor == s.substep_clock - 1 && ws.full.restart_marks >= 0) {
      rate = ws.full.restart_marks == 0 ? Rate::kFiltered : Rate::kFilteredMarked;
    }
    const SubstepFn substep = PickSubstep(integrator == Integrator::kSymplecticEuler, rate, ws.full.identity);
    const Progress p = substep(m, s, ws, T, /*backup=*/k == 0);
    times->forces_ns += NowNs() - t0;
    ws.full.restart_marks = p.marks;
    if (!p.ok) {
      ws.full.restart_marks = -1;
      RestoreWritten(s, ws, k == 0 ? p.atoms : ws.num_active, k == 0 ? p.elems : ws.num_elems, filter);
      s.substep_clock = clock0;
      s.elem_stamp_floor = floor0;
      return false;
    }
    if (filter) s.elem_stamp_floor = s.substep_clock;
    ++s.substep_clock;
    ws.full.force_zero = true;
  }
  StreamFence();
  return true;
}

}  // namespace idms::internal
