#include "idms/sim/surface.h"

#include "idms/sim/check.h"

namespace idms {

std::vector<int32_t> SurfaceTriangles(const Model& model) {
  std::vector<int32_t> tris(model.tri_atoms.size());
  for (size_t i = 0; i < tris.size(); ++i) {
    const int32_t v = model.atom_external_id[static_cast<size_t>(model.tri_atoms[i])];
    IDMS_CHECK(v >= 0);
    tris[i] = v;
  }
  return tris;
}

void GatherSurface(const Model& model, std::span<const double> atom_pos, std::span<double> out) {
  IDMS_CHECK(atom_pos.size() == 3 * static_cast<size_t>(model.num_atoms));
  IDMS_CHECK(out.size() == 3 * model.external_atoms.size());
  for (size_t i = 0; i < model.external_atoms.size(); ++i) {
    const size_t a = 3 * static_cast<size_t>(model.external_atoms[i]);
    out[3 * i] = atom_pos[a];
    out[3 * i + 1] = atom_pos[a + 1];
    out[3 * i + 2] = atom_pos[a + 2];
  }
}

}  // namespace idms
