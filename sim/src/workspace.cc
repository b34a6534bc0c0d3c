// MakeWorkspace sizes the step's scratch once; ResyncWorkspace refiles it from a State.
#include "idms/sim/workspace.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "idms/sim/check.h"
#include "idms/sim/model.h"
#include "idms/sim/stability.h"
#include "step_internal.h"

namespace idms {
namespace {

void CheckOptions(const StepOptions& o) {
  IDMS_CHECK(o.dt_s > 0 && std::isfinite(o.dt_s));
  IDMS_CHECK(o.lambda > 0 && o.lambda <= 1);
  IDMS_CHECK(o.full || (o.local_radius > 0 && std::isfinite(o.local_radius)));
  IDMS_CHECK(o.settle_time_s >= 0 && o.settle_speed >= 0 && o.settle_distance >= 0 && o.hash_cell >= 0);
  IDMS_CHECK(o.air_damping >= 0 && o.min_distance_fraction > 0 && o.min_distance_fraction < 1);
  IDMS_CHECK(o.max_device_force >= 0 && o.max_device_force_rate >= 0 && o.transition_force_rate > 0 &&
             o.transition_window_s >= 0);
  IDMS_CHECK(o.stability.safety > 0 && o.stability.max_substeps >= 1 && o.stability.max_substeps <= 1 << 16);
  IDMS_CHECK(o.stability.energy_rel_tol >= 0 && o.stability.energy_abs_tol >= 0 && o.stability.energy_memory_s > 0);
  IDMS_CHECK(o.stability.cg_max_iterations >= 1 && o.stability.cg_tolerance > 0);
}

// Triangles per atom in CSR form, for the Edit API.
void BuildAtomTriangles(const Model& m, Workspace& ws) {
  ws.atom_tri_num.assign(m.num_atoms, 0);
  for (int32_t id : m.tri_atoms) ++ws.atom_tri_num[id];
  ws.atom_tri_adr.resize(m.num_atoms);
  int32_t adr = 0;
  for (int32_t i = 0; i < m.num_atoms; ++i) ws.atom_tri_adr[i] = adr, adr += ws.atom_tri_num[i];
  ws.atom_tri.resize(adr);
  std::vector<int32_t> fill(ws.atom_tri_adr);
  for (int32_t t = 0; t < m.num_tris; ++t) {
    for (int c = 0; c < 3; ++c) ws.atom_tri[fill[m.tri_atoms[3 * t + c]]++] = t;
  }
}

}  // namespace

Workspace MakeWorkspace(const Model& m, const StepOptions& options) {
  CheckOptions(options);
  IDMS_CHECK(static_cast<int32_t>(m.atom_mass.size()) == m.num_atoms &&
             m.num_elems == static_cast<int32_t>(m.elem_k.size()));
  Workspace ws;
  ws.options = options;
  ws.num_atoms = m.num_atoms;
  ws.topology_version = m.topology_version;
  const size_t na = static_cast<size_t>(m.num_atoms), ne = static_cast<size_t>(m.num_elems);

  IDMS_CHECK(static_cast<int32_t>(m.atom_omega2.size()) == m.num_atoms);  // FinalizeModel ran
  for (int32_t a = 0; a < m.num_atoms; ++a) IDMS_CHECK(m.atom_fixed[a] || m.atom_mass[a] > 0);

  // Local simulation: the hash files every atom (fixed ones too: they can touch a tool).
  if (!options.full) {
    ws.local_radius = options.local_radius;
    const double cell = options.hash_cell > 0 ? options.hash_cell : options.local_radius;
    std::vector<Real> rest(m.atom_pos_eq.begin(), m.atom_pos_eq.end());
    BuildSpatialHash(cell, rest.data(), m.num_atoms, &ws.hash);
  }

  // Per-atom and per-element scratch, at full size so no tick ever grows them.
  ws.atom_mark.assign(na, 0);
  ws.atom_cand.assign(na, 0);
  ws.atom_slot.assign(na, -1);
  ws.atom_extra_k.assign(na, 0.0);
  ws.atom_force.assign(3 * na, Real(0));
  ws.active.assign(na, -1);
  ws.candidates.assign(na, -1);
  ws.reach.assign(na, -1);
  ws.boundary.assign(na, -1);
  ws.elems.assign(ne, -1);
  ws.elem_mark.assign(ne, 0);
  ws.elem_cut.assign(ne, 0);
  ws.pending_cuts.assign(ne, -1);
  ws.backup_pos.assign(3 * na, Real(0));
  ws.backup_vel.assign(3 * na, Real(0));
  ws.backup_elem_len.assign(ne, Real(0));
  ws.backup_elem_rate.assign(ne, Real(0));

  // Integrator scratch only where it can be used (implicit also serves as the fallback).
  ws.use_rk4 = options.integrator == Integrator::kRk4;
  ws.use_implicit = options.integrator == Integrator::kImplicitEuler || options.stability.implicit_fallback;
  if (ws.use_rk4) {
    ws.rk_x0.assign(3 * na, Real(0));
    ws.rk_v0.assign(3 * na, Real(0));
    ws.rk_dx.assign(3 * na, Real(0));
    ws.rk_dv.assign(3 * na, Real(0));
  }
  if (ws.use_implicit) internal::SizeImplicitBuffers(m, ws);
  if (options.full) internal::SizeFusedPass(m, ws);

  BuildAtomTriangles(m, ws);
  return ws;
}

void ResyncWorkspace(const Model& m, const State& s, Workspace& ws) {
  IDMS_CHECK(ws.num_atoms == m.num_atoms && static_cast<int32_t>(s.atom_pos.size()) == 3 * m.num_atoms);
  // Refile every atom at its State position (same buckets, no allocation).
  if (!ws.options.full) {
    std::fill(ws.hash.bucket_head.begin(), ws.hash.bucket_head.end(), -1);
    std::fill(ws.hash.atom_key.begin(), ws.hash.atom_key.end(), kHashUnfiled);
    std::fill(ws.hash.atom_next.begin(), ws.hash.atom_next.end(), -1);
    std::fill(ws.hash.atom_prev.begin(), ws.hash.atom_prev.end(), -1);
    for (int32_t a = 0; a < m.num_atoms; ++a) UpdateSpatialHash(ws.hash, a, &s.atom_pos[3 * a]);
  }
  // Per-tick scratch back to its between-steps invariant.
  std::fill(ws.atom_mark.begin(), ws.atom_mark.end(), 0);
  std::fill(ws.atom_cand.begin(), ws.atom_cand.end(), 0);
  std::fill(ws.atom_slot.begin(), ws.atom_slot.end(), -1);
  std::fill(ws.atom_extra_k.begin(), ws.atom_extra_k.end(), 0.0);
  std::fill(ws.elem_mark.begin(), ws.elem_mark.end(), 0);
  ws.num_active = ws.num_candidates = ws.num_elems = ws.num_boundary = ws.num_reach = 0;
  ws.reach_slack = -1;
  internal::ResetFused(ws);
  ws.synced_tick = s.tick;
}

}  // namespace idms
