// Model generators (thesis 5.6): the two-layer tetrahedral slab of figure 3-1 with home
// elements, and stiff inclusions ("tumours", thesis 2.1 and 3.2.3).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "idms/sim/model.h"

namespace idms {

// A spherical region whose elements are stiffer and whose atoms are heavier.
struct Inclusion {
  double center[3] = {0, 0, 0};  // model units
  double radius = 0;             // model units
  double k_scale = 1;            // multiplies k of elements whose midpoint lies inside
  double mass_scale = 1;         // multiplies the mass of free atoms inside
};

struct SlabOptions {
  int32_t rows = 5;      // rows of the top hex grid (y direction)
  int32_t cols = 4;      // atoms in even rows; odd rows have cols + 1
  double spacing = 1.0;  // element length of the top grid, model units
  double k = 15.0;       // element stiffness (thesis 6.1)
  double b = 0.2;        // element viscosity (thesis 6.1)
  double mass = 0.002;   // atom mass (thesis 6.1)
  double home_k = 15.0;  // home element stiffness
  double home_b = 0.2;   // home element viscosity
  // Positions are rounded to this many decimals, as the thesis's files are ("0.866");
  // rest lengths are derived from the rounded positions, so the slab is still at rest. -1 = none.
  int decimals = 3;
  std::vector<Inclusion> inclusions;
  std::string name = "hex";
};

// The slab of figure 3-1: a top hex grid of external free atoms at z = 0 (rows alternate
// cols and cols + 1 atoms), triangulated exactly as appendix B.1.2; below every triangle whose
// base lies on its lower row, an internal free apex atom at depth spacing * sqrt(2/3) forming a
// regular tetrahedron; apexes joined to their lattice neighbours; and for every external atom a
// fixed home atom and a zero-length home element. Atom order: top, home, apex.
// With rows = 5, cols = 4: 58 atoms, 141 elements, 22 external atoms, 28 triangles.
Model GenerateSlab(const SlabOptions& options);

// Applies inclusions to an existing model (elements by midpoint, free atoms by position).
void ApplyInclusions(const std::vector<Inclusion>& inclusions, Model* model);

}  // namespace idms
