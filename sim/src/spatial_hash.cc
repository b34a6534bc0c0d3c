// Uniform-grid spatial hash of atom positions: build once, refile moved atoms in O(1).
#include "idms/sim/spatial_hash.h"

#include <algorithm>

#include "idms/sim/check.h"

namespace idms {

void BuildSpatialHash(double cell, const Real* pos, int32_t num_atoms, SpatialHash* hash) {
  IDMS_CHECK(cell > 0 && num_atoms >= 0);
  SpatialHash& h = *hash;
  h.cell = cell;
  h.inv_cell = 1.0 / cell;
  // About one bucket per atom (power of two, at least 2^4): short chains, 4 bytes per atom.
  h.bits = 4;
  while ((int64_t{1} << h.bits) < num_atoms && h.bits < 30) ++h.bits;
  h.bucket_head.assign(size_t{1} << h.bits, -1);
  h.atom_next.assign(num_atoms, -1);
  h.atom_prev.assign(num_atoms, -1);
  h.atom_key.assign(num_atoms, kHashUnfiled);
  for (int32_t a = 0; a < num_atoms; ++a) UpdateSpatialHash(h, a, pos + 3 * a);
}

void UpdateSpatialHash(SpatialHash& h, int32_t atom, const Real* p) {
  const uint64_t key =
      HashCellKey(HashCellCoord(p[0], h.inv_cell), HashCellCoord(p[1], h.inv_cell), HashCellCoord(p[2], h.inv_cell));
  const uint64_t old = h.atom_key[atom];
  if (key == old) return;
  // Unlink from the old bucket.
  if (old != kHashUnfiled) {
    const int32_t prev = h.atom_prev[atom], next = h.atom_next[atom];
    if (prev >= 0) {
      h.atom_next[prev] = next;
    } else {
      h.bucket_head[HashBucket(h, old)] = next;
    }
    if (next >= 0) h.atom_prev[next] = prev;
  }
  // Push onto the front of the new one.
  int32_t& head = h.bucket_head[HashBucket(h, key)];
  h.atom_prev[atom] = -1;
  h.atom_next[atom] = head;
  if (head >= 0) h.atom_prev[head] = atom;
  head = atom;
  h.atom_key[atom] = key;
}

}  // namespace idms
