// Phase 2 of full mode's fused pass (full_step.cc): eqs. 4.4-4.9 for a batch of elements,
// vectorised by hand for the baseline x86-64 target and, chosen at run time, for AVX2.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <type_traits>

#include "full_step_internal.h"
#include "step_internal.h"

namespace idms::internal {
namespace {

// Phase 2 works on V = Real (one element) or a vector of lanes (one element each), with GCC and
// Clang vector extensions: one source for both, so every lane does the scalar code's IEEE
// operations in the scalar order (no FMA: -ffp-contract=off), and the AVX2 code gives the
// baseline code's bits. Vectors go by reference between these functions: compiled for the
// baseline target, they may not pass a 32-byte vector by value (Clang rejects it). Rejected:
// leaving the loop to the auto-vectoriser, which cannot load the rows below without strided
// loads (18% slower) and cannot write the rollback copy with non-temporal stores.
template <class V>
[[gnu::always_inline]] inline void LoadLanes(V& v, const Real* p) {
  std::memcpy(&v, p, sizeof(V));
}
template <class V>
[[gnu::always_inline]] inline void StoreLanes(Real* p, const V& v) {
  std::memcpy(p, &v, sizeof(V));
}

// The energy check's sums (BatchIo::energy) over lanes of elements, at their lengths l: the
// elastic energy as forces.cc's ActiveEnergy forms it, and what its rounding allowance needs.
template <class V>
struct EnergySums {
  V u{}, ks{}, k{};
};

// Called with phase 2's loads, before its stores (see ForceMultiple).
template <class V>
[[gnu::always_inline]] inline void AddEnergy(const V& l, const V& k, const V& leq, EnergySums<V>& e) {
  const V stretch = l - leq;
  e.u += Real(0.5) * k * stretch * stretch;
  e.ks += k * (stretch < Real(0) ? -stretch : stretch);
  e.k += k;
}

// Inline, as everything that touches an EnergySums: a sum whose address escapes lives in memory,
// where every vector store of the loop (memcpy) might write it (phase 2 ran 2.7 times as long).
template <class V>
[[gnu::always_inline]] inline double LaneSum(const V& v) {
  if constexpr (std::is_same_v<V, Real>) {
    return v;
  } else {
    double sum = 0;
    for (size_t i = 0; i < sizeof(V) / sizeof(Real); ++i) sum += v[i];
    return sum;
  }
}

template <class V>
[[gnu::always_inline]] inline void FlushEnergy(const BatchIo& io, const EnergySums<V>& e) {
  io.energy[0] += LaneSum(e.u), io.energy[1] += LaneSum(e.ks), io.energy[2] += LaneSum(e.k);
}

// Eqs. 4.6-4.9 for element j (V = Real) or elements j.. (vectors), given s', l = |s'| and, with
// kDirectIn, the filter state read in place: the filter state advances and mag is the force's
// multiple of s'. Every load comes before the first store: large arrays each start a page, so
// the arrays indexed by element share their offsets within a page, and a load that follows a
// store at the same offset of another page waits for it (4K aliasing; up to 10% at 10^6 atoms).
template <Rate kRate, bool kDirectIn, bool kEnergy, class V>
[[gnu::always_inline]] inline void ForceMultiple(const BatchIo& io, int32_t j, const V& l, const V& sx, const V& sy,
                                                 const V& sz, [[maybe_unused]] const V& dvx,
                                                 [[maybe_unused]] const V& dvy, [[maybe_unused]] const V& dvz,
                                                 [[maybe_unused]] const V& old_len, [[maybe_unused]] const V& old_rate,
                                                 V& mag, [[maybe_unused]] EnergySums<V>& energy) {
  V k, leq;
  [[maybe_unused]] V b{}, rate{};
  LoadLanes(k, io.k + j), LoadLanes(leq, io.leq + j);
  if constexpr (kEnergy) AddEnergy(l, k, leq, energy);
  if constexpr (kRate != Rate::kNone) LoadLanes(b, io.b + j);
  if constexpr (IsFiltered(kRate)) {
    V pl, pr;
    if constexpr (kDirectIn) {
      const auto keep = old_len != kFilterRestart;
      pl = keep ? old_len : l;
      pr = keep ? old_rate : V{};
    } else {
      V fresh, prev_len, prev_rate;
      LoadLanes(fresh, io.fresh + j), LoadLanes(prev_len, io.prev_len + j), LoadLanes(prev_rate, io.prev_rate + j);
      pl = fresh != Real(0) ? prev_len : l;
      pr = fresh != Real(0) ? prev_rate : V{};
    }
    // eq. 4.6: filtered length rate.
    rate = io.lambda * (l - pl) * io.inv_t + (Real(1) - io.lambda) * pr;
    StoreLanes(io.len + j, l);
    StoreLanes(io.rate + j, rate);
  }
  // eqs. 4.7-4.9 as a multiple of s'.
  const V inv_l = Real(1) / l;
  mag = k * (Real(1) - leq * inv_l);
  if constexpr (kRate == Rate::kAnalytic) rate = (dvx * sx + dvy * sy + dvz * sz) * inv_l;
  if constexpr (kRate != Rate::kNone) mag += b * rate * inv_l;
}

// Elements [j, n) one at a time: the tail after the vectors, or a whole batch where there are no
// vector registers.
template <Rate kRate, bool kDirectIn, bool kEnergy>
void BatchForcesScalar(const BatchIo io, int32_t j) {
  [[maybe_unused]] EnergySums<Real> energy;
  for (; j < io.n; ++j) {
    const Real* s = io.s4 + 4 * j;
    const Real l = std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
    Real dv[3] = {0, 0, 0}, old_len = 0, old_rate = 0;
    if constexpr (kRate == Rate::kAnalytic) std::memcpy(dv, io.dv4 + 4 * j, sizeof(dv));
    if constexpr (kDirectIn) {
      old_len = io.len[j], old_rate = io.rate[j];
      if (io.backup_len) StreamStore(io.backup_len + j, old_len), StreamStore(io.backup_rate + j, old_rate);
    }
    Real mag;
    ForceMultiple<kRate, kDirectIn, kEnergy>(io, j, l, s[0], s[1], s[2], dv[0], dv[1], dv[2], old_len, old_rate, mag,
                                             energy);
    io.ex[j] = mag * s[0], io.ey[j] = mag * s[1], io.ez[j] = mag * s[2];
    if (l <= kMinLength) io.degenerate[j / 64] |= uint64_t{1} << (j % 64);
  }
  if constexpr (kEnergy) FlushEnergy(io, energy);
}

#if defined(__SSE2__)
// The baseline target: 4 floats or 2 doubles per vector (SSE2 on x86-64).
using F4 = float __attribute__((vector_size(16)));
using D2 = double __attribute__((vector_size(16)));

// Rows r0..r3 (4 floats each) to x, y, z of the 4 elements. (Each helper exists for float and
// double; one of the two is unused in each build.)
[[maybe_unused]] inline void LoadXyz(const float* p, F4& x, F4& y, F4& z) {
  const __m128 r0 = _mm_loadu_ps(p), r1 = _mm_loadu_ps(p + 4), r2 = _mm_loadu_ps(p + 8), r3 = _mm_loadu_ps(p + 12);
  const __m128 xy01 = _mm_unpacklo_ps(r0, r1), xy23 = _mm_unpacklo_ps(r2, r3);
  const __m128 zw01 = _mm_unpackhi_ps(r0, r1), zw23 = _mm_unpackhi_ps(r2, r3);
  x = F4(_mm_movelh_ps(xy01, xy23)), y = F4(_mm_movehl_ps(xy23, xy01)), z = F4(_mm_movelh_ps(zw01, zw23));
}
[[maybe_unused]] inline F4 Sqrt(F4 v) { return F4(_mm_sqrt_ps(__m128(v))); }
// Non-temporal stores (p 16-byte aligned), as StreamStore.
[[maybe_unused]] inline void Stream(float* p, F4 v) { _mm_stream_ps(p, __m128(v)); }
[[maybe_unused]] inline uint64_t DegenerateBits(F4 l) {
  return static_cast<uint64_t>(_mm_movemask_ps(_mm_cmple_ps(__m128(l), _mm_set1_ps(kMinLength))));
}

// Rows r0, r1 (4 doubles each) to x, y, z of the 2 elements.
[[maybe_unused]] inline void LoadXyz(const double* p, D2& x, D2& y, D2& z) {
  const __m128d xy0 = _mm_loadu_pd(p), xy1 = _mm_loadu_pd(p + 4);
  x = D2(_mm_unpacklo_pd(xy0, xy1)), y = D2(_mm_unpackhi_pd(xy0, xy1));
  z = D2(_mm_loadh_pd(_mm_load_sd(p + 2), p + 6));
}
[[maybe_unused]] inline D2 Sqrt(D2 v) { return D2(_mm_sqrt_pd(__m128d(v))); }
[[maybe_unused]] inline void Stream(double* p, D2 v) { _mm_stream_pd(p, __m128d(v)); }
[[maybe_unused]] inline uint64_t DegenerateBits(D2 l) {
  return static_cast<uint64_t>(_mm_movemask_pd(_mm_cmple_pd(__m128d(l), _mm_set1_pd(kMinLength))));
}
#endif

// The vector loop, for the baseline target. Its twin below is the same loop with AVX2 types: the
// target-specific helpers (transposes, sqrt, movemask) cannot be called from one shared loop
// compiled for the baseline target, but ForceMultiple, plain vector arithmetic, can.
template <Rate kRate, bool kDirectIn, bool kEnergy>
void BatchForcesBase(const BatchIo io) {
  int32_t j = 0;
#if defined(__SSE2__)
  using V = std::conditional_t<sizeof(Real) == 4, F4, D2>;
  constexpr int32_t kLanes = sizeof(V) / sizeof(Real);
  [[maybe_unused]] EnergySums<V> energy;
  for (; j + kLanes <= io.n; j += kLanes) {
    V sx, sy, sz, dvx{}, dvy{}, dvz{}, old_len{}, old_rate{};
    LoadXyz(io.s4 + 4 * j, sx, sy, sz);
    if constexpr (kRate == Rate::kAnalytic) LoadXyz(io.dv4 + 4 * j, dvx, dvy, dvz);
    if constexpr (kDirectIn) {
      LoadLanes(old_len, io.len + j), LoadLanes(old_rate, io.rate + j);
      if (io.backup_len) Stream(io.backup_len + j, old_len), Stream(io.backup_rate + j, old_rate);
    }
    const V l = Sqrt(sx * sx + sy * sy + sz * sz);  // eq. 4.4
    V mag;
    ForceMultiple<kRate, kDirectIn, kEnergy>(io, j, l, sx, sy, sz, dvx, dvy, dvz, old_len, old_rate, mag, energy);
    StoreLanes(io.ex + j, mag * sx), StoreLanes(io.ey + j, mag * sy), StoreLanes(io.ez + j, mag * sz);
    io.degenerate[j / 64] |= DegenerateBits(l) << (j % 64);
  }
  if constexpr (kEnergy) FlushEnergy(io, energy);
#endif
  BatchForcesScalar<kRate, kDirectIn, kEnergy>(io, j);
}

#if defined(__x86_64__) && !defined(__AVX2__)
// AVX2: 8 floats or 4 doubles per vector. Each 256-bit register holds rows i and i + 4 (floats)
// or i and i + 2 (doubles) in its two halves, so that in-lane shuffles transpose.
using F8 = float __attribute__((vector_size(32)));
using D4 = double __attribute__((vector_size(32)));

[[gnu::target("avx2"), maybe_unused]] inline __m256 LoadRows(const float* lo, const float* hi) {
  return _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(lo)), _mm_loadu_ps(hi), 1);
}
[[gnu::target("avx2"), maybe_unused]] inline void LoadXyz(const float* p, F8& x, F8& y, F8& z) {
  const __m256 r0 = LoadRows(p, p + 16), r1 = LoadRows(p + 4, p + 20);
  const __m256 r2 = LoadRows(p + 8, p + 24), r3 = LoadRows(p + 12, p + 28);
  const __m256 xy01 = _mm256_unpacklo_ps(r0, r1), xy23 = _mm256_unpacklo_ps(r2, r3);
  const __m256 zw01 = _mm256_unpackhi_ps(r0, r1), zw23 = _mm256_unpackhi_ps(r2, r3);
  x = F8(_mm256_shuffle_ps(xy01, xy23, 0x44)), y = F8(_mm256_shuffle_ps(xy01, xy23, 0xee));
  z = F8(_mm256_shuffle_ps(zw01, zw23, 0x44));
}
[[gnu::target("avx2"), maybe_unused]] inline F8 Sqrt(F8 v) { return F8(_mm256_sqrt_ps(__m256(v))); }
[[gnu::target("avx2"), maybe_unused]] inline void Stream(float* p, F8 v) {
  _mm_stream_ps(p, _mm256_castps256_ps128(__m256(v))), _mm_stream_ps(p + 4, _mm256_extractf128_ps(__m256(v), 1));
}
[[gnu::target("avx2"), maybe_unused]] inline uint64_t DegenerateBits(F8 l) {
  return static_cast<uint64_t>(_mm256_movemask_ps(_mm256_cmp_ps(__m256(l), _mm256_set1_ps(kMinLength), _CMP_LE_OQ)));
}

