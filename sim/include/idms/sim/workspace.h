// Workspace: the step's scratch, sized once by MakeWorkspace, plus the options it was sized for.
// Not simulation state (a fresh Workspace steps a State to the same bits), except the scalpel's
// pending cuts and implicit Euler's CG warm start.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "idms/sim/spatial_hash.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"
#include "idms/sim/tool.h"

namespace idms {

struct Model;

// Atoms a punctured needle's shaft can hold laterally at once (more are left free this tick and
// counted in ToolReport::needle_overflow).
inline constexpr int kNeedleAtoms = 256;

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
  // Friction (friction.cc): coefficients and spring-damper as resolved for this tick (mu_s = 0:
  // none), the anchor as ToolState holds it, the tick's strongest contacts (new anchors), and what
  // the evaluations found.
  double mu_s = 0, mu_d = 0, k_t = 0, b_t = 0;
  int32_t anchor_atoms[kAnchorAtoms] = {-1, -1, -1, -1};
  double anchor_w[kAnchorAtoms] = {0, 0, 0, 0};
  double anchor_offset[3] = {0, 0, 0};
  double friction_u[3] = {0, 0, 0};
  FrictionState friction = FrictionState::kNone;
  int32_t strong_atoms[kAnchorAtoms] = {-1, -1, -1, -1};  // contacts by force, strongest first
  double strong_f[kAnchorAtoms] = {0, 0, 0, 0};
  double anchor_start[3] = {0, 0, 0};   // anchor point at the tick's start
  double prev_pos[3] = {0, 0, 0};       // the tool's pose before this tick (friction's work)
  double eval_friction[3] = {0, 0, 0};  // friction's part of eval_force
  double tick_friction[3] = {0, 0, 0};  // ... of tick_force
  double eval_normal[3] = {0, 0, 0};    // unit contact normal (surface -> tool), last evaluation
  double eval_fn = 0;                   // |contact force|, last evaluation
  double tick_fn = 0;                   // ... weighted over the tick's evaluations
  // Needle (needle.cc): the unit axis, the resolved parameters, and, once punctured, the tick's
  // entry point, shaft and number of captured atoms (Workspace::needle_atoms) and what the
  // evaluations found.
  double axis[3] = {0, 0, -1};
  NeedleParams needle;
  NeedleState needle_state;
  double entry_start[3] = {0, 0, 0};  // entry point at the tick's start
  double shaft_len = 0;               // inserted length of shaft the capture runs along, model units
  double grip_len = 0;                // the part of it in the tissue (entry or tail to exit or tip): the grip's
  int32_t num_needle_atoms = 0;
  double eval_axial = 0;          // axial friction force on the atoms (along the axis), last evaluation
  double eval_normal_needle = 0;  // the grip it was bounded by, last evaluation
  double eval_lateral = 0;        // ... its lateral springs' part
  double tick_axial = 0;          // ... weighted over the tick's evaluations
  double tick_normal_needle = 0;
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

namespace internal {
struct FusedPass;  // full mode's fused kernel: its lists, caches and buffers (full_step.cc)

// Owns a FusedPass, or none; copies deeply, so a Workspace stays a value (the agent keeps a rest
// copy). Defined in full_step.cc, the one file that sees inside a FusedPass.
class FusedPassPtr {
 public:
  FusedPassPtr();
  ~FusedPassPtr();
  FusedPassPtr(const FusedPassPtr& other);
  FusedPassPtr(FusedPassPtr&& other) noexcept;
  FusedPassPtr& operator=(const FusedPassPtr& other);
  FusedPassPtr& operator=(FusedPassPtr&& other) noexcept;
  void Emplace();  // a new, empty FusedPass (allocates)
  FusedPass* get() const { return p_.get(); }
  FusedPass* operator->() const { return p_.get(); }
  FusedPass& operator*() const { return *p_; }
  bool operator==(std::nullptr_t) const { return p_ == nullptr; }

 private:
  std::unique_ptr<FusedPass> p_;
};
}  // namespace internal

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

  // Derived from the options (the model's own constants are the Model's).
  bool use_rk4 = false, use_implicit = false;  // which scratch exists
  double local_radius = 0;                     // effective r_l (local mode)

