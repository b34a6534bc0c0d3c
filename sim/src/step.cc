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

using internal::NowNs;

struct Plan {
  Integrator integrator = Integrator::kExplicitEuler;
  int32_t substeps = 1;
  bool fallback = false;
};

// Tool stiffness felt by each atom this tick (contact normal stiffness, grasp k), and contacts.
void ToolStiffness(const State& s, Workspace& ws, StepReport* report) {
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    const ActiveTool& at = ws.tools[t];
    if (!IsContactTool(at.kind)) continue;
    for (int32_t i = 0; i < ws.num_candidates; ++i) {
      const int32_t a = ws.candidates[i];
      const Real* p = &s.atom_pos[3 * a];
      const double d[3] = {p[0] - at.pos[0], p[1] - at.pos[1], p[2] - at.pos[2]};
      if (!internal::InsideSphere(d, at.radius)) continue;
      const ContactForce cf = SphereContact(at.law, at.stiffness, at.radius, ws.options.min_distance_fraction, d);
      if (!cf.touching) continue;
      ++report->tools[t].contacts;
      if (a != at.grasp_atom) ws.atom_extra_k[a] += cf.stiffness;
    }
    if (at.grasp_atom >= 0) ws.atom_extra_k[at.grasp_atom] += at.grasp_k;
  }
}

