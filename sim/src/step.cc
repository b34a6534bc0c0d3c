// Step: the DSM tick of thesis figs. 4-1 and 5-7 as a pipeline of timed stages, with the
// stability control of thesis 4.2 (predict, substep or fall back, check, roll back, retry) and
// the device-force safety net.
#include "idms/sim/step.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "idms/sim/check.h"
#include "idms/sim/integrate.h"
#include "idms/sim/model.h"
#include "idms/sim/tool.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms {

const char* IntegratorName(Integrator integrator) {
  switch (integrator) {
    case Integrator::kExplicitEuler:
      return "euler";
    case Integrator::kSymplecticEuler:
      return "symplectic";
    case Integrator::kRk4:
      return "rk4";
    case Integrator::kImplicitEuler:
      return "implicit";
  }
  return "?";
}

bool ParseIntegratorName(std::string_view name, Integrator* integrator) {
  for (Integrator i :
       {Integrator::kExplicitEuler, Integrator::kSymplecticEuler, Integrator::kRk4, Integrator::kImplicitEuler}) {
    if (name == IntegratorName(i)) {
      *integrator = i;
      return true;
    }
  }
  return false;
}

namespace {

using internal::Energy;
using internal::StageTimer;
using internal::StageTimes;

struct Plan {
  Integrator integrator = Integrator::kExplicitEuler;
  int32_t substeps = 1;
  bool fallback = false;
};

// Tool stiffness felt by each atom this tick (contact normal stiffness, grasp k), contacts, and
// the atoms within the tools' reach (Workspace::reach), in one pass over the candidates: for each
// atom the tools in order, as a pass per tool would add them.
constexpr int32_t kToolPrefetch = 16;  // candidates ahead
void ToolStiffness(State& s, Workspace& ws, StepReport* report) {
  ws.num_reach = 0;
  ws.reach_slack = -1;
  double slack = std::numeric_limits<double>::infinity();
  bool grasp_seen[kMaxTools] = {};
  bool friction = false, needle = false;
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    ActiveTool& at = ws.tools[t];
    if (IsContactTool(at.kind)) slack = std::min(slack, 0.5 * at.radius);
    std::fill(at.strong_atoms, at.strong_atoms + kAnchorAtoms, -1);
    std::fill(at.strong_f, at.strong_f + kAnchorAtoms, 0.0);
    friction = friction || at.mu_s > 0;
    needle = needle || at.kind == ToolKind::kNeedle;
  }
  internal::BeginSuture(s, ws);
  if (slack == std::numeric_limits<double>::infinity()) return;  // no contact tool
  const int32_t n = ws.num_candidates;
  for (int32_t i = 0; i < n; ++i) {
    const int32_t a = ws.candidates[i];
    // The loads wait on memory (the pass before streamed the whole model through the caches).
    if (i + kToolPrefetch < n) __builtin_prefetch(&s.atom_pos[3 * ws.candidates[i + kToolPrefetch]]);
    const Real* p = &s.atom_pos[3 * a];
    bool near = false;
    for (int32_t t = 0; t < ws.num_tools; ++t) {
      ActiveTool& at = ws.tools[t];
      if (!IsContactTool(at.kind)) continue;
      if (a == at.grasp_atom) {
        near = grasp_seen[t] = true;
        ws.atom_extra_k[a] += at.grasp_k;
        // Its contact is counted (it is not felt: the grasp element holds it).
      }
      const double d[3] = {p[0] - at.pos[0], p[1] - at.pos[1], p[2] - at.pos[2]};
      near = near || internal::InsideSphere(d, 2 * at.radius);
      if (!internal::InsideSphere(d, at.radius)) continue;
      const ContactForce cf = SphereContact(at.law, at.stiffness, at.radius, ws.options.min_distance_fraction, d);
      if (!cf.touching) continue;
      ++report->tools[t].contacts;
      if (a != at.grasp_atom) ws.atom_extra_k[a] += cf.stiffness;
      // The strongest contacts: friction's anchor, a needle's entry point.
      if ((at.mu_s > 0 || at.kind == ToolKind::kNeedle) && a != at.grasp_atom) {
        internal::RankContact(at, a, std::sqrt(cf.f[0] * cf.f[0] + cf.f[1] * cf.f[1] + cf.f[2] * cf.f[2]));
      }
    }
    if (near) ws.reach[ws.num_reach++] = a;
  }
  // A grasped atom that is not a candidate (the list changed since the grasp) is held all the same.
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    const ActiveTool& at = ws.tools[t];
    if (IsContactTool(at.kind) && at.grasp_atom >= 0 && !grasp_seen[t]) ws.atom_extra_k[at.grasp_atom] += at.grasp_k;
  }
  ws.reach_slack = slack;
  if (friction) internal::BeginFriction(s, ws);
  if (needle) internal::BeginNeedles(s, ws, report);
}

