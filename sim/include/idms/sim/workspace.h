// Workspace: the step's scratch, sized once by MakeWorkspace, plus the options it was sized for.
// Not simulation state (a fresh Workspace steps a State to the same bits), except the scalpel's
// pending cuts and implicit Euler's CG warm start.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "idms/sim/spatial_hash.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"
#include "idms/sim/tool.h"

namespace idms {

struct Model;

// A tool slot as this tick uses it: validated input plus what State remembers (grasp). The
// fields it shares with ToolCommand, ToolState and ToolReport have the same names there.
struct ActiveTool {
  ToolKind kind = ToolKind::kNone;  // kNone: ignored this tick (unused slot or never valid)
  ContactLaw law = ContactLaw::kThesis;
  double pos[3] = {0, 0, 0};         // MIO centre / blade base, model units
  double blade_tip[3] = {0, 0, 0};   // scalpel
  double radius = 0, stiffness = 0;  // MIO r and k
  bool closed = false;               // tweezers: closed this tick (held when the input was bad)
  int32_t grasp_atom = -1;
  double grasp_leq = 0, grasp_k = 0;
  double eval_force[3] = {0, 0, 0};  // sum of this tool's forces on atoms, current evaluation
  double tick_force[3] = {0, 0, 0};  // the same, weighted over the tick's evaluations
  int32_t contacts = 0;
};

// Linearised backward Euler on the active set: a row-major CSR matrix (viewed by Eigen through
// Eigen::Map, so no Eigen-owned storage) and the CG vectors, all indexed by active slot.
struct ImplicitBuffers {
  std::vector<int32_t> outer;                       // (3 * capacity_atoms + 1)
  std::vector<int32_t> inner;                       // (capacity_nnz)
  std::vector<Real> values;                         // (capacity_nnz)
  std::vector<Real> rhs, dv, r, z, p, q, inv_diag;  // (3 * capacity_atoms)
  std::vector<Real> diag_blocks;                    // (9 * capacity_atoms)
  std::vector<Real> atom_dv_guess;                  // (num_atoms x 3): last solution per atom, CG warm start
};

// Full mode's fused pass (full_step.cc): element forces, accumulation and integration in one
// sweep over the elements in the order the general path visits them (grouped by their lowest
// free endpoint), so each free atom is integrated as soon as its last element is done and every
// per-atom sum is formed in the same order: the same bits as the general path. Built from the
// live lists (see `live`) without allocating; arrays are in walk order unless noted.
struct FullPass {
  // Off = every full-mode tick takes the general path (tests and benches compare the two).
  bool enabled = true;
  // May use the AVX2 build of its vectorised phase where the CPU has AVX2 (the same bits; off
  // lets a test cover the baseline x86-64 code on any machine).
  bool avx2 = true;
  // The lists below, and ws.active / candidates / elems with their marks, hold the full-mode
  // sets across ticks (the between-steps invariant of the marks is suspended while live).
  bool live = false;
  uint64_t topology_version = 0;  // model version the arrays were built for
  bool identity = false;          // ws.elems[w] == w: element arrays need no indirection
  // `force` of every free atom is 0 (the fused pass leaves it so for the next tick).
  bool force_zero = false;
  // Elements the last fused substep found degenerate (their eq. 4.6 filters carry a restart mark);
  // -1 = unknown (the last substep was not this pass's).
  int32_t restart_marks = -1;
  std::vector<int32_t> group_end;              // (num_atoms) by active slot: one past its last element
  std::vector<int32_t> other;                  // (num_elems) endpoint that is not the group's atom; ~id if fixed
  std::vector<int32_t> elem_g;                 // (num_elems) the group's atom (the lower free endpoint)
  std::vector<Real> elem_k, elem_b, elem_leq;  // (num_elems) model values, as Real
  std::vector<Real> atom_t_over_m;             // (num_atoms) by active slot: T / Model::atom_mass
  Real t_over_m_of = 0;                        // the substep T of atom_t_over_m; 0 = not computed
  // The pass's force accumulator, (num_atoms x 4) with a zero 4th lane: one vector per atom.
  std::vector<Real> force;
  std::vector<Real> scratch;  // per-batch temporaries (full_step.cc)
  // (num_elems / batch + 1) per batch of the walk: the highest active slot of a free endpoint in
  // it or an earlier batch (the energy check forms a batch's end-of-tick lengths past it).
  std::vector<int32_t> batch_ready;
  // Float builds: the rollback copy of the atoms as two 4-wide rows per slot (position, velocity;
  // lane 3 not used), written with one non-temporal vector store each (else Workspace::backup_pos
  // and backup_vel).
  std::vector<Real> backup_rows;
  // May ask the kernel (Linux, madvise MADV_COLLAPSE) to back the 2 MiB-aligned inside of the
  // arrays the pass streams, the State's included, with huge pages, once when the pass goes live
  // and again when the State's arrays move: a 10^6-atom pass crosses a 4 KiB page every few
  // hundred elements in each of its ~20 streams, and each crossing can cost a page walk. The
  // contents do not change; off, or where the kernel declines, nothing else changes either.
  bool huge_pages = true;
  bool huge_workspace_done = false;  // the workspace's arrays were advised
  const Real* huge_state = nullptr;  // State::atom_pos.data() when the State's were advised
  int64_t huge_bytes = 0;            // bytes the kernel moved to huge pages so far
  // Stable step of the configured integrator without tools (the minimum over free atoms), and
  // how many atoms reach it: a tick only re-examines the atoms a tool stiffens.
  double dt_free = 0;
  int32_t dt_free_count = 0;
};

struct Workspace {
  // Why the options live here and not in a Step argument: the buffers below are sized for them
  // (hash cell from the local radius, RK4 and implicit scratch only when they can be used), so
  // keeping both in one object makes a mismatch impossible and keeps Step's signature the one
  // DESIGN.md gives. Changing options = MakeWorkspace again (O(N), allocates).
  StepOptions options;

