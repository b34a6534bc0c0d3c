// A uniform-grid spatial hash of atom positions (the spatial data structure of thesis 5.5.1 and
// 7.2.3): queries cost O(cells + atoms near the query), updates O(1) per moved atom, so a local
// step's cost does not grow with the model. Sized once; updates and queries never allocate.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "idms/sim/state.h"

namespace idms {

// Buckets are intrusive doubly linked lists threaded through per-atom next/prev arrays; each
// atom keeps the packed cell it was filed under, so a query only accepts atoms of the cell it
// visits (no duplicates when two cells share a bucket). Rejected: a sorted cell array (cheaper
// queries, but an O(N) rebuild whenever anything moves) and an octree (deeper pointer chases
// for the same point queries).
struct SpatialHash {
  double cell = 1;  // cell edge, model units
  double inv_cell = 1;
  int32_t bits = 1;                  // 1 << bits buckets
  std::vector<int32_t> bucket_head;  // (1 << bits), first atom or -1
  std::vector<int32_t> atom_next;    // (num_atoms), next atom in the bucket or -1
  std::vector<int32_t> atom_prev;    // (num_atoms), previous atom in the bucket or -1
  std::vector<uint64_t> atom_key;    // (num_atoms), packed cell the atom is filed under
};

// Cell coordinates are clamped to +-2^20 so far-away or non-finite positions still file somewhere.
inline constexpr int64_t kHashCellLimit = int64_t{1} << 20;
// atom_key of an atom that is in no bucket (no cell packs to it: keys use 63 bits).
inline constexpr uint64_t kHashUnfiled = ~uint64_t{0};

inline int64_t HashCellCoord(double x, double inv_cell) {
  double c = std::floor(x * inv_cell);
  if (!(c >= -static_cast<double>(kHashCellLimit))) c = -static_cast<double>(kHashCellLimit);  // NaN too
  if (c > static_cast<double>(kHashCellLimit - 1)) c = static_cast<double>(kHashCellLimit - 1);
  return static_cast<int64_t>(c);
}

inline uint64_t HashCellKey(int64_t ix, int64_t iy, int64_t iz) {
  const uint64_t mask = (uint64_t{1} << 21) - 1;
  return ((static_cast<uint64_t>(ix + kHashCellLimit) & mask) << 42) |
         ((static_cast<uint64_t>(iy + kHashCellLimit) & mask) << 21) |
         (static_cast<uint64_t>(iz + kHashCellLimit) & mask);
}

inline uint32_t HashBucket(const SpatialHash& hash, uint64_t key) {
  return static_cast<uint32_t>((key * 0x9E3779B97F4A7C15ull) >> (64 - hash.bits));
}

// Files every atom of `pos` (num_atoms x 3) under cells of edge `cell`. Allocates.
void BuildSpatialHash(double cell, const Real* pos, int32_t num_atoms, SpatialHash* hash);

// Refiles one atom at its new position. O(1), no allocation.
void UpdateSpatialHash(SpatialHash& hash, int32_t atom, const Real* p);

// Calls f(atom) for every atom filed in a cell that overlaps the box [lo, hi] (a superset of
// the atoms inside the box: callers filter by distance). When the box covers more cells than
// there are buckets, scans every atom instead (same result, O(N)). Does not allocate.
template <class F>
void ForEachAtomInBox(const SpatialHash& hash, const double lo[3], const double hi[3], F&& f) {
  int64_t c0[3], c1[3];
  double cells = 1;
  for (int k = 0; k < 3; ++k) {
    c0[k] = HashCellCoord(lo[k], hash.inv_cell);
    c1[k] = HashCellCoord(hi[k], hash.inv_cell);
    if (c1[k] < c0[k]) return;
    cells *= static_cast<double>(c1[k] - c0[k] + 1);
  }
  if (cells > static_cast<double>(hash.bucket_head.size())) {
    const uint64_t mask = (uint64_t{1} << 21) - 1;
    const int32_t n = static_cast<int32_t>(hash.atom_key.size());
    for (int32_t a = 0; a < n; ++a) {
      const uint64_t key = hash.atom_key[a];
      const int64_t ix = static_cast<int64_t>((key >> 42) & mask) - kHashCellLimit;
      const int64_t iy = static_cast<int64_t>((key >> 21) & mask) - kHashCellLimit;
      const int64_t iz = static_cast<int64_t>(key & mask) - kHashCellLimit;
      if (ix >= c0[0] && ix <= c1[0] && iy >= c0[1] && iy <= c1[1] && iz >= c0[2] && iz <= c1[2]) f(a);
    }
    return;
  }
  for (int64_t ix = c0[0]; ix <= c1[0]; ++ix) {
    for (int64_t iy = c0[1]; iy <= c1[1]; ++iy) {
      for (int64_t iz = c0[2]; iz <= c1[2]; ++iz) {
        const uint64_t key = HashCellKey(ix, iy, iz);
        for (int32_t a = hash.bucket_head[HashBucket(hash, key)]; a >= 0; a = hash.atom_next[a]) {
          if (hash.atom_key[a] == key) f(a);
        }
      }
    }
  }
}

}  // namespace idms