// Thesis 4.2 past the 6th-order window: the smallest predicted stable step over active atoms.
double PredictStableDt(const Model& m, const Workspace& ws, Integrator integrator) {
  if (internal::FusedLive(ws)) return internal::FullPredictStableDt(m, ws, integrator);
  double dt = std::numeric_limits<double>::infinity();
  const LengthRate rate = internal::UsesFilter(ws.options, integrator) ? LengthRate::kFiltered : LengthRate::kAnalytic;
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    const AtomBound bound{m.atom_omega2[a] + ws.atom_extra_k[a] / m.atom_mass[a],
                          m.atom_damp[a] + ws.options.air_damping};
    dt = std::min(dt, StableDt(integrator, bound, rate, ws.options.lambda));
  }
  return dt;
}

// The attempts of this tick, in order: the configured scheme with the predicted substeps, then
// the implicit fallback (or more substeps when no fallback is allowed).
int32_t MakePlans(const Model& m, State& s, Workspace& ws, StepReport* report, Plan plans[3]) {
  const StabilityOptions& st = ws.options.stability;
  const Integrator configured = ws.options.integrator;
  if (configured == Integrator::kImplicitEuler) {
    plans[0] = {configured, 1, false};
    plans[1] = {configured, 4, false};
    return 2;
  }
  int32_t n = 1;
  if (st.predict) {
    report->predicted_dt_s = PredictStableDt(m, ws, configured);
    const double ratio = ws.options.dt_s / (st.safety * report->predicted_dt_s);
    n = ratio <= 1 ? 1 : ratio <= st.max_substeps ? static_cast<int32_t>(std::ceil(ratio)) : st.max_substeps + 1;
  }
  if (n > st.max_substeps) {
    if (st.implicit_fallback) {
      plans[0] = {Integrator::kImplicitEuler, 1, true};
      plans[1] = {Integrator::kImplicitEuler, 4, true};
      return 2;
    }
    ++s.warnings.substep_limit;
    plans[0] = {configured, st.max_substeps, false};
    return 1;
  }
  plans[0] = {configured, n, false};
  if (st.implicit_fallback) {
    plans[1] = {Integrator::kImplicitEuler, 1, true};
    plans[2] = {Integrator::kImplicitEuler, 4, true};
    return 3;
  }
  if (2 * n > st.max_substeps) return 1;
  plans[1] = {configured, 2 * n, false};
  return 2;
}

// Whether this tick's attempts can change the eq. 4.6 filter state: only the configured scheme
// reads it (the implicit fallback uses the analytic rate), and only when some b > 0. When not,
// the filter arrays need no rollback copy (leave out what the scene does not need).
bool FilterInUse(const Model& m, const Workspace& ws) {
  return m.has_damping && internal::UsesFilter(ws.options, ws.options.integrator);
}

// Marks the listed elements' eq. 4.6 filters to restart: this tick did not advance them.
void MarkListedFilters(State& s, const Workspace& ws) {
  for (int32_t i = 0; i < ws.num_elems; ++i) s.elem_len[ws.elems[i]] = kFilterRestart;
}