[[gnu::target("avx2"), maybe_unused]] inline __m256d LoadRows(const double* lo, const double* hi) {
  return _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_loadu_pd(lo)), _mm_loadu_pd(hi), 1);
}
[[gnu::target("avx2"), maybe_unused]] inline void LoadXyz(const double* p, D4& x, D4& y, D4& z) {
  const __m256d xy02 = LoadRows(p, p + 8), xy13 = LoadRows(p + 4, p + 12);
  const __m256d zw02 = LoadRows(p + 2, p + 10), zw13 = LoadRows(p + 6, p + 14);
  x = D4(_mm256_unpacklo_pd(xy02, xy13)), y = D4(_mm256_unpackhi_pd(xy02, xy13));
  z = D4(_mm256_unpacklo_pd(zw02, zw13));
}
[[gnu::target("avx2"), maybe_unused]] inline D4 Sqrt(D4 v) { return D4(_mm256_sqrt_pd(__m256d(v))); }
[[gnu::target("avx2"), maybe_unused]] inline void Stream(double* p, D4 v) {
  _mm_stream_pd(p, _mm256_castpd256_pd128(__m256d(v))), _mm_stream_pd(p + 2, _mm256_extractf128_pd(__m256d(v), 1));
}
[[gnu::target("avx2"), maybe_unused]] inline uint64_t DegenerateBits(D4 l) {
  return static_cast<uint64_t>(_mm256_movemask_pd(_mm256_cmp_pd(__m256d(l), _mm256_set1_pd(kMinLength), _CMP_LE_OQ)));
}

