// One DSM step (thesis fig. 4-1 and 5-7): tools, active set, forces, integration, checks,
// device force. The options that shape a step live in the Workspace (see MakeWorkspace).
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

#include "idms/sim/state.h"
#include "idms/sim/tool.h"

namespace idms {

struct Model;
struct Workspace;

enum class Integrator : uint8_t {
  kExplicitEuler,    // eqs. 4.13-4.15 exactly: x += T v(n), v += T a(n)  (the thesis reference)
  kSymplecticEuler,  // v(n+1) = v(n) + T a(x(n), v(n)), then x(n+1) = x(n) + T v(n+1)
  kRk4,              // classical Runge-Kutta on (x, v); the tool is held still within a step
  kImplicitEuler,    // linearised backward Euler on the active set (Baraff-Witkin), CG solve
};

// Where the element length rate of eq. 4.8 comes from. RK4 and implicit Euler always use
// kAnalytic: their stages and Jacobian need a force that is a function of (x, v), which a
// filter state is not. Elements with b = 0 everywhere skip the rate altogether.
enum class LengthRate : uint8_t {
  kAuto,      // kFiltered for the Euler schemes
  kFiltered,  // eq. 4.6: lambda (l_n - l_{n-1}) / T + (1 - lambda) l'_{n-1}, T = the substep
  kAnalytic,  // s^ . (v1 - v0)
};

// How a step reacts when the predicted stable step is shorter than dt.
struct StabilityOptions {
  bool predict = true;  // Gershgorin bound over active atoms, tool stiffness included
  double safety = 0.9;  // substep length = safety * predicted stable step
  int32_t max_substeps = 8;
  bool implicit_fallback = true;  // beyond max_substeps, or after a failed check: implicit Euler
  // Reject a tick whose active-region energy grows (see below). Off: a tick is rejected only when
  // an active atom is not finite, and the energies are not formed. (Full mode's fused pass forms
  // them on its way, for about a quarter more time in a one-substep tick: the end-of-tick lengths
  // take a second gather of each element's atoms. The general path spends two passes on them.)
  bool energy_check = true;
  // A tick fails when H_after > H_before + energy_rel_tol * scale + energy_abs_tol, where H is
  // kinetic + elastic + contact + gravity energy of the active region with the tool held at its
  // new pose (so the work the tool did this tick is already in H_before) and scale is the sum of
  // the magnitudes of those terms. Damped dynamics only lose energy; the tolerance absorbs the
  // explicit schemes' O((omega T)^2) per-step error, so this catches divergence, not drift.
  double energy_rel_tol = 0.25;
  double energy_abs_tol = 1e-9;
  // A slow divergence gains a little every tick. The gains H_after - H_before are also summed in
  // State::energy_excess = max(0, decay * excess + gain), decay = exp(-dt / energy_memory_s),
  // and a tick also fails when that sum passes the tolerance remembered the same way
  // (State::energy_allowance = max(tolerance, decay * allowance)): gains accepted under an
  // earlier, larger tolerance decay with it. A stable damped scheme's gains average out below
  // zero; an unstable one's compound.
  double energy_memory_s = 1.0;
  int32_t cg_max_iterations = 200;
  double cg_tolerance = 1e-8;  // relative residual
};

struct StepOptions {
  double dt_s = 1e-3;  // T, the tick (the haptic servo period)
  // The default is the error-against-run-time bench's choice (docs/error-vs-runtime.md): on the
  // Pareto front within the 1 kHz budget in every case measured, where the thesis's explicit
  // Euler with r_l = 2.25 was dominated. The thesis's settings stay one option away.
  Integrator integrator = Integrator::kSymplecticEuler;
  double lambda = 1.0;  // eq. 4.6; 1 = plain backward difference
  LengthRate length_rate = LengthRate::kAuto;

  // Local simulation (thesis 5.5.2): atoms within local_radius of a tool (or of a grasped atom)
  // move; full = every free atom moves (model generation, reference runs). The effective radius
  // is at least the MIO radius, so every contact atom is simulated.
  bool full = false;
  double local_radius = 3.0;  // r_l, model units (2 r; the thesis's 6.2 uses 2.25 = 1.5 r)
  // Beyond the thesis's window: an atom outside it keeps moving while it is unsettled — speed
  // above settle_speed, or elastic force above settle_distance times the sum of its elements'
  // k (it would still move more than settle_distance) — for at most settle_time_s after it
  // last was in the window; then it is immobilised (v = 0). With wake_neighbours, a frozen atom
  // next to the active region that became unsettled (e.g. the tissue around a released pluck)
  // joins the active set too. settle_time_s = 0 and wake_neighbours = false is the thesis.
  double settle_time_s = 1.0;
  double settle_speed = 1e-3;     // model units / s
  double settle_distance = 1e-3;  // model units
  bool wake_neighbours = true;
  double hash_cell = 0;  // spatial-hash cell edge, model units; 0 = local_radius