// Non-finite atoms or filter states found at a tick's start (a State that came in broken) are
// reset to rest, so that one bad value cannot poison every later tick. True when it reset any.
bool RepairActiveRegion(const Model& m, State& s, Workspace& ws) {
  bool repaired = false;
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    Real* p = &s.atom_pos[3 * a];
    Real* v = &s.atom_vel[3 * a];
    bool ok = true;
    for (int c = 0; c < 3; ++c) ok = ok && std::isfinite(p[c]) && std::isfinite(v[c]);
    if (ok) continue;
    for (int c = 0; c < 3; ++c) p[c] = static_cast<Real>(m.atom_pos_eq[3 * a + c]), v[c] = 0;
    if (!ws.options.full) UpdateSpatialHash(ws.hash, a, p);
    repaired = true;
  }
  // The filter state only where the configured scheme reads it (an unused one stays as it is).
  const bool filter = FilterInUse(m, ws);
  for (int32_t i = 0; filter && i < ws.num_elems; ++i) {
    const int32_t e = ws.elems[i];
    if (std::isfinite(s.elem_len[e]) && std::isfinite(s.elem_rate[e])) continue;
    s.elem_len[e] = kFilterRestart;
    s.elem_rate[e] = 0;
    repaired = true;
  }
  if (repaired) ++s.warnings.state_repaired;
  return repaired;
}

// The general kernel's rollback copy of the active region: atoms by slot, elements by list
// index. kSave: State to the copy (the tick's start); else the copy back to State.
template <bool kSave>
void CopyRegion(const Model& m, State& s, Workspace& ws) {
  auto copy = [](auto& in_state, auto& in_copy) {
    if constexpr (kSave) {
      in_copy = in_state;
    } else {
      in_state = in_copy;
    }
  };
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    for (int c = 0; c < 3; ++c)
      copy(s.atom_pos[3 * a + c], ws.backup_pos[3 * i + c]), copy(s.atom_vel[3 * a + c], ws.backup_vel[3 * i + c]);
  }
  const int32_t num_elems = FilterInUse(m, ws) ? ws.num_elems : 0;
  for (int32_t i = 0; i < num_elems; ++i) {
    const int32_t e = ws.elems[i];
    copy(s.elem_len[e], ws.backup_elem_len[i]);
    copy(s.elem_rate[e], ws.backup_elem_rate[i]);
  }
}

// Stage 5: device force = -sum of the tool's forces on atoms; zeroed when non-finite, magnitude
// clamped, and its growth rate-limited (drops pass at once: releasing is always safe, and the
// thesis's tweezers force "instantly falls to zero", 6.1.3).
void DeviceForces(State& s, const Workspace& ws, StepReport* report) {
  const StepOptions& o = ws.options;
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    ToolReport& tr = report->tools[t];
    ToolState& ts = s.tools[t];
    double f[3] = {0, 0, 0};
    if (ws.tools[t].kind != ToolKind::kNone) {
      for (int c = 0; c < 3; ++c) f[c] = -ws.tools[t].tick_force[c];
    }
    std::copy(f, f + 3, tr.force_raw);
    double mag = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    if (!std::isfinite(mag)) {
      ++s.warnings.device_force_nonfinite;
      f[0] = f[1] = f[2] = mag = 0;
    }
    const double prev = std::sqrt(ts.force[0] * ts.force[0] + ts.force[1] * ts.force[1] + ts.force[2] * ts.force[2]);
    const double rate =
        ts.easing ? std::min(o.transition_force_rate, o.max_device_force_rate) : o.max_device_force_rate;
    double limit = o.max_device_force;
    if (prev + rate * o.dt_s < limit) limit = prev + rate * o.dt_s;
    if (mag > limit) {
      // Easing in is the expected path after a jump, not a numerical event.
      if (!ts.easing)
        ++(limit < o.max_device_force ? s.warnings.device_force_rate_limited : s.warnings.device_force_clamped);
      for (int c = 0; c < 3; ++c) f[c] *= limit / mag;
    } else if (ts.easing_ticks == 0) {
      ts.easing = false;  // the window is over and the contact force met: the ordinary limits again
    }
    if (ts.easing_ticks > 0) --ts.easing_ticks;
    std::copy(f, f + 3, ts.force);
    std::copy(f, f + 3, tr.force);
  }
}

