// The model's surface as a mesh: the triangles over the external atoms and their positions,
// vertex i = external atom i (the order of Model::external_atoms). What the agent's loop hands to
// the mesh encoder and the renderer draws; no protocol types.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "idms/sim/model.h"

namespace idms {

// The model's surface triangles as vertex ids (num_tris x 3), vertex i = external atom i.
std::vector<int32_t> SurfaceTriangles(const Model& model);

// Copies the external atoms' positions out of atom positions (num_atoms x 3) into
// out (num_external x 3). Does not allocate.
void GatherSurface(const Model& model, std::span<const double> atom_pos, std::span<double> out);

}  // namespace idms