  // Field forces (thesis eq. 4.2), off unless the scene asks.
  bool gravity = false;
  double gravity_accel[3] = {0, 0, -9.81};  // model units / s^2
  double air_damping = 0;                   // 1/s: f = -air_damping * m * v (the thesis writes -m x1', i.e. 1/s)

  double min_distance_fraction = 0.05;  // thesis contact law guard, fraction of r

  // Device limits: what leaves the step is clamped (the atoms still feel the unclamped force).
  double max_device_force = 10;        // force units (PHANToM-class: ~8.5 N peak)
  double max_device_force_rate = 1e4;  // force units / s
  // After the model jumps under the tool (BeginForceTransition: a reset while pressing leaves the
  // tool deep inside the rest surface), the tissue springs back around the tool for tens of ticks:
  // its contact force leaps to the device's limit, vanishes, and overshoots. For the transition
  // window, and then until it meets the contact force, the device force rises no faster than
  // transition_force_rate (drops pass at once, as always). 10 force units / s is a tenth of the
  // thesis palpation's own steepest rise (0.1 per tick at first contact): no step is felt, and a
  // 1.7 press is regained within 0.2 s. The window outlasts the hex fragment's rebound (~50 ms).
  double transition_force_rate = 10;  // force units / s, > 0
  double transition_window_s = 0.25;  // s, >= 0

  StabilityOptions stability;