// Without the energy check a tick is accepted when every active atom is finite.
bool ActiveFinite(const State& s, const Workspace& ws) {
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    for (int c = 0; c < 3; ++c) {
      if (!std::isfinite(s.atom_pos[3 * a + c]) || !std::isfinite(s.atom_vel[3 * a + c])) return false;
    }
  }
  return true;
}

// The tick's attempts, the stability policy of thesis 4.2 over two kernels: plan (substeps as
// predicted, implicit Euler as the fallback), keep a rollback copy and the energy before, run each
// attempt through a kernel, check it (energy, or finiteness), and roll back and retry down the
// plan; when every attempt fails, freeze the active region. The kernel of the first attempt is the
// fused one when the tick can take it (full mode, the configured explicit scheme): it writes the
// rollback copy and forms the energies on its way, and checks the tick's start state as it reads
// it. A fused attempt that fails is run again by the general kernel, whose check decides (the
// fused energies round differently, and the general kernel's bits are the reference); every other
// attempt is the general kernel's.
class Dynamics {
 public:
  Dynamics(const Model& m, State& s, Workspace& ws, StepReport* report, StageTimes* times)
      : m_(m), s_(s), ws_(ws), st_(ws.options.stability), report_(report), times_(times) {}

  // Stages 3-4; `fused`: the tick may take the fused kernel (its lists are live).
  void Run(bool fused) {
    {
      StageTimer timer(&report_->checks_ns);
      // The general kernel is handed a repaired state; the fused one finds a broken one itself.
      if (!fused) RepairActiveRegion(m_, s_, ws_);
      if (substep_limit_ < 0) substep_limit_ = s_.warnings.substep_limit;
      ToolStiffness(s_, ws_, report_);
      num_plans_ = MakePlans(m_, s_, ws_, report_, plans_);
      fused = fused && plans_[0].integrator == ws_.options.integrator;
      decay_ = std::exp(-ws_.options.dt_s / st_.energy_memory_s);
      if (fused) {
        // Tools and gravity here; the pass forms the kinetic and elastic terms.
        if (st_.energy_check) internal::ToolAndGravityEnergy(m_, s_, ws_, &before_);
      } else {
        GeneralStart();
      }
    }
    bool accepted = false;
    for (int32_t k = 0; k < num_plans_ && !accepted; ++k) {
      const Plan& plan = plans_[k];
      if (k > 0) {
        StageTimer timer(&report_->checks_ns);
        CopyRegion<false>(m_, s_, ws_);
        ++s_.warnings.rollback;
      }
      if (k == 0 && fused) {
        accepted = FusedAttempt(plan);
        report_->fused = accepted;
        if (!accepted) {
          if (HandOver()) {
            // The state came in broken: repaired, the tick is planned again from it.
            Run(false);
            return;
          }
          // The general kernel is the judge: the same attempt again (same bits; its energies
          // round differently), then the rest of the plan as usual.
          accepted = GeneralAttempt(plan);
        }
      } else {
        accepted = GeneralAttempt(plan);
      }
      report_->attempts = k + 1;
      report_->substeps = plan.substeps;
      report_->integrator_used = plan.integrator;
      report_->fallback = plan.fallback;
    }
    StageTimer timer(&report_->checks_ns);
    if (!accepted) Freeze();
    // Filters the accepted attempt did not advance cannot continue next tick.
    if (m_.has_damping && !(accepted && internal::UsesFilter(ws_.options, report_->integrator_used))) {
      MarkListedFilters(s_, ws_);
    }
    report_->energy_before = before_.h;
  }

 private:
  // The general kernel's rollback copy and energy at the tick's start (tools at their new pose).
  void GeneralStart() {
    CopyRegion<true>(m_, s_, ws_);
    // The energies cost two passes over the active region: only when the check is on.
    before_ = st_.energy_check ? internal::ActiveEnergy(m_, s_, ws_) : Energy{};
  }

