// The stages of Step (step.cc) as the other sim/src files implement them; nobody else includes it.
#pragma once

#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "idms/sim/model.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"

namespace idms::internal {

inline int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// Below this length an element has no direction (eq. 4.5 would divide by ~0).
inline constexpr Real kMinLength = sizeof(Real) == 4 ? Real(1e-6) : Real(1e-12);

inline bool Finite3(const double* v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

inline double Dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// Squared distance from p to segment ab; *t (when given) the nearest point's parameter in [0, 1].
inline double SegmentDist2(const double p[3], const double a[3], const double b[3], double* t = nullptr) {
  double ab[3], ap[3];
  for (int c = 0; c < 3; ++c) ab[c] = b[c] - a[c], ap[c] = p[c] - a[c];
  const double len2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
  double u = len2 > 0 ? (ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / len2 : 0.0;
  u = u < 0 ? 0.0 : (u > 1 ? 1.0 : u);
  if (t != nullptr) *t = u;
  double d2 = 0;
  for (int c = 0; c < 3; ++c) d2 += (ap[c] - u * ab[c]) * (ap[c] - u * ab[c]);
  return d2;
}

// SphereContact's own first test, inline: the loops over full mode's contact candidates (every
// external atom) skip the call for the atoms a tool cannot touch.
inline bool InsideSphere(const double d[3], double r) { return d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < r * r; }

// A tool parameter as a boundary checks it (the needle's, the suture's): its name, what it must
// be, its value, its lower bound and its largest value. FirstBadParam: the first rule whose value
// is not finite or out of its bounds, or null (no allocation: the step asks it too).
// BadParamMessage: "prefix.field must be <expected>, got <value>". CheckParams: true when every
// rule holds, otherwise false with *error the first bad one's message.
enum class ParamBound : uint8_t { kPositive, kNonNegative, kAny };
struct ParamRule {
  const char* field;
  const char* expected;
  double value;
  ParamBound bound;
  double max = std::numeric_limits<double>::infinity();
};
const ParamRule* FirstBadParam(const ParamRule* rules, int n);
std::string BadParamMessage(const char* prefix, const ParamRule& rule);
bool CheckParams(const char* prefix, const ParamRule* rules, int n, std::string* error);

// Adds the steady-clock time from its construction to its end to *sink: the one idiom for the
// stage times of StepReport.
class StageTimer {
 public:
  explicit StageTimer(int64_t* sink) : sink_(sink), t0_(NowNs()) {}
  ~StageTimer() { *sink_ += NowNs() - t0_; }
  StageTimer(const StageTimer&) = delete;
  StageTimer& operator=(const StageTimer&) = delete;

 private:
  int64_t* sink_;
  int64_t t0_;
};

struct StageTimes {
  int64_t forces_ns = 0;
  int64_t integrate_ns = 0;
};

// tool.cc — stage 1: validates the input into ws.tools (holding the last valid pose on bad
// input), and flags the elements each scalpel's sweep crossed as pending cuts.
void ResolveTools(const Model& model, State& state, Workspace& ws, const ToolInput& input, StepReport* report);

// tool.cc — tweezers: grasp the nearest free contact atom on closing, release on opening.
// Needs the contact candidates, so it runs after BuildActiveSet.
void UpdateGrasps(const Model& model, State& state, Workspace& ws, StepReport* report);

// friction.cc — Coulomb friction with stiction (thesis 7.2.4; the law is described there).
// AnchorPoint: sum of w_i p_i over up to kAnchorAtoms atoms (-1 ends the list); false when it is not
// finite. The friction anchor, and a needle's entry point.
bool AnchorPoint(const State& state, const int32_t* atoms, const double* w, double out[3]);
// SpreadOverStrongest: the tick's strongest contacts with weights by contact force (summing to 1;
// -1 / 0 in unused slots): a new friction anchor, a needle's entry.
void SpreadOverStrongest(const ActiveTool& tool, int32_t* atoms, double* w);
// RankContact: keeps the tool's kAnchorAtoms strongest contacts of the tick (ToolStiffness).
void RankContact(ActiveTool& tool, int32_t atom, double force);
// At the tick's start, after the contacts were ranked: anchors a tool that touches and has none,
// notes the anchor point, and adds the friction spring's stiffness to the anchor atoms'
// atom_extra_k (active atoms only, so ClearExtraK's anchors and ClearTickScratch undo it).
void BeginFriction(State& state, Workspace& ws);
// In ToolForces, after the tool's contact loop (eval_force = the contact forces so far): adds the
// friction force to the anchor atoms' accumulator and to eval_force.
void AddFriction(const State& state, Workspace& ws, ActiveTool& tool, Real* force, int stride);
// Friction's Huber potential at the State's positions for a tool whose contact force sum is `contact`.
double FrictionEnergy(const State& state, const ActiveTool& tool, const double contact[3], double dt);
// After the accepted attempt: stick or slip (the anchor dragged), re-spread, the report's
// friction fields, the anchor back to State; contact lost clears it.
void CommitFriction(State& state, Workspace& ws, StepReport* report);

// needle.cc — the straight needle (the model is described there).
// The command's axis and parameters are valid (a zero axis or a bad parameter is bad input).
bool ValidNeedleCommand(const ToolCommand& command);
// In ResolveTools: the unit axis, parameters with their defaults, the State's needle, the tip's
// faded stiffness, and the inserted shaft's length at the tick's start.
void ResolveNeedle(const State& state, const ToolState& tool_state, const ToolCommand& command, double dt,
                   ActiveTool& tool);
// Some needle is inside the tissue this tick.
bool NeedleInside(const Workspace& ws);
// The inserted shaft's far end (the tip is the tool's pos).
void NeedleShaft(const ActiveTool& tool, double tail[3]);
// In ToolStiffness: each punctured needle's captured atoms (active atoms near the inserted shaft),
// their spring stiffness and the axial spring's on the entry atoms into atom_extra_k.
void BeginNeedles(const State& state, Workspace& ws, StepReport* report);
// In ToolForces, after the tip's contact loop: the lateral and axial forces of a punctured needle
// on the atoms' accumulator and eval_force.
void AddNeedle(const State& state, Workspace& ws, int32_t tool, Real* force, int stride);
// A punctured needle's lateral and axial-friction potentials at the State's positions.
double NeedleEnergy(const State& state, const Workspace& ws, int32_t tool);
// After the accepted attempt: puncture (tip axial force above the threshold), axial stick or slip,
// withdrawal, the tip's fade; the report's needle fields; the needle back to State.
void CommitNeedles(const Model& model, State& state, Workspace& ws, StepReport* report);

// suture.cc — the suture thread (the model is described there).
// The command's suture parameters are valid (a bad one is bad input).
bool ValidSutureCommand(const ToolCommand& command);
// At the end of ResolveTools: lays the thread behind the first needle that asks for one, finds
// the needle drawing it, the tie command's rising edge, and whether its punctures pull this tick.
void ResolveSuture(State& state, Workspace& ws, const ToolInput& input);
// In ToolStiffness: the thread's point in each puncture at the tick's start, and the punctures'
// springs into their atoms' atom_extra_k.
void BeginSuture(const State& state, Workspace& ws);
// In ToolForces: each puncture's spring-damper toward the thread on its atoms' accumulator.
void AddSuture(const State& state, Workspace& ws, Real* force, int stride);
// The punctures' spring potentials at the State's positions.
double SutureEnergy(const State& state, const Workspace& ws);
// From CommitNeedles: needle slot `tool`'s tail passed the point on these atoms; the thread it
// draws now passes through it (a new puncture).
void SutureDrawnThrough(State& state, int32_t tool, const int32_t* atoms, const double* w, SutureReport* report);
// After CommitNeedles: a tie, the thread over the tick, the punctures slid, a break, the pull on
// the needle's tail into its tick_force; the report's suture fields.
void CommitSuture(State& state, Workspace& ws, StepReport* report);

// active_set.cc — stage 2: active atoms (ws.active, copied to State), contact candidates, and
// the active element list; immobilises atoms that left the window and settled.
void BuildActiveSet(const Model& model, State& state, Workspace& ws);

// active_set.cc — after integration: frozen free atoms next to the active region that are no
// longer settled are listed in State::active_atoms, so the next tick moves them.
void WakeNeighbours(const Model& model, State& state, Workspace& ws);

// active_set.cc — clears the per-tick marks of the lists (the between-steps invariant).
void ClearTickScratch(Workspace& ws);

// forces.cc — stage 3: ws.atom_force for the active atoms at the State's current (x, v):
// gravity, air, tool contact and grasp (thesis 4.2, 5.5.1), then element forces (eqs. 4.3-4.9).
// `filtered` uses and advances the eq. 4.6 filter with step T. Each tool's sum of forces on atoms
// lands in ws.tools[t].eval_force.
void EvaluateForces(const Model& model, State& state, Workspace& ws, bool filtered, Real T);

// forces.cc — the parts of EvaluateForces the full-mode fused pass calls on its own, into an
// accumulator holding atom a's force at force[stride * a] (ws.atom_force: stride 3): eq. 4.2
// field forces written over the active atoms' entries; tool contact and grasp forces added to
// them. An atom's sum is formed in one order by both kernels: field, tools, elements in list
// order, and the caller's external forces last (the fused kernel adds those as it integrates
// the atom, so no pass of their own).
void FieldForces(const Model& model, const State& state, Workspace& ws, Real* force, int stride);
void ToolForces(const State& state, Workspace& ws, Real* force, int stride);
// full_step_batch.cc — whether the vectorised paths take their AVX2 code: allowed (StepOptions::
// fused_avx2) and the CPU has it (asked once).
bool UseAvx2(bool allow_avx2);
// Workspace::atom_force_external (num_atoms x 3), or null when there are none.
const Real* ExternalForces(const Model& model, const Workspace& ws);

// The atoms a tool loop visits: Workspace::reach while atoms cannot have moved in from outside it
// (reach_slack > 0), else every candidate. Either gives the same sums in the same order.
struct AtomList {
  const int32_t* ids;
  int32_t n;
};
inline AtomList ToolAtoms(const Workspace& ws) {
  return ws.reach_slack > 0 ? AtomList{ws.reach.data(), ws.num_reach}
                            : AtomList{ws.candidates.data(), ws.num_candidates};
}

// forces.cc — energy of the active region (see StabilityOptions::energy_rel_tol).
struct Energy {
  double h = 0;      // NaN when any active atom is non-finite
  double scale = 0;  // sum of the magnitudes of the terms of h
  // Rounding noise of h: lengths computed from absolute positions carry ~eps * |p| of error,
  // which in float at |p| ~ 10^2 exceeds the abs tolerance; this keeps the check from firing
  // on rounding.
  double noise = 0;
};
Energy ActiveEnergy(const Model& model, const State& state, const Workspace& ws);
// The terms of ActiveEnergy the full-mode fused pass does not form itself, added to `e`: gravity
// over the active atoms (relative to rest) and the tools' penalty potentials and grasp elements
// at their current pose (h, scale, noise; finiteness is the pass's).
void ToolAndGravityEnergy(const Model& model, const State& state, const Workspace& ws, Energy* e);

// Elastic energy of every element against its rest length, sum of k (l - l_eq)^2 / 2.
double ElasticEnergy(const Model& model, const State& state);

// integrate.cc — stage 4: `substeps` substeps of `integrator` over dt; accumulates the tools'
// tick_force (evaluation-weighted average of eval_force). Returns CG iterations (implicit).
int32_t RunIntegrator(const Model& model, State& state, Workspace& ws, Integrator integrator, int32_t substeps,
                      StageTimes* times);

// implicit.cc — one linearised backward-Euler substep of length T on the active set.
// Returns the CG iterations; counts cg_not_converged / implicit_grew in state.warnings.
int32_t ImplicitEulerSubstep(const Model& model, State& state, Workspace& ws, Real T, StageTimes* times);

// implicit.cc — sizes the implicit buffers (MakeWorkspace).
void SizeImplicitBuffers(const Model& model, Workspace& ws);

// full_step.cc — the full-mode fused pass (Workspace::fused).
// True when this tick can take it: full mode, explicit or symplectic Euler, no cut pending, and
// a model with elements. Evaluated after ResolveTools.
bool FusedEligible(const Model& model, const Workspace& ws);
// Makes the full-mode lists live (BuildActiveSet once, then the pass's arrays), or rebuilds
// them after a topology edit. O(atoms + elements) when it rebuilds, else O(1); no allocation.
void EnsureFullLive(const Model& model, State& state, Workspace& ws);
// Restores the between-steps invariant of the marks before a general-path tick.
void EndFullLive(Workspace& ws);
// Makes and sizes the fused kernel (MakeWorkspace, full mode).
void SizeFusedPass(const Model& model, Workspace& ws);

// The part of [data, data + bytes) that whole 2 MiB pages cover: {begin, length}, length 0 if none.
struct HugeRange {
  uintptr_t begin = 0;
  size_t length = 0;
};
HugeRange HugePageInterior(const void* data, size_t bytes);
// The stable step of `integrator` over the free atoms with the tools' stiffness this tick, from
// the cached tool-free minimum plus the atoms a tool stiffens: the value PredictStableDt gives.
double FullPredictStableDt(const Model& model, const Workspace& ws, Integrator integrator);
// The energy check's kinetic and elastic energy of the active region (ActiveEnergy's terms), as
// the fused pass forms them on the way: at the tick's start and at its end.
struct FusedEnergy {
  double kinetic_before = 0, elastic_before = 0;
  double noise_before = 0;  // a bound on the elastic part of Energy::noise
  double kinetic_after = 0, elastic_after = 0;
};
// `substeps` fused substeps of `integrator` (the plan's first attempt). Writes the rollback copy
// on the way; returns false, with the State back at the tick's start, when an input or a result
// was not finite (the general path then repairs, retries and falls back as usual). `energy`, if
// not null, receives the energy check's terms (one more gather per element, from cache).
bool RunFused(const Model& model, State& state, Workspace& ws, Integrator integrator, int32_t substeps,
              StageTimes* times, FusedEnergy* energy);
// Takes back an attempt RunFused completed: the State back at the tick's start from the pass's
// rollback copy.
void RestoreFused(const Model& model, State& state, Workspace& ws);
// The fused kernel's lists are live (full mode, kept from tick to tick).
bool FusedLive(const Workspace& ws);
// Forgets the fused kernel's lists and cached zero forces (ResyncWorkspace).
void ResetFused(Workspace& ws);
// Zeroes atom_extra_k where ToolStiffness may have set it (Workspace::reach).
void ClearExtraK(Workspace& ws);

// True when the resolved eq. 4.6 mode for `integrator` is the filter.
inline bool UsesFilter(const StepOptions& options, Integrator integrator) {
  const bool euler = integrator == Integrator::kExplicitEuler || integrator == Integrator::kSymplecticEuler;
  return euler && options.length_rate != LengthRate::kAnalytic;
}

}  // namespace idms::internal