// Thesis 4.2 past the 6th-order window: the smallest predicted stable step over active atoms.
double PredictStableDt(const Model& m, const Workspace& ws, Integrator integrator) {
  if (ws.full.live) return internal::FullPredictStableDt(m, ws, integrator);
  double dt = std::numeric_limits<double>::infinity();
  const LengthRate rate = internal::UsesFilter(ws.options, integrator) ? LengthRate::kFiltered : LengthRate::kAnalytic;
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    const AtomBound bound{ws.atom_omega2[a] + ws.atom_extra_k[a] / m.atom_mass[a],
                          ws.atom_damp[a] + ws.options.air_damping};
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
bool FilterInUse(const Workspace& ws) {
  return ws.any_damping && internal::UsesFilter(ws.options, ws.options.integrator);
}

// Non-finite atoms or filter states found at a tick's start (a State that came in broken) are
// reset to rest, so that one bad value cannot poison every later tick.
void RepairActiveRegion(const Model& m, State& s, Workspace& ws) {
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
  const bool filter = FilterInUse(ws);
  for (int32_t i = 0; filter && i < ws.num_elems; ++i) {
    const int32_t e = ws.elems[i];
    if (std::isfinite(s.elem_len[e]) && std::isfinite(s.elem_rate[e])) continue;
    s.elem_len[e] = s.elem_rate[e] = 0;
    s.elem_stamp[e] = std::numeric_limits<int64_t>::min();
    repaired = true;
  }
  if (repaired) ++s.warnings.state_repaired;
}

// The active region and its rollback copy: atoms by slot, elements by list index. kSave: State
// to the copy (the tick's start); else the copy back to State.
template <bool kSave>
void CopyRegion(State& s, Workspace& ws) {
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
  const int32_t num_elems = FilterInUse(ws) ? ws.num_elems : 0;
  for (int32_t i = 0; i < num_elems; ++i) {
    const int32_t e = ws.elems[i];
    copy(s.elem_len[e], ws.backup_elem_len[i]);
    copy(s.elem_rate[e], ws.backup_elem_rate[i]);
    copy(s.elem_stamp[e], ws.backup_elem_stamp[i]);
  }
}

void Backup(State& s, Workspace& ws) { CopyRegion<true>(s, ws); }

void Restore(State& s, Workspace& ws, int64_t clock) {
  CopyRegion<false>(s, ws);
  s.substep_clock = clock;
}

// Every attempt failed: back to the tick's start, at rest, filters restarted; no device force.
void Freeze(State& s, Workspace& ws, int64_t clock) {
  Restore(s, ws, clock);
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    s.atom_vel[3 * a] = s.atom_vel[3 * a + 1] = s.atom_vel[3 * a + 2] = 0;
  }
  const int32_t num_elems = FilterInUse(ws) ? ws.num_elems : 0;
  for (int32_t i = 0; i < num_elems; ++i) s.elem_stamp[ws.elems[i]] = std::numeric_limits<int64_t>::min();
  for (int32_t t = 0; t < ws.num_tools; ++t) std::fill(ws.tools[t].tick_force, ws.tools[t].tick_force + 3, 0.0);
  ++s.warnings.unrecovered;
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
    double limit = o.max_device_force;
    if (prev + o.max_device_force_rate * o.dt_s < limit) limit = prev + o.max_device_force_rate * o.dt_s;
    if (mag > limit) {
      ++(limit < o.max_device_force ? s.warnings.device_force_rate_limited : s.warnings.device_force_clamped);
      for (int c = 0; c < 3; ++c) f[c] *= limit / mag;
    }
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

// Stages 3-4 of the general path: stability plan, rollback copy, energy before (tools at their
// new pose); integrate, check finiteness and energy, roll back and retry down the plan list;
// every attempt failing freezes the active region.
void GeneralTick(const Model& m, State& s, Workspace& ws, StepReport* report, internal::StageTimes* times) {
  using namespace internal;
  int64_t t0 = NowNs();
  RepairActiveRegion(m, s, ws);
  ToolStiffness(s, ws, report);
  Plan plans[3];
  const int32_t num_plans = MakePlans(m, s, ws, report, plans);
  Backup(s, ws);
  const int64_t clock = s.substep_clock;
  const StabilityOptions& st = ws.options.stability;
  // The energies cost two passes over the active region: only when the check is on.
  const Energy before = st.energy_check ? ActiveEnergy(m, s, ws) : Energy{};
  const double tolerance = st.energy_rel_tol * before.scale + st.energy_abs_tol + 4 * before.noise;
  const double excess_decay = std::exp(-ws.options.dt_s / st.energy_memory_s);
  double excess = s.energy_excess * excess_decay;
  const double allowance = std::max(tolerance, s.energy_allowance * excess_decay);
  report->checks_ns += NowNs() - t0;

  bool accepted = false;
  for (int32_t k = 0; k < num_plans && !accepted; ++k) {
    if (k > 0) {
      t0 = NowNs();
      Restore(s, ws, clock);
      ++s.warnings.rollback;
      report->checks_ns += NowNs() - t0;
    }
    IDMS_CHECK(plans[k].integrator != Integrator::kRk4 || ws.use_rk4);
    report->cg_iterations = RunIntegrator(m, s, ws, plans[k].integrator, plans[k].substeps, times);
    t0 = NowNs();
    if (st.energy_check) {
      report->energy_after = ActiveEnergy(m, s, ws).h;
      const double gain = report->energy_after - before.h;
      excess = std::max(0.0, s.energy_excess * excess_decay + gain);
      accepted = gain <= tolerance && excess <= allowance;  // false for NaN
    } else {
      accepted = ActiveFinite(s, ws);
    }
    report->attempts = k + 1;
    report->substeps = plans[k].substeps;
    report->integrator_used = plans[k].integrator;
    report->fallback = plans[k].fallback;
    report->checks_ns += NowNs() - t0;
  }
  t0 = NowNs();
  s.energy_excess = accepted && std::isfinite(excess) ? excess : s.energy_excess * excess_decay;
  if (std::isfinite(allowance)) s.energy_allowance = allowance;
  if (!accepted) {
    Freeze(s, ws, clock);
    report->unrecovered = true;
    report->fallback = false;
    if (st.energy_check) report->energy_after = ActiveEnergy(m, s, ws).h;
  }
  report->energy_before = before.h;
  report->checks_ns += NowNs() - t0;
}

// Stages 3-4 through full mode's fused pass: the plan's first attempt, when it is the configured
// explicit scheme, with the rollback copy written on the way and, when the energy check is on,
// the energies formed on the way too and checked as GeneralTick checks them. False = not taken,
// stopped at a non-finite value, or the check failed, with the State restored: the caller then
// runs GeneralTick, so this undoes what GeneralTick does again (tool stiffness, contacts, a
// substep-limit warning), and a failed check is met again there, rolled back, retried and
// counted as the general path does.
bool FusedTick(const Model& m, State& s, Workspace& ws, StepReport* report, internal::StageTimes* times) {
  using namespace internal;
  int64_t t0 = NowNs();
  ToolStiffness(s, ws, report);
  const int64_t substep_limit = s.warnings.substep_limit;
  Plan plans[3];
  MakePlans(m, s, ws, report, plans);
  const StabilityOptions& st = ws.options.stability;
  const int64_t clock = s.substep_clock, stamp_floor = s.elem_stamp_floor;
  // The tools' and gravity's energies at the tick's start (tools at their new pose); the pass
  // forms the kinetic and elastic ones.
  Energy before, after;
  if (st.energy_check) ToolAndGravityEnergy(m, s, ws, &before);
  report->checks_ns += NowNs() - t0;
  const Plan& plan = plans[0];
  FusedEnergy fe;
  bool accepted = plan.integrator == ws.options.integrator &&
                  RunFused(m, s, ws, plan.integrator, plan.substeps, times, st.energy_check ? &fe : nullptr);
  t0 = NowNs();
  const double decay = std::exp(-ws.options.dt_s / st.energy_memory_s);
  double excess = s.energy_excess * decay, allowance = std::max(st.energy_abs_tol, s.energy_allowance * decay);
  if (accepted && st.energy_check) {
    // GeneralTick's test on the same terms.
    before.h += fe.kinetic_before + fe.elastic_before;
    before.scale += fe.kinetic_before + fe.elastic_before;
    before.noise += fe.noise_before;
    ToolAndGravityEnergy(m, s, ws, &after);
    after.h += fe.kinetic_after + fe.elastic_after;
    const double tolerance = st.energy_rel_tol * before.scale + st.energy_abs_tol + 4 * before.noise;
    const double gain = after.h - before.h;
    allowance = std::max(tolerance, s.energy_allowance * decay);
    excess = std::max(0.0, s.energy_excess * decay + gain);
    accepted = gain <= tolerance && excess <= allowance;  // false for NaN
    if (!accepted) UndoFused(s, ws, clock, stamp_floor);
  }
  if (accepted) {
    s.energy_excess = std::isfinite(excess) ? excess : s.energy_excess * decay;
    if (std::isfinite(allowance)) s.energy_allowance = allowance;
    report->energy_before = before.h;
    report->energy_after = after.h;
    report->attempts = 1;
    report->substeps = plan.substeps;
    report->integrator_used = plan.integrator;
    report->fused = true;
    report->checks_ns += NowNs() - t0;
    return true;
  }
  ClearExtraK(ws);
  for (ToolReport& tr : report->tools) tr.contacts = 0;
  s.warnings.substep_limit = substep_limit;
  report->predicted_dt_s = 0;
  report->checks_ns += NowNs() - t0;
  return false;
}

}  // namespace

