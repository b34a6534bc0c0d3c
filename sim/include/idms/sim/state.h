// State: everything a step changes (thesis 4.1 state vector, eq. 4.6 filter state, tools,
// counters). It holds no pointers into the Model, so snapshot, rollback and replay are plain
// copies, and every array has a fixed size from MakeState on, so stepping never allocates.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

namespace idms {

struct Model;

// The scalar of the evolving state. Double by default: positions are absolute (eq. 4.15), and a
// 10^6-atom model spans ~10^3 units, where float keeps only ~6e-5 units of resolution. Define
// IDMS_SIM_REAL_FLOAT on the whole build (it changes the ABI) to measure single precision.
#ifdef IDMS_SIM_REAL_FLOAT
using Real = float;
#else
using Real = double;
#endif

// Tools (devices) stepped at once; ToolInput and the reports hold this many slots.
inline constexpr int kMaxTools = 4;

enum class ToolKind : uint8_t {
  kNone,      // slot unused
  kSphere,    // fingertip MIO: penalty contact with external atoms
  kTweezers,  // a sphere that grasps the nearest contact atom while closed
  kScalpel,   // a blade segment that cuts the elements its swept path crosses; no contact force
  kNeedle,    // a rigid straight needle: its tip presses like a small sphere MIO until it punctures
              // (needle.cc), then the shaft holds the tissue laterally and slides against axial friction
};

// Friction at a contact tool (thesis 7.2.4): none (no friction, or no contact), sticking to its
// anchor on the surface, or slipping (the anchor dragged so that |f_t| = mu_d f_n).
enum class FrictionState : uint8_t { kNone, kStick, kSlip };

// Atoms a friction anchor is spread over: the tool's strongest contacts when it was placed.
inline constexpr int kAnchorAtoms = 4;

// Whether a tool of this kind presses on atoms with the contact law (a sphere MIO: the fingertip,
// the tweezers, and the needle's tip, whose stiffness fades out once it has punctured); the
// scalpel only cuts.
constexpr bool IsContactTool(ToolKind kind) {
  return kind == ToolKind::kSphere || kind == ToolKind::kTweezers || kind == ToolKind::kNeedle;
}

// What a needle slot remembers between ticks (needle.cc). Before puncture, the tip's fade and the
// press's largest per-tick change. Once punctured, the entry point is a weighted mean of surface atoms (the tip's
// strongest contacts at the puncture), so it rides on the tissue; the needle's depth is the tip's distance past it
// along the axis, measured from entry_depth (the depth at the puncture). Axial friction is the
// Kikuuwe stick/slip of friction.cc in one dimension: the needle sticks where depth =
// axial_offset, and axial_u is the committed displacement from there.
struct NeedleState {
  bool punctured = false;
  // The tip contact's stiffness factor: 1 free; once punctured it falls so that the tip's force
  // drops by at most tip_max_step a tick, and after a withdrawal it rises by tip_ramp a tick.
  double tip_scale = 1;
  double tip_ramp = 0;      // in (0, 1]: tip_max_step / the tip force at the puncture, at least dt / 0.25 s
  double tip_max_step = 0;  // largest per-tick change of the tip's axial force while free, force units
  double tip_axial = 0;     // the tip's axial force last tick (on the atoms, along the axis), force units
  int32_t entry_atoms[kAnchorAtoms] = {-1, -1, -1, -1};
  double entry_w[kAnchorAtoms] = {0, 0, 0, 0};
  double entry_depth = 0;   // model units: depth at the puncture (the inserted length is depth - it)
  double axial_offset = 0;  // model units: the depth where the needle sticks
  double axial_u = 0;       // model units: committed axial displacement from the sticking depth
  FrictionState axial = FrictionState::kNone;
  // Through the far side (issue 32): the tip left the tissue (no element within the capture
  // radius of it) at exit_depth past the entry, the exit point riding on the captured atoms
  // nearest the tip then. Pulled on through, the tail passes the entry (entry_passed) and then
  // the exit (a suture it draws passes each in turn), and once it has left the last atom it held,
  // the needle is free again.
  bool exited = false;
  bool entry_passed = false;
  bool exit_passed = false;
  int32_t exit_atoms[kAnchorAtoms] = {-1, -1, -1, -1};
  double exit_w[kAnchorAtoms] = {0, 0, 0, 0};
  double exit_depth = 0;  // model units: depth at the exit
};

// The suture thread (suture.cc): a chain of mass points and tension-only springs whose first node
// the needle's tail (its eye) holds. Every point the thread has been drawn through is a puncture: a
// point riding on tissue atoms that the thread slides through without friction (its arc position
// s, in segments from node 0, follows the nearest point of the thread). A tie binds two points of
// the thread (arc positions fixed: the knot holds the material, not the tissue) with a spring of
// rest length 0 whose pull is bounded by the tie force: the knot drawn tight by hand. Fixed
// arrays: the step never allocates, and a scene without a thread carries one empty struct.
inline constexpr int kSutureSegments = 128;
inline constexpr int kSuturePunctures = 16;
inline constexpr int kSutureTies = 8;

struct SuturePuncture {
  int32_t atoms[kAnchorAtoms] = {-1, -1, -1, -1};
  double w[kAnchorAtoms] = {0, 0, 0, 0};
  double s = 0;  // arc position of the thread in it, segments from node 0
  // Which way along the thread from the puncture before it (+1: at smaller s, -1: larger, 0: the
  // first): punctures keep their order along the thread (the thread between two cannot be negative).
  int32_t order = 0;
};

struct SutureTie {
  double s_a = 0, s_b = 0;        // the knot's two arc positions
  int32_t first = -1, last = -1;  // the punctures it sits on (the knot does not pass into them)
};

struct SutureState {
  int32_t num_nodes = 0;  // 0: no thread (the first needle with suture.length > 0 lays one)
  int32_t tool = -1;      // the needle slot whose tail node 0 follows (-1: it trails free)
  // Resolved when the thread was laid (later commands do not change them).
  double seg_len = 0;    // model units: rest length of each segment
  double node_mass = 0;  // mass units
  double k = 0, b = 0;   // each segment's spring (force / length) and damper (force / (length / s))
  double hold_k = 0;     // a puncture's spring to the thread, force / length
  double hold_b = 0;     // ... and its damper
  // The needle's eye's spring-damper to node 0, the one the hand feels the thread through: the
  // needle's lateral stiffness (what the hand feels of the tissue along the shaft), which a stiff
  // hole (hold_k) would otherwise make a rope's jerk.
  double eye_k = 0, eye_b = 0;
  double strength = 0;   // segment tension at which the thread breaks, force units (0: never)
  double tie_force = 0;  // a knot's largest pull, force units
  double tie_speed = 0;  // model units / s: how fast a knot cinches its loop
  double drag = 0;       // 1 / s: the thread's air damping
  std::array<double, 3 * (kSutureSegments + 1)> pos{};  // model units
  std::array<double, 3 * (kSutureSegments + 1)> vel{};  // model units / s
  std::array<double, 3> eye{};                          // the needle's tail last tick: where node 0 is held
  std::array<SuturePuncture, kSuturePunctures> punctures{};
  int32_t num_punctures = 0;
  int32_t stitch_start = 0;  // the first puncture not yet tied off
  std::array<SutureTie, kSutureTies> ties{};
  int32_t num_ties = 0;
  int32_t broken = -1;    // the segment that parted, or -1
  bool tie_held = false;  // the tie command was on last tick (a tie is edge-triggered)
};

// What a tool slot remembers between ticks (thesis table 5.1 plus the tweezers of 6.1.3).
struct ToolState {
  double pos[3] = {0, 0, 0};         // last valid device endpoint, model frame and units
  double blade_tip[3] = {0, 0, 0};   // scalpel: last valid blade tip (the blade is pos..blade_tip)
  double radius = 0, stiffness = 0;  // sphere/tweezers: last valid MIO r and k
  ToolKind kind = ToolKind::kNone;   // kind of the last valid sample
  bool has_pos = false;              // the fields above hold a valid sample
  bool closed = false;               // tweezers were closed last tick (grasping is edge-triggered)
  // The tweezers' grasp element (thesis 6.1.3): atom -> MIO centre. The centre is not an atom,
  // so the element lives here rather than in the Model, which stays const during a step.
  int32_t grasp_atom = -1;      // -1 = not grasping
  double grasp_leq = 0;         // model units: distance atom-centre when the tweezers closed
  double grasp_k = 0;           // force / length: the MIO's k at closure
  double force[3] = {0, 0, 0};  // device force sent last tick (for the rate clamp), force units
  // Set when the model jumped under the tool (BeginForceTransition: a reset to rest): the device
  // force rises no faster than StepOptions::transition_force_rate for the transition window and
  // then until it has caught up with the contact force.
  bool easing = false;
  int32_t easing_ticks = 0;  // ticks of the transition window still to come
  // Friction's anchor (thesis 7.2.4, friction.cc): a point on the surface, the weighted mean of
  // up to kAnchorAtoms atoms (weights sum to 1, unused slots -1), so it moves as the tissue
  // deforms; the tool sticks where its centre is the anchor point + anchor_offset. friction_u is
  // the committed tangential displacement from there (the implicit-Euler state of Kikuuwe et al.
  // 2006). Cleared when the tool loses contact.
  int32_t anchor_atoms[kAnchorAtoms] = {-1, -1, -1, -1};
  double anchor_w[kAnchorAtoms] = {0, 0, 0, 0};
  double anchor_offset[3] = {0, 0, 0};  // model units: centre - anchor point when sticking
  double friction_u[3] = {0, 0, 0};     // model units, committed at the end of the last tick
  FrictionState friction = FrictionState::kNone;
  double axis[3] = {0, 0, -1};  // needle: last valid unit axis, tail -> tip
  NeedleState needle;
};

// Counted numerical events (STYLE: numerical trouble is a counted warning and a safe fallback).
// The one list of them, as MuJoCo keeps mjtWarning: X(name, meaning) for each. WarningCounters,
// WarningKinds, TotalWarnings and every report are made from it, so none can miss a counter.
#define IDMS_WARNINGS(X)                                                                \
  X(bad_tool_input, "non-finite or negative tool input; the last valid pose was held")  \
  X(substep_limit, "predicted substeps exceeded max_substeps and no fallback allowed")  \
  X(implicit_fallback, "a tick switched from an explicit integrator to implicit Euler") \
  X(rollback, "an attempt failed the finiteness/energy check and was undone")           \
  X(unrecovered, "every attempt failed: the active region was restored at rest")        \
  X(state_repaired, "non-finite atoms found at a tick's start were reset to rest")      \
  X(device_force_nonfinite, "device force was NaN/Inf and was zeroed")                  \
  X(device_force_clamped, "device force magnitude hit max_device_force")                \
  X(device_force_rate_limited, "device force change hit max_device_force_rate")         \
  X(cg_not_converged, "implicit Euler: CG stopped at its iteration limit")              \
  X(implicit_grew, "implicit Euler: the active system outgrew its buffers (allocated)") \
  X(workspace_resync, "the Workspace was rebuilt from a State it had not stepped")

struct WarningCounters {
#define IDMS_WARNING_FIELD(name, meaning) int64_t name = 0;
  IDMS_WARNINGS(IDMS_WARNING_FIELD)
#undef IDMS_WARNING_FIELD
};

struct State {
  double time_s = 0;  // simulated time
  int64_t tick = 0;   // completed steps