template <Rate kRate, bool kDirectIn, bool kEnergy>
[[gnu::target("avx2")]] void BatchForcesAvx2(const BatchIo io) {
  using V = std::conditional_t<sizeof(Real) == 4, F8, D4>;
  constexpr int32_t kLanes = sizeof(V) / sizeof(Real);
  int32_t j = 0;
  [[maybe_unused]] EnergySums<V> energy;
  for (; j + kLanes <= io.n; j += kLanes) {
    V sx, sy, sz, dvx{}, dvy{}, dvz{}, old_len{}, old_rate{};
    LoadXyz(io.s4 + 4 * j, sx, sy, sz);
    if constexpr (kRate == Rate::kAnalytic) LoadXyz(io.dv4 + 4 * j, dvx, dvy, dvz);
    if constexpr (kDirectIn) {
      LoadLanes(old_len, io.len + j), LoadLanes(old_rate, io.rate + j);
      if (io.backup_len) Stream(io.backup_len + j, old_len), Stream(io.backup_rate + j, old_rate);
    }
    const V l = Sqrt(sx * sx + sy * sy + sz * sz);  // eq. 4.4
    V mag;
    ForceMultiple<kRate, kDirectIn, kEnergy>(io, j, l, sx, sy, sz, dvx, dvy, dvz, old_len, old_rate, mag, energy);
    StoreLanes(io.ex + j, mag * sx), StoreLanes(io.ey + j, mag * sy), StoreLanes(io.ez + j, mag * sz);
    io.degenerate[j / 64] |= DegenerateBits(l) << (j % 64);
  }
  if constexpr (kEnergy) FlushEnergy(io, energy);
  // The tail and the caller are SSE code, which runs about half as fast while the registers'
  // upper halves are dirty; GCC leaves the vzeroupper out before this tail call.
  _mm256_zeroupper();
  BatchForcesScalar<kRate, kDirectIn, kEnergy>(io, j);
}

