// MakeState: a model at rest, with every array at the fixed size the step relies on.
#include "idms/sim/state.h"

#include <cmath>

#include "idms/sim/model.h"

namespace idms {

State MakeState(const Model& model) {
  State s;
  const int32_t na = model.num_atoms, ne = model.num_elems;
  s.atom_pos.assign(model.atom_pos_eq.begin(), model.atom_pos_eq.end());
  s.atom_vel.assign(3 * static_cast<size_t>(na), Real(0));
  s.elem_len.resize(ne);
  for (int32_t e = 0; e < ne; ++e) s.elem_len[e] = static_cast<Real>(model.elem_leq[e]);
  s.elem_rate.assign(ne, Real(0));
  // Stamp -1 = "updated in the substep before the first", so the first filter update is continuous.
  s.elem_stamp.assign(ne, -1);
  s.active_atoms.assign(na, -1);
  s.atom_linger.assign(na, 0);
  return s;
}

void FoldStampFloor(const Model& model, State& s) {
  if (s.elem_stamp_floor == kNoStamp) return;
  for (int32_t e = 0; e < model.num_elems; ++e) {
    const bool free_end = !model.atom_fixed[model.elem_atoms[2 * e]] || !model.atom_fixed[model.elem_atoms[2 * e + 1]];
    if (free_end && s.elem_stamp[e] < s.elem_stamp_floor) s.elem_stamp[e] = s.elem_stamp_floor;
  }
  s.elem_stamp_floor = kNoStamp;
}

void SyncFilterToPositions(const Model& model, State& s) {
  s.elem_stamp_floor = kNoStamp;
  for (int32_t e = 0; e < model.num_elems; ++e) {
    const Real* p0 = &s.atom_pos[3 * model.elem_atoms[2 * e]];
    const Real* p1 = &s.atom_pos[3 * model.elem_atoms[2 * e + 1]];
    const Real dx = p1[0] - p0[0], dy = p1[1] - p0[1], dz = p1[2] - p0[2];
    s.elem_len[e] = std::sqrt(dx * dx + dy * dy + dz * dz);
    s.elem_rate[e] = 0;
    s.elem_stamp[e] = s.substep_clock - 1;
  }
}

std::array<WarningKind, kNumWarningKinds> WarningKinds(const WarningCounters& w) {
#define IDMS_WARNING_KIND(name, meaning) WarningKind{#name, w.name},
  return {{IDMS_WARNINGS(IDMS_WARNING_KIND)}};
#undef IDMS_WARNING_KIND
}

int64_t TotalWarnings(const WarningCounters& w) {
  int64_t total = 0;
  for (const WarningKind& k : WarningKinds(w)) total += k.count;
  return total;
}

}  // namespace idms