  // Thesis 4.1: x1 (held as the absolute position p of eq. 4.15) and x2.
  std::vector<Real> atom_pos;  // (num_atoms x 3), model units
  std::vector<Real> atom_vel;  // (num_atoms x 3), model units / s; 0 for fixed and inactive atoms

  // Eq. 4.6 filter state per element: l_{n-1} and l'_{n-1}, continued at the next update. An
  // element whose filter cannot continue (not updated in the last substep: outside the active
  // region, the last tick ran a scheme without the filter, it was degenerate, or it was just
  // restarted by hand) carries a restart mark, elem_len = kFilterRestart: its next update starts
  // from rest (l_{n-1} = l, l'_{n-1} = 0).
  std::vector<Real> elem_len;   // (num_elems), model units: l at the last update, or kFilterRestart
  std::vector<Real> elem_rate;  // (num_elems), model units / s: filtered length rate

  // Local simulation (thesis 5.5.2): the atoms integrated last tick, in order. The buffer has
  // num_atoms entries; the first num_active are meaningful. atom_linger counts the ticks an atom
  // that left the haptic window may still move while it settles (StepOptions::settle_time_s).
  std::vector<int32_t> active_atoms;  // (num_atoms)
  int32_t num_active = 0;
  std::vector<int32_t> atom_linger;  // (num_atoms), ticks