// BatchElastic's vector loop in AVX2.
[[gnu::target("avx2")]] double BatchElasticAvx2(int32_t n, const Real* len2, const Real* k, const Real* leq,
                                                int32_t* done) {
  using V = std::conditional_t<sizeof(Real) == 4, F8, D4>;
  constexpr int32_t kLanes = sizeof(V) / sizeof(Real);
  V u{};
  int32_t j = 0;
  for (; j + kLanes <= n; j += kLanes) {
    V l2, kj, leqj;
    LoadLanes(l2, len2 + j), LoadLanes(kj, k + j), LoadLanes(leqj, leq + j);
    const V stretch = Sqrt(l2) - leqj;
    u += Real(0.5) * kj * stretch * stretch;
  }
  *done = j;
  const double sum = LaneSum(u);
  _mm256_zeroupper();
  return sum;
}
#endif

template <Rate kRate, bool kDirectIn, bool kEnergy>
void Dispatch(bool allow_avx2, const BatchIo& io) {
#if defined(__x86_64__) && !defined(__AVX2__)
  if (UseAvx2(allow_avx2)) return BatchForcesAvx2<kRate, kDirectIn, kEnergy>(io);
#endif
  BatchForcesBase<kRate, kDirectIn, kEnergy>(io);
}

template <bool kEnergy>
void DispatchRate(Rate rate, bool direct_in, bool allow_avx2, const BatchIo& io) {
  switch (rate) {
    case Rate::kNone:
      return Dispatch<Rate::kNone, false, kEnergy>(allow_avx2, io);
    case Rate::kAnalytic:
      return Dispatch<Rate::kAnalytic, false, kEnergy>(allow_avx2, io);
    case Rate::kFiltered:
      return direct_in ? Dispatch<Rate::kFiltered, true, kEnergy>(allow_avx2, io)
                       : Dispatch<Rate::kFiltered, false, kEnergy>(allow_avx2, io);
  }
}

}  // namespace