  // The fused kernel's attempt, checked as the general one's. A failure leaves the State at the
  // tick's start.
  bool FusedAttempt(const Plan& plan) {
    internal::FusedEnergy fe;
    if (!internal::RunFused(m_, s_, ws_, plan.integrator, plan.substeps, times_, st_.energy_check ? &fe : nullptr)) {
      return false;
    }
    StageTimer timer(&report_->checks_ns);
    if (!st_.energy_check) return Accept(0, 0, true);
    before_.h += fe.kinetic_before + fe.elastic_before;
    before_.scale += fe.kinetic_before + fe.elastic_before;
    before_.noise += fe.noise_before;
    Energy after;
    internal::ToolAndGravityEnergy(m_, s_, ws_, &after);
    after.h += fe.kinetic_after + fe.elastic_after;
    if (Accept(after.h - before_.h, after.h, false)) return true;
    internal::RestoreFused(m_, s_, ws_);
    return false;
  }

  // After a failed fused attempt (State at the tick's start): the general kernel takes the rest
  // of the plan, with its own rollback copy and energies. True when the tick's start state was
  // broken and has been repaired: then the tick is planned again.
  bool HandOver() {
    StageTimer timer(&report_->checks_ns);
    if (RepairActiveRegion(m_, s_, ws_)) {
      internal::ClearExtraK(ws_);
      for (ToolReport& tr : report_->tools) tr.contacts = 0;
      s_.warnings.substep_limit = substep_limit_;
      before_ = Energy{};
      return true;
    }
    GeneralStart();
    return false;
  }

  bool GeneralAttempt(const Plan& plan) {
    IDMS_CHECK(plan.integrator != Integrator::kRk4 || ws_.use_rk4);
    report_->cg_iterations = internal::RunIntegrator(m_, s_, ws_, plan.integrator, plan.substeps, times_);
    StageTimer timer(&report_->checks_ns);
    if (!st_.energy_check) return Accept(0, 0, ActiveFinite(s_, ws_));
    const double after = internal::ActiveEnergy(m_, s_, ws_).h;
    return Accept(after - before_.h, after, true);
  }

  // The energy check (StabilityOptions) on an attempt that gained `gain`; without it, `finite`
  // decides. An accepted attempt's excess and allowance are kept.
  bool Accept(double gain, double energy_after, bool finite) {
    report_->energy_after = energy_after;
    const double tolerance = Tolerance();
    const double allowance = std::max(tolerance, s_.energy_allowance * decay_);
    const double excess =
        st_.energy_check ? std::max(0.0, s_.energy_excess * decay_ + gain) : s_.energy_excess * decay_;
    const bool ok = st_.energy_check ? gain <= tolerance && excess <= allowance : finite;  // false for NaN
    if (ok) Keep(excess, allowance);
    return ok;
  }

  // The tolerance a gain is held to (energy_abs_tol when the check is off: before_ is zero).
  double Tolerance() const { return st_.energy_rel_tol * before_.scale + st_.energy_abs_tol + 4 * before_.noise; }

  void Keep(double excess, double allowance) {
    s_.energy_excess = std::isfinite(excess) ? excess : s_.energy_excess * decay_;
    if (std::isfinite(allowance)) s_.energy_allowance = allowance;
  }

  // Every attempt failed: back to the tick's start, at rest (the filters are marked to restart
  // by Run); no device force.
  void Freeze() {
    CopyRegion<false>(m_, s_, ws_);
    for (int32_t i = 0; i < ws_.num_active; ++i) {
      const int32_t a = ws_.active[i];
      s_.atom_vel[3 * a] = s_.atom_vel[3 * a + 1] = s_.atom_vel[3 * a + 2] = 0;
    }
    for (int32_t t = 0; t < ws_.num_tools; ++t) {
      std::fill(ws_.tools[t].tick_force, ws_.tools[t].tick_force + 3, 0.0);
      std::fill(ws_.tools[t].tick_friction, ws_.tools[t].tick_friction + 3, 0.0);
      ws_.tools[t].tick_fn = 0;
    }
    ++s_.warnings.unrecovered;
    Keep(s_.energy_excess * decay_, std::max(Tolerance(), s_.energy_allowance * decay_));
    report_->unrecovered = true;
    report_->fallback = false;
    if (st_.energy_check) report_->energy_after = internal::ActiveEnergy(m_, s_, ws_).h;
  }

