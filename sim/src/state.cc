// MakeState: a model at rest, with every array at the fixed size the step relies on.
#include "idms/sim/state.h"

#include <algorithm>

#include "idms/sim/model.h"

namespace idms {

State MakeState(const Model& model) {
  State s;
  const int32_t na = model.num_atoms, ne = model.num_elems;
  s.atom_pos.assign(model.atom_pos_eq.begin(), model.atom_pos_eq.end());
  s.atom_vel.assign(3 * static_cast<size_t>(na), Real(0));
  s.elem_len.resize(ne);
  s.elem_rate.resize(ne);
  s.active_atoms.assign(na, -1);
  s.atom_linger.assign(na, 0);
  // At rest: each filter starts at its element's length at the first update, with rate 0.
  SyncFilterToPositions(model, s);
  return s;
}

void SyncFilterToPositions(const Model& model, State& s) {
  std::fill(s.elem_len.begin(), s.elem_len.begin() + model.num_elems, kFilterRestart);
  std::fill(s.elem_rate.begin(), s.elem_rate.begin() + model.num_elems, Real(0));
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