  // What the workspace was made for (checked by Step).
  int32_t num_atoms = 0;
  uint64_t topology_version = 0;
  // State::tick this workspace expects next; -1 = refile the hash from the State at the first
  // Step (so a State edited before its first step, e.g. in a test, is picked up).
  int64_t synced_tick = -1;

  // Derived from the model and options.
  bool any_damping = false;                    // some element has b > 0; else the viscous filter is skipped
  bool use_rk4 = false, use_implicit = false;  // which scratch exists
  double local_radius = 0;                     // effective r_l (local mode)
  double cut_reach = 0;                        // model units: half the longest element allowed for cut search
  std::vector<double> atom_omega2;             // (num_atoms), 1/s^2: Gershgorin bound without tools
  std::vector<double> atom_damp;               // (num_atoms), 1/s: Gershgorin damping bound without tools

  SpatialHash hash;  // local mode only; files every atom at its State position

  // Per-atom scratch. Invariant between steps: marks 0, slots -1, extra_k 0 (except while
  // full.live: then marks and slots describe every free atom).
  std::vector<uint8_t> atom_mark;    // (num_atoms), 1 = active this tick, 2 = checked by the wake pass
  std::vector<uint8_t> atom_cand;    // (num_atoms), 1 = contact candidate this tick
  std::vector<int32_t> atom_slot;    // (num_atoms), index into the active list or -1
  std::vector<double> atom_extra_k;  // (num_atoms), tool stiffness on the atom this tick
  std::vector<Real> atom_force;      // (num_atoms x 3), force units; valid for active atoms

  // Optional input, not scratch: forces from outside the DSM (e.g. draping's attraction to a
  // form, thesis 5.6.1), added to every active atom at every force evaluation of the next Step,
  // held constant over its substeps and stages. Empty (the default, never allocated by
  // MakeWorkspace) = none, at the cost of one branch per evaluation. When set it must hold
  // num_atoms x 3 values (IDMS_CHECK). The energy check, stability prediction and implicit
  // Jacobian do not see these forces: a caller doing work through them turns
  // stability.energy_check off and keeps the tick short against their stiffness.
  std::vector<Real> atom_force_external;  // (num_atoms x 3) or empty, force units

  // Lists of this tick (buffers of full size; counts say how much is used).
  std::vector<int32_t> active;  // (num_atoms) active free atoms
  int32_t num_active = 0;
  std::vector<int32_t> candidates;  // (num_atoms) external atoms that may touch a tool
  int32_t num_candidates = 0;
  std::vector<int32_t> boundary;  // (num_atoms) inactive free atoms checked by the wake pass
  int32_t num_boundary = 0;
  std::vector<int32_t> elems;  // (num_elems) elements with an active endpoint, not cut
  int32_t num_elems = 0;
  std::vector<uint8_t> elem_mark;     // (num_elems)
  std::vector<uint8_t> elem_cut;      // (num_elems), 1 = pending cut: no force until removed
  std::vector<int32_t> pending_cuts;  // (num_elems)
  int32_t num_pending_cuts = 0;

  // Rollback copy of the active region, by active slot / active element index.
  std::vector<Real> backup_pos, backup_vel;             // (num_atoms x 3)
  std::vector<Real> backup_elem_len, backup_elem_rate;  // (num_elems)
  std::vector<int64_t> backup_elem_stamp;               // (num_elems)

  // RK4 scratch by active slot (only when use_rk4).
  std::vector<Real> rk_x0, rk_v0, rk_dx, rk_dv;  // (num_atoms x 3)

  ImplicitBuffers implicit;  // only when use_implicit

  FullPass full;  // sized only in full mode

  // Surface adjacency for the Edit API: triangles of atom i are
  // atom_tri[atom_tri_adr[i] .. + atom_tri_num[i]) (holes allowed after removals).
  std::vector<int32_t> atom_tri_adr, atom_tri_num, atom_tri;

  std::array<ActiveTool, kMaxTools> tools{};
  int32_t num_tools = 0;
};

// Sizes everything for `model` and `options` (validated: IDMS_CHECK on nonsense such as
// dt <= 0). Builds the spatial hash from the rest positions. O(atoms + elements), allocates.
Workspace MakeWorkspace(const Model& model, const StepOptions& options);

// Refiles the spatial hash from `state` and clears per-tick scratch. Step calls it itself (and
// counts warnings.workspace_resync) when the state is not the one it stepped last, e.g. after
// restoring a snapshot. O(atoms), does not allocate.
void ResyncWorkspace(const Model& model, const State& state, Workspace& workspace);

}  // namespace idms