  const Model& m_;
  State& s_;
  Workspace& ws_;
  const StabilityOptions& st_;
  StepReport* report_;
  StageTimes* times_;
  Plan plans_[3];
  int32_t num_plans_ = 0;
  Energy before_;
  double decay_ = 1;
  int64_t substep_limit_ = -1;  // warnings.substep_limit at the tick's start
};

}  // namespace

StepReport Step(const Model& m, State& s, Workspace& ws, const ToolInput& input) {
  using namespace internal;
  StepReport report;
  StageTimer total(&report.total_ns);
  IDMS_CHECK(ws.num_atoms == m.num_atoms && ws.topology_version == m.topology_version);
  IDMS_CHECK(static_cast<int32_t>(s.atom_pos.size()) == 3 * m.num_atoms &&
             static_cast<int32_t>(s.elem_len.size()) == m.num_elems);
  const int64_t warnings_before = TotalWarnings(s.warnings);
  if (s.tick != ws.synced_tick) {
    if (ws.synced_tick >= 0) ++s.warnings.workspace_resync;
    ResyncWorkspace(m, s, ws);
  }

  // 1. Tools: validated input, scalpel sweeps -> pending cuts.
  {
    StageTimer timer(&report.tools_ns);
    ResolveTools(m, s, ws, input, &report);
  }

  // 2. Active set (haptic window), then the tweezers, which need its contact candidates. The
  // fused kernel keeps its full-mode lists from tick to tick; every other tick builds them.
  const bool fused = FusedEligible(m, ws);
  {
    StageTimer timer(&report.active_set_ns);
    if (fused) {
      EnsureFullLive(m, s, ws);
    } else {
      EndFullLive(ws);
      BuildActiveSet(m, s, ws);
    }
  }
  {
    StageTimer timer(&report.tools_ns);
    UpdateGrasps(m, s, ws, &report);
  }

  // 3-4. Dynamics: plan, integrate, check, roll back and retry.
  StageTimes times;
  Dynamics(m, s, ws, &report, &times).Run(fused);
  if (report.fallback) ++s.warnings.implicit_fallback;
  report.forces_ns = times.forces_ns;
  report.integrate_ns = times.integrate_ns;

  // 5. Friction's anchors (stick or slip), needles (puncture, axial stick or slip, withdrawal,
  // through), the suture thread (ties, its own dynamics, breaks), then the device force.
  {
    StageTimer timer(&report.checks_ns);
    CommitFriction(s, ws, &report);
    CommitNeedles(m, s, ws, &report);
    CommitSuture(s, ws, &report);
    DeviceForces(s, ws, &report);
  }

  // Refile the atoms that moved (local mode: nothing else can have moved).
  {
    StageTimer timer(&report.active_set_ns);
    if (!ws.options.full) {
      for (int32_t i = 0; i < ws.num_active; ++i)
        UpdateSpatialHash(ws.hash, ws.active[i], &s.atom_pos[3 * ws.active[i]]);
    }
    WakeNeighbours(m, s, ws);
    report.active_atoms = ws.num_active;
    report.active_elems = ws.num_elems;
    report.pending_cuts = ws.num_pending_cuts;
    if (report.fused) {
      ClearExtraK(ws);  // the lists stay live for the next tick
    } else {
      EndFullLive(ws);
      ClearTickScratch(ws);
    }
  }

  ++s.tick;
  s.time_s += ws.options.dt_s;
  ws.synced_tick = s.tick;
  ws.reach_slack = -1;  // the caller may move atoms before the next tick
  report.new_warnings = TotalWarnings(s.warnings) - warnings_before;
  return report;
}

void BeginForceTransition(const State& from, State& to, const StepOptions& options) {
  const auto window = static_cast<int32_t>(std::ceil(options.transition_window_s / options.dt_s));
  for (int t = 0; t < kMaxTools; ++t) {
    ToolState& ts = to.tools[t];
    std::copy(from.tools[t].force, from.tools[t].force + 3, ts.force);
    ts.easing = true;
    ts.easing_ticks = std::max(window, 0);
  }
}

}  // namespace idms