  std::array<ToolState, kMaxTools> tools{};
  SutureState suture;
  // Energy the dynamics gained with the tools held still, accumulated over recent ticks
  // (StabilityOptions::energy_memory_s): catches a divergence too slow for one tick's check.
  double energy_excess = 0;
  // The tolerance the excess is held to, with the same memory: max(tolerance, decay * allowance).
  // What contact was allowed to gain is forgotten no faster than the gain itself, so a tolerance
  // that shrinks when contact ends cannot fail every later tick on old, accepted gains.
  double energy_allowance = 0;
  WarningCounters warnings;
};

// State::elem_len of an element whose eq. 4.6 filter restarts at its next update (lengths are
// never negative).
inline constexpr Real kFilterRestart = Real(-1);

// A model at rest: p = p_eq, v = 0, element lengths at their current (rest) value. Allocates.
State MakeState(const Model& model);

// Marks every eq. 4.6 filter to restart at its next update (l_{n-1} = l, rate 0): call after
// setting positions by hand (initial conditions, draping), so the first step sees no jump.
void SyncFilterToPositions(const Model& model, State& state);

// Each warning counter with its name (as in WarningCounters), for reports by kind.
struct WarningKind {
  const char* name;
  int64_t count;
};
#define IDMS_WARNING_ONE(name, meaning) +1
inline constexpr int kNumWarningKinds = 0 IDMS_WARNINGS(IDMS_WARNING_ONE);
#undef IDMS_WARNING_ONE
std::array<WarningKind, kNumWarningKinds> WarningKinds(const WarningCounters& warnings);

// The sum of all warning counters (0 in a clean run).
int64_t TotalWarnings(const WarningCounters& warnings);

}  // namespace idms
