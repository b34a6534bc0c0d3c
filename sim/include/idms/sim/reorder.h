// Renumbering a model for memory locality, once, as a model-preparation step (`idms-sim
// reorder`): the step's full-mode fused pass then streams its arrays front to back.
#pragma once

#include <cstdint>
#include <vector>

#include "idms/sim/model.h"

namespace idms {

struct ReorderOptions {
  // Atoms in reverse Cuthill-McKee order (breadth first from a peripheral atom, neighbours by
  // degree, reversed): an element's two atoms get nearby ids, so what the pass touches at once
  // stays in cache. Off = atoms keep their ids.
  bool atoms = true;
};

// Old id -> new id, for anything that refers to the original numbering.
struct Reordering {
  std::vector<int32_t> atom_new_id;  // (num_atoms)
  std::vector<int32_t> elem_new_id;  // (num_elems)
};

// The same model renumbered: atoms as the options say, then elements in the order full mode's
// step visits them (grouped by their lowest free endpoint, each group by the other endpoint;
// elements between two fixed atoms last), so that the step's element arrays need no index.
// Positions, masses, conditions, k, b and triangles (renumbered, same winding) are unchanged;
// rest lengths are rederived (the same values). The external atoms keep their relative order
// only when atoms are not renumbered: the .plg written from the result matches its .fem.
// O(atoms log atoms + elements log elements); allocates. `map` may be null.
Model ReorderForLocality(const Model& model, const ReorderOptions& options = {}, Reordering* map = nullptr);

}  // namespace idms