// The baseline code or, on x86-64, the AVX2 code chosen once at run time: the default build runs
// on any x86-64 and uses AVX2 where it exists. Rejected: -march=native (the binary must run on
// any CI machine); compiling the whole file twice (inline functions it shares with other files
// could be linked in their AVX2 form and fault on an older CPU), or the whole substep as an AVX2
// clone (no faster).
bool UseAvx2([[maybe_unused]] bool allow_avx2) {
#if defined(__x86_64__) && !defined(__AVX2__)
  static const bool avx2 = __builtin_cpu_supports("avx2");
  return avx2 && allow_avx2;
#else
  return false;
#endif
}

void BatchForces(Rate rate, bool direct_in, bool allow_avx2, const BatchIo& io) {
  std::fill(io.degenerate, io.degenerate + kMaskWords, 0);
  if (io.energy) return DispatchRate<true>(rate, direct_in, allow_avx2, io);
  DispatchRate<false>(rate, direct_in, allow_avx2, io);
}

double BatchElastic(bool allow_avx2, int32_t n, const Real* len2, const Real* k, const Real* leq) {
  double sum = 0;
  int32_t j = 0;
#if defined(__x86_64__) && !defined(__AVX2__)
  if (UseAvx2(allow_avx2)) sum = BatchElasticAvx2(n, len2, k, leq, &j);
#endif
#if defined(__SSE2__)
  if (j == 0) {
    using V = std::conditional_t<sizeof(Real) == 4, F4, D2>;
    constexpr int32_t kLanes = sizeof(V) / sizeof(Real);
    V u{};
    for (; j + kLanes <= n; j += kLanes) {
      V l2, kj, leqj;
      LoadLanes(l2, len2 + j), LoadLanes(kj, k + j), LoadLanes(leqj, leq + j);
      const V stretch = Sqrt(l2) - leqj;
      u += Real(0.5) * kj * stretch * stretch;
    }
    sum = LaneSum(u);
  }
#endif
  for (; j < n; ++j) {
    const Real stretch = std::sqrt(len2[j]) - leq[j];
    sum += Real(0.5) * k[j] * stretch * stretch;
  }
  return sum;
}

}  // namespace idms::internal