StepReport Step(const Model& m, State& s, Workspace& ws, const ToolInput& input) {
  using namespace internal;
  StepReport report;
  const int64_t t_start = NowNs();
  IDMS_CHECK(ws.num_atoms == m.num_atoms && ws.topology_version == m.topology_version);
  IDMS_CHECK(static_cast<int32_t>(s.atom_pos.size()) == 3 * m.num_atoms &&
             static_cast<int32_t>(s.elem_len.size()) == m.num_elems);
  const int64_t warnings_before = TotalWarnings(s.warnings);
  if (s.tick != ws.synced_tick) {
    if (ws.synced_tick >= 0) ++s.warnings.workspace_resync;
    ResyncWorkspace(m, s, ws);
  }

  // 1. Tools: validated input, scalpel sweeps -> pending cuts.
  int64_t t0 = NowNs();
  ResolveTools(m, s, ws, input, &report);
  report.tools_ns = NowNs() - t0;

  // 2. Active set (haptic window), then the tweezers, which need its contact candidates. Full
  // mode's fused pass keeps its lists from tick to tick; every other tick builds them, after
  // folding the fused pass's element stamp back into the State.
  t0 = NowNs();
  bool fused = FusedEligible(m, ws);
  if (fused) {
    EnsureFullLive(m, s, ws);
  } else {
    EndFullLive(ws);
    FoldStampFloor(m, s);
    BuildActiveSet(m, s, ws);
  }
  report.active_set_ns = NowNs() - t0;
  t0 = NowNs();
  UpdateGrasps(m, s, ws, &report);
  report.tools_ns += NowNs() - t0;

  // 3-4. Plan, integrate, check, roll back and retry: fused when it can, else (or when the
  // fused attempt met a non-finite value) the general path.
  StageTimes times;
  if (fused && !FusedTick(m, s, ws, &report, &times)) {
    fused = false;
    FoldStampFloor(m, s);
  }
  if (!fused) GeneralTick(m, s, ws, &report, &times);
  if (report.fallback) ++s.warnings.implicit_fallback;
  report.forces_ns = times.forces_ns;
  report.integrate_ns = times.integrate_ns;

  // 5. Device force.
  t0 = NowNs();
  DeviceForces(s, ws, &report);
  report.checks_ns += NowNs() - t0;

  // Refile the atoms that moved (local mode: nothing else can have moved).
  t0 = NowNs();
  if (!ws.options.full) {
    for (int32_t i = 0; i < ws.num_active; ++i) UpdateSpatialHash(ws.hash, ws.active[i], &s.atom_pos[3 * ws.active[i]]);
  }
  WakeNeighbours(m, s, ws);
  report.active_atoms = ws.num_active;
  report.active_elems = ws.num_elems;
  report.pending_cuts = ws.num_pending_cuts;
  if (fused) {
    ClearExtraK(ws);  // the lists stay live for the next tick
  } else {
    EndFullLive(ws);
    ClearTickScratch(ws);
  }
  report.active_set_ns += NowNs() - t0;

  ++s.tick;
  s.time_s += ws.options.dt_s;
  ws.synced_tick = s.tick;
  report.new_warnings = TotalWarnings(s.warnings) - warnings_before;
  report.total_ns = NowNs() - t_start;
  return report;
}

}  // namespace idms
