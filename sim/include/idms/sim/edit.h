// Topology edits between steps (thesis 3.2.6 reformability): removing elements (the scalpel's
// cuts) and the surface triangles that lose an edge. Every edit keeps Model, State and
// Workspace consistent and bumps Model::topology_version, which viewers follow.
#pragma once

#include <cstdint>

namespace idms {

struct Model;
struct State;
struct Workspace;

// Removes element `elem` by moving the last element into its place (element ids above it are
// not stable across edits): the Model's element arrays and CSR adjacency (which then has holes,
// still valid through atom_elem_adr/_num; FinalizeModel compacts it), the State's eq. 4.6
// filter arrays and the Workspace's element flags. Drops the surface triangles with both of its
// atoms as vertices (they lose an edge). Returns the number of triangles dropped.
// Does not bump topology_version (ApplyPendingEdits batches). O(degree + triangles at its two
// atoms); shrinks vectors only, so it does not allocate.
int32_t RemoveElement(Model& model, State& state, Workspace& workspace, int32_t elem);

struct EditReport {
  int32_t elements_removed = 0;
  int32_t triangles_removed = 0;
  bool topology_changed = false;
};

// Applies the cuts the scalpel sweeps of earlier Steps found (Step cannot: it reads a const
// Model; until applied, a pending cut already exerts no force). Bumps model.topology_version
// (and the workspace's) once when anything changed. Call between steps, on the stepping thread.
// Does not allocate.
EditReport ApplyPendingEdits(Model& model, State& state, Workspace& workspace);

}  // namespace idms