  // Full mode with explicit or symplectic Euler takes the fused kernel (see Step); off = the
  // general kernel always (tests and benches compare the two). May change between steps.
  bool fused_pass = true;
  // The fused kernel may use the AVX2 build of its vectorised phase where the CPU has AVX2 (the
  // same bits; off lets a test cover the baseline x86-64 code on any machine).
  bool fused_avx2 = true;
  // Threads for the fused kernel (full mode): the walk in as many contiguous sections of a
  // renumbered model (idms-sim reorder), the same bits as one thread. 1 in a model that is not
  // renumbered, and fewer where a section would have under 256 elements (see GetFusedPassStatus).
  int32_t threads = 1;
};

struct ToolReport {
  double force[3] = {0, 0, 0};      // device force after the finite check and the clamps
  double force_raw[3] = {0, 0, 0};  // -sum of forces the tool applied to atoms (tick average)
  int32_t contacts = 0;             // atoms inside the MIO at the tick's start
  int32_t grasp_atom = -1;          // tweezers: grasped atom after this tick, -1 = none
  int32_t cut_elements = 0;         // scalpel: elements this tick's sweep crossed (pending edit)
  bool input_held = false;          // the input was invalid; the last valid pose was used
  // Friction (friction.cc): its part of force_raw (tangential to the contact, tick average), the
  // normal force it was bounded by (|contact force|, tick average), and the state
  // after this tick. friction_work: the work friction's forces did on the atoms and the device
  // this tick plus the change of its spring's energy (k_t |u|^2 / 2): <= 0 when friction is
  // passive (it only dissipates). All 0 / kNone without friction.
  double friction_force[3] = {0, 0, 0};  // on the device, force units
  double normal_force = 0;               // force units
  double friction_work = 0;              // force * length
  FrictionState friction = FrictionState::kNone;
  // Needle (needle.cc): punctured after this tick; the inserted length (depth past the entry
  // point), model units; the tip's axial force on the tissue (tick average, force units; what the
  // puncture threshold is compared with); the axial friction force on the device along the axis
  // (negative while the needle slides in: it resists) and the grip normal force it was bounded by
  // (the last evaluation's); the atoms the shaft held, and
  // how many near it were left free (more than kNeedleAtoms). All 0 / false without a needle.
  bool punctured = false;
  double inserted = 0;
  double tip_axial_force = 0;
  double axial_force = 0;
  double needle_normal = 0;
  FrictionState axial = FrictionState::kNone;
  int32_t needle_atoms = 0;
  int32_t needle_overflow = 0;
  // Needle through the far side: its tip out of the tissue again (until it is free), and this
  // tick the tail passed the exit (the needle drawn through, free again).
  bool exited = false;
  bool drawn_through = false;
};

// The suture thread (suture.cc) after the tick: what it holds, and this tick's events. All 0 /
// false without a thread.
struct SutureReport {
  int32_t nodes = 0;
  int32_t punctures = 0;      // points the thread has been drawn through
  int32_t new_punctures = 0;  // ... this tick
  int32_t ties = 0;
  bool tied = false;         // this tick's tie command knotted a stitch
  bool tie_refused = false;  // ... or found no stitch to knot (fewer than two punctures since the last tie)
  bool broke = false;        // a segment parted this tick (SutureState::broken says which)
  double max_tension = 0;    // force units: the tautest segment
  double pull = 0;           // force units: the thread's pull on the needle's tail
  int32_t substeps = 0;
};

struct StepReport {
  std::array<ToolReport, kMaxTools> tools{};
  int32_t num_tools = 0;
  SutureReport suture;
  int32_t active_atoms = 0;
  int32_t active_elems = 0;
  int32_t substeps = 0;  // of the accepted attempt
  int32_t attempts = 0;  // 1 unless a check failed and the tick was retried
  Integrator integrator_used = Integrator::kExplicitEuler;
  double predicted_dt_s = 0;  // stable step predicted for the configured integrator
  bool fallback = false;      // the accepted attempt used implicit Euler as a fallback
  bool unrecovered = false;   // every attempt failed; active region restored at rest
  // Full mode's fused pass computed the accepted attempt (internal::FusedPass); false = the
  // general path did (local mode, another integrator, a pending cut, or a fused attempt that met a
  // non-finite value or failed the energy check and was retried there).
  bool fused = false;
  int32_t cg_iterations = 0;  // implicit Euler: total over substeps
  // Active region, with the tools at their new pose; 0 when stability.energy_check is off.
  double energy_before = 0, energy_after = 0;
  int64_t new_warnings = 0;  // warnings counted during this tick
  int32_t pending_cuts = 0;  // elements awaiting ApplyPendingEdits
  // Stage times, ns (steady clock).
  int64_t tools_ns = 0;       // tool validation, grasp, cut detection
  int64_t active_set_ns = 0;  // hash queries, active atoms and elements, hash update
  int64_t forces_ns = 0;      // external and element forces (all evaluations); full mode's fused
                              // pass counts its whole sweep here, integration included
  int64_t integrate_ns = 0;   // state updates, implicit assembly and CG
  int64_t checks_ns = 0;      // prediction, backup, energy, rollback, device force
  int64_t total_ns = 0;
};

// Advances the state by options.dt_s (the options the Workspace was made with):
//  1. tools: validate input, tweezers grasp/release, scalpel sweep -> pending cuts (Edit API);
//  2. active set: atoms within r_l of a tool through the spatial hash (or all, when full);
//  3. element forces (eqs. 4.3-4.9) on elements with an active endpoint, contact (5.5.1);
//  4. integrate the active free atoms, substepped or implicit as predicted, checked for
//     finiteness and energy, rolled back and retried on failure;
//  5. device force = -sum of tool forces on atoms; zeroed if non-finite, clamped.
// Preconditions: state and workspace were made for this model (same topology_version,
// IDMS_CHECK). Single-threaded; never throws. Cost: local mode O(atoms and elements near the
// tools), independent of model size; full mode O(model). The first Step after MakeWorkspace,
// or after the State was replaced (snapshot restore), refiles the spatial hash from the State:
// O(atoms) once — call ResyncWorkspace before a real-time loop starts to keep that out of it.
// Full mode with explicit or symplectic Euler takes a fused pass (internal::FusedPass): forces,
// sums and integration in one sweep, the same bits as the general path at a fraction of its
// memory traffic, with the energy check's energies formed on the way (a tick whose check fails
// is taken back and run by the general path, which rolls back and retries as always; the
// energies' rounding differs from the general path's, so a gain within rounding of the
// tolerance could be judged differently); StepReport::fused says which ran. It keeps the
// full-mode lists from tick to tick and rebuilds them (O(atoms + elements)) after a topology
// edit or a tick that took the general path. Renumbering the model once (reorder.h) lets it
// stream its arrays without an index.
// Allocates nothing with the explicit integrators. Implicit Euler (also as the fallback)
// allocates only when its active system outgrows every earlier one: never in full mode, and in
// local mode only past 2048 active atoms (counted in warnings.implicit_grew).
// Deterministic: the same model, state and input give the same state bits, whatever the
// Workspace's history (lists are kept in atom order), except implicit Euler, whose CG warm
// start lives in the Workspace (same bits for the same Workspace history; otherwise the same
// to the CG tolerance).
StepReport Step(const Model& model, State& state, Workspace& workspace, const ToolInput& input);

// The model jumps under the tools: `to` replaces `from` (a reset to rest). Each tool's device force
// carries on from `from`'s and eases towards the new contact force (StepOptions::transition_*), so
// the hand feels no step. Allocates nothing.
void BeginForceTransition(const State& from, State& to, const StepOptions& options);

// Energy of the whole model (kinetic + elastic, gravity if enabled in the workspace), for tests
// and tools; O(atoms + elements). Does not allocate.
double ModelEnergy(const Model& model, const State& state, const Workspace& workspace);

const char* IntegratorName(Integrator integrator);

// The inverse of IntegratorName ("euler", "symplectic", "rk4", "implicit"); false if unknown.
bool ParseIntegratorName(std::string_view name, Integrator* integrator);

}  // namespace idms
