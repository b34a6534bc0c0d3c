// The Discrete Simulation Model (thesis ch. 3): what a step reads but never changes.
// Structure of arrays, int32 ids, -1 = none. Built by the file readers or the generators,
// then completed by FinalizeModel(), which derives everything that is not stored in files.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace idms {

// Boundary and surface condition codes of the .fem format (thesis appendix B.2).
inline constexpr int kBcFixed = 1000;
inline constexpr int kBcFree = 1001;
inline constexpr int kScInternal = 2000;
inline constexpr int kScExternal = 2001;

struct Model {
  std::string name;  // one token, no whitespace (the first field of the .fem header)

  int32_t num_atoms = 0;
  int32_t num_elems = 0;
  int32_t num_tris = 0;
  int32_t num_external = 0;  // atoms with surface condition external

  // Atoms (thesis table 3.1).
  std::vector<double> atom_pos_eq;     // (num_atoms x 3), model units: rest position p_eq
  std::vector<double> atom_mass;       // (num_atoms), mass units; 0 allowed on fixed atoms only
  std::vector<uint8_t> atom_fixed;     // (num_atoms), 1 = bc fixed (immobile), 0 = free
  std::vector<uint8_t> atom_external;  // (num_atoms), 1 = sc external (on the surface)

  // Elements (thesis table 3.2): a linear spring and dashpot in parallel.
  std::vector<int32_t> elem_atoms;  // (num_elems x 2), atom ids, a0 != a1
  std::vector<double> elem_k;       // (num_elems), force / length, >= 0
  std::vector<double> elem_b;       // (num_elems), force / (length / s), >= 0
  std::vector<double> elem_leq;     // (num_elems), model units: |p_eq[a1] - p_eq[a0]| (derived)
  std::vector<uint8_t> elem_home;   // (num_elems), 1 = home element (derived, see FinalizeModel)

  // Surface: the list of external atoms (thesis table 3.3) and the triangles of the .plg.
  std::vector<int32_t> external_atoms;    // (num_external), atom ids in file order = plg vertex order
  std::vector<int32_t> atom_external_id;  // (num_atoms), index into external_atoms or -1 (derived)
  std::vector<int32_t> tri_atoms;         // (num_tris x 3), atom ids, counter-clockwise seen from outside

  // Atom -> element adjacency in CSR form (derived): the elements of atom i are
  // atom_elem[atom_elem_adr[i] .. atom_elem_adr[i] + atom_elem_num[i]).
  std::vector<int32_t> atom_elem_adr;  // (num_atoms)
  std::vector<int32_t> atom_elem_num;  // (num_atoms)
  std::vector<int32_t> atom_elem;      // (2 * num_elems), element ids

  // Step constants (derived): each free atom's Gershgorin bound of the element network (thesis
  // 4.2; the stable-step prediction adds the tools' stiffness), 0 for fixed atoms; the longest
  // rest length; whether any element is damped. Upper bounds: removing elements keeps them.
  std::vector<double> atom_omega2;  // (num_atoms), 1/s^2: sum of the atom's row of K / m
  std::vector<double> atom_damp;    // (num_atoms), 1/s: the same for the dashpots
  double max_leq = 0;               // model units
  bool has_damping = false;         // some element has b > 0 (else the viscous terms are skipped)

  // Bumped by every topology edit (cut, grasp, glue); viewers follow it.
  uint64_t topology_version = 0;
};

// Derives num_*, elem_leq, elem_home, external_atoms, atom_external_id, the CSR adjacency and
// the step constants from the stored arrays. Call after filling atoms, elements and triangles. Allocates.
// A home element joins an external atom to a fixed atom at the same rest position (thesis 3.1).
void FinalizeModel(Model& model);

// Bytes held by the model's arrays (capacity, not size), for memory reports.
int64_t ModelBytes(const Model& model);

}  // namespace idms