  SpatialHash hash;  // local mode only; files every atom at its State position

  // Per-atom scratch. Invariant between steps: marks 0, slots -1, extra_k 0 (except while the
  // fused kernel's lists are live: then marks and slots describe every free atom).
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
  // The candidates a tool can reach this tick, in candidate order (ToolStiffness, at the tick's
  // start): those within twice a contact tool's radius of its centre, and grasped atoms. The tool
  // loops visit these instead of every candidate while reach_slack > 0: how much farther any atom
  // may still move before one from outside could touch a tool (half the smallest radius at the
  // start; the fused kernel takes off what it moves atoms; < 0 once a kernel moved them without
  // measuring, and between ticks). Atoms with atom_extra_k set are among them.
  std::vector<int32_t> reach;  // (num_atoms)
  int32_t num_reach = 0;
  double reach_slack = -1;
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

  // RK4 scratch by active slot (only when use_rk4).
  std::vector<Real> rk_x0, rk_v0, rk_dx, rk_dv;  // (num_atoms x 3)

  ImplicitBuffers implicit;  // only when use_implicit

  internal::FusedPassPtr fused;  // full mode only

  // Surface adjacency for the Edit API: triangles of atom i are
  // atom_tri[atom_tri_adr[i] .. + atom_tri_num[i]) (holes allowed after removals).
  std::vector<int32_t> atom_tri_adr, atom_tri_num, atom_tri;

  std::array<ActiveTool, kMaxTools> tools{};
  int32_t num_tools = 0;
  // A punctured needle's captured atoms per tool slot, found at the tick's start (active-list
  // order; the first ActiveTool::num_needle_atoms are meaningful). Kept outside ActiveTool, which
  // ResolveTools resets every tick, so that a scene without a needle never touches them.
  std::array<std::array<int32_t, kNeedleAtoms>, kMaxTools> needle_atoms{};
  // The suture (suture.cc), set by ResolveTools: its punctures pull on the tissue this tick, the
  // needle slot that draws it (-1: none), a tie command's rising edge, and the thread's point in
  // each puncture at the tick's start with its velocity and direction (what the tissue is pulled toward).
  bool suture_on = false;
  int32_t suture_tool = -1;
  bool suture_tie = false;
  std::array<std::array<double, 9>, kSuturePunctures> suture_points{};
};

// Sizes everything for `model` and `options` (validated: IDMS_CHECK on nonsense such as
// dt <= 0). Builds the spatial hash from the rest positions. O(atoms + elements), allocates.
Workspace MakeWorkspace(const Model& model, const StepOptions& options);

// Refiles the spatial hash from `state` and clears per-tick scratch. Step calls it itself (and
// counts warnings.workspace_resync) when the state is not the one it stepped last, e.g. after
// restoring a snapshot. O(atoms), does not allocate.
void ResyncWorkspace(const Model& model, const State& state, Workspace& workspace);

// What full mode's fused kernel is doing, for tests and benches.
struct FusedPassStatus {
  bool live = false;           // its lists are built and kept from tick to tick
  bool identity = false;       // the model's element order is the walk's (renumbered, reorder.h)
  bool row_backup = false;     // the rollback copy of the atoms is two 4-wide rows per atom (float on SSE)
  int32_t sections = 1;        // threads the walk runs on (StepOptions::threads, as the model allows)
  int64_t cross_elements = 0;  // elements between sections, computed twice per substep
  int64_t huge_bytes = 0;      // bytes AdviseHugePages moved to huge pages so far
};
FusedPassStatus GetFusedPassStatus(const Workspace& workspace);

// Opt-in, for benches and model generation (the step itself makes no system call): asks the
// kernel (Linux, madvise MADV_COLLAPSE) to back the 2 MiB-aligned inside of the arrays full
// mode's fused pass streams, the State's included, with huge pages. A 10^6-atom pass crosses a
// 4 KiB page every few hundred elements in each of its ~20 streams, and each crossing can cost a
// page walk. Contents do not change; where the kernel declines, nothing else changes either.
// Call again if the State's arrays move. Returns the bytes moved (0 in local mode or off Linux).
int64_t AdviseHugePages(const State& state, Workspace& workspace);

}  // namespace idms
