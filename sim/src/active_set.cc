// The haptic window (thesis 5.5.2, 7.2.3): which atoms move this tick, which external atoms may
// touch a tool, and which elements need forces — found through the spatial hash, not a scan.
#include <algorithm>
#include <cmath>

#include "idms/sim/model.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms::internal {
namespace {

inline double Dist2(const Real* p, const double* c) {
  const double dx = p[0] - c[0], dy = p[1] - c[1], dz = p[2] - c[2];
  return dx * dx + dy * dy + dz * dz;
}

// Squared distance from atom position p to segment ab.
double SegmentDist2(const Real* p, const double* a, const double* b) {
  const double q[3] = {p[0], p[1], p[2]};
  return internal::SegmentDist2(q, a, b);
}

// An atom is unsettled when it moves faster than settle_speed or its elastic force would still
// move it more than settle_distance (|sum of element forces| > settle_distance * sum of k).
// O(degree); reads positions only, so a fresh Workspace decides the same.
bool Unsettled(const Model& m, const State& s, const Workspace& ws, int32_t a) {
  const Real* v = &s.atom_vel[3 * a];
  const double speed2 = double(v[0]) * v[0] + double(v[1]) * v[1] + double(v[2]) * v[2];
  if (speed2 > ws.options.settle_speed * ws.options.settle_speed) return true;
  double f[3] = {0, 0, 0}, k_sum = 0;
  const Real* pa = &s.atom_pos[3 * a];
  const int32_t adr = m.atom_elem_adr[a];
  for (int32_t j = 0; j < m.atom_elem_num[a]; ++j) {
    const int32_t e = m.atom_elem[adr + j];
    if (ws.elem_cut[e]) continue;
    const int32_t b = m.elem_atoms[2 * e] == a ? m.elem_atoms[2 * e + 1] : m.elem_atoms[2 * e];
    const Real* pb = &s.atom_pos[3 * b];
    const double d[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
    const double l = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    const double scale = l > kMinLength ? m.elem_k[e] * (1 - m.elem_leq[e] / l) : 0.0;
    for (int c = 0; c < 3; ++c) f[c] += scale * d[c];
    k_sum += m.elem_k[e];
  }
  const double limit = ws.options.settle_distance * k_sum;
  return f[0] * f[0] + f[1] * f[1] + f[2] * f[2] > limit * limit;
}

class ActiveSetBuilder {
 public:
  ActiveSetBuilder(const Model& m, State& s, Workspace& ws) : m_(m), s_(s), ws_(ws) {}

  void AddActive(int32_t a, int32_t linger) {
    if (m_.atom_fixed[a]) return;
    s_.atom_linger[a] = std::max(s_.atom_linger[a], linger);
    if (ws_.atom_mark[a]) return;
    ws_.atom_mark[a] = 1;
    ws_.active[ws_.num_active++] = a;
  }

  void AddCandidate(int32_t a) {
    if (!m_.atom_external[a] || ws_.atom_cand[a]) return;
    ws_.atom_cand[a] = 1;
    ws_.candidates[ws_.num_candidates++] = a;
  }

  // Atoms within radius of c; contact tools also collect the external ones as candidates.
  void QuerySphere(const double* c, double radius, bool contact, int32_t linger) {
    const double lo[3] = {c[0] - radius, c[1] - radius, c[2] - radius};
    const double hi[3] = {c[0] + radius, c[1] + radius, c[2] + radius};
    const double r2 = radius * radius;
    ForEachAtomInBox(ws_.hash, lo, hi, [&](int32_t a) {
      if (!(Dist2(&s_.atom_pos[3 * a], c) <= r2)) return;
      AddActive(a, linger);
      if (contact) AddCandidate(a);
    });
  }

  // Atoms within radius of the blade segment ab.
  void QuerySegment(const double* a, const double* b, double radius, int32_t linger) {
    double lo[3], hi[3];
    for (int c = 0; c < 3; ++c) lo[c] = std::min(a[c], b[c]) - radius, hi[c] = std::max(a[c], b[c]) + radius;
    const double r2 = radius * radius;
    ForEachAtomInBox(ws_.hash, lo, hi, [&](int32_t i) {
      if (SegmentDist2(&s_.atom_pos[3 * i], a, b) <= r2) AddActive(i, linger);
    });
  }

 private:
  const Model& m_;
  State& s_;
  Workspace& ws_;
};

}  // namespace

void BuildActiveSet(const Model& m, State& s, Workspace& ws) {
  ws.num_active = ws.num_candidates = ws.num_elems = 0;
  ActiveSetBuilder b(m, s, ws);
  if (ws.options.full) {
    // Full mode: every free atom moves, every external atom may touch.
    for (int32_t a = 0; a < m.num_atoms; ++a) b.AddActive(a, 0), b.AddCandidate(a);
  } else {
    // Window atoms: within r_l of each tool (at least its radius) and of each grasped atom.
    const int32_t linger = static_cast<int32_t>(std::ceil(ws.options.settle_time_s / ws.options.dt_s - 1e-9));
    for (int32_t t = 0; t < ws.num_tools; ++t) {
      const ActiveTool& at = ws.tools[t];
      if (at.kind == ToolKind::kNone) continue;
      if (at.kind == ToolKind::kScalpel) {
        b.QuerySegment(at.pos, at.blade_tip, ws.local_radius, linger);
        continue;
      }
      b.QuerySphere(at.pos, std::max(ws.local_radius, at.radius), /*contact=*/true, linger);
      if (at.kind == ToolKind::kNeedle && at.shaft_len > 0) {
        // A needle inside: the tissue along its inserted shaft moves too.
        double tail[3];
        NeedleShaft(at, tail);
        b.QuerySegment(tail, at.pos, std::max(ws.local_radius, at.needle.capture_radius), linger);
      }
      if (at.grasp_atom >= 0) {
        double g[3];
        for (int c = 0; c < 3; ++c) g[c] = s.atom_pos[3 * at.grasp_atom + c];
        b.QuerySphere(g, ws.local_radius, /*contact=*/false, linger);
        b.AddActive(at.grasp_atom, linger);
      }
    }
    // The suture's punctures pull on the tissue around them wherever the tools are.
    const SutureState& ss = s.suture;
    for (int32_t j = 0; ss.num_nodes > 0 && j < ss.num_punctures; ++j) {
      const SuturePuncture& pu = ss.punctures[j];
      double p[3];
      if (!AnchorPoint(s, pu.atoms, pu.w, p)) continue;
      b.QuerySphere(p, ws.local_radius, /*contact=*/false, linger);
      for (int i = 0; i < kAnchorAtoms && pu.atoms[i] >= 0; ++i) b.AddActive(pu.atoms[i], linger);
    }
    // Atoms that left the window (or were woken) keep moving while they are unsettled; then
    // they are immobilised.
    for (int32_t i = 0; i < s.num_active; ++i) {
      const int32_t a = s.active_atoms[i];
      if (ws.atom_mark[a]) continue;
      if (s.atom_linger[a] > 0 && Unsettled(m, s, ws, a)) {
        --s.atom_linger[a];
        ws.atom_mark[a] = 1;
        ws.active[ws.num_active++] = a;
      } else {
        s.atom_linger[a] = 0;
        s.atom_vel[3 * a] = s.atom_vel[3 * a + 1] = s.atom_vel[3 * a + 2] = 0;
      }
    }
    // Id order: the lists do not depend on the hash's chain order, so a resynced workspace (or a
    // restored snapshot) steps to the same bits, and memory is walked forwards.
    std::sort(ws.active.begin(), ws.active.begin() + ws.num_active);
    std::sort(ws.candidates.begin(), ws.candidates.begin() + ws.num_candidates);
  }

  // Active elements: an active endpoint and not awaiting a cut (thesis 5.5.2, block 2).
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    ws.atom_slot[a] = i;
    const int32_t adr = m.atom_elem_adr[a];
    for (int32_t j = 0; j < m.atom_elem_num[a]; ++j) {
      const int32_t e = m.atom_elem[adr + j];
      if (ws.elem_mark[e] || ws.elem_cut[e]) continue;
      ws.elem_mark[e] = 1;
      ws.elems[ws.num_elems++] = e;
    }
  }

  // Eq. 4.6 restart marks on the elements that leave the list (an endpoint among last tick's
  // atoms, none among this tick's) or wait for a cut: they are not updated from now on, so their
  // filters cannot continue when they come back. What last tick listed is found from State alone,
  // so a fresh or resynced Workspace marks the same elements.
  if (m.has_damping) {
    for (int32_t i = 0; i < s.num_active; ++i) {
      const int32_t a = s.active_atoms[i];
      if (ws.atom_mark[a]) continue;
      const int32_t adr = m.atom_elem_adr[a];
      for (int32_t j = 0; j < m.atom_elem_num[a]; ++j) {
        const int32_t e = m.atom_elem[adr + j];
        if (!ws.elem_mark[e]) s.elem_len[e] = kFilterRestart;
      }
    }
    for (int32_t i = 0; i < ws.num_pending_cuts; ++i) s.elem_len[ws.pending_cuts[i]] = kFilterRestart;
  }

  // The list handed to the next tick.
  std::copy(ws.active.begin(), ws.active.begin() + ws.num_active, s.active_atoms.begin());
  s.num_active = ws.num_active;
}

void WakeNeighbours(const Model& m, State& s, Workspace& ws) {
  if (ws.options.full || !ws.options.wake_neighbours || ws.options.settle_time_s <= 0) return;
  const int32_t linger = static_cast<int32_t>(std::ceil(ws.options.settle_time_s / ws.options.dt_s - 1e-9));
  // Free inactive endpoints of active elements, each checked once (mark 2 = checked).
  for (int32_t i = 0; i < ws.num_elems; ++i) {
    const int32_t e = ws.elems[i];
    for (int c = 0; c < 2; ++c) {
      const int32_t b = m.elem_atoms[2 * e + c];
      if (ws.atom_mark[b] || m.atom_fixed[b]) continue;
      ws.atom_mark[b] = 2;
      ws.boundary[ws.num_boundary++] = b;
      if (!Unsettled(m, s, ws, b)) continue;
      // Listed with last tick's atoms, it is considered (and kept while unsettled) next tick.
      s.atom_linger[b] = linger;
      s.active_atoms[s.num_active++] = b;
    }
  }
}

void ClearTickScratch(Workspace& ws) {
  for (int32_t i = 0; i < ws.num_boundary; ++i) ws.atom_mark[ws.boundary[i]] = 0;
  ws.num_boundary = 0;
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    ws.atom_mark[a] = 0;
    ws.atom_slot[a] = -1;
    ws.atom_extra_k[a] = 0;
  }
  for (int32_t i = 0; i < ws.num_candidates; ++i) {
    ws.atom_cand[ws.candidates[i]] = 0;
    ws.atom_extra_k[ws.candidates[i]] = 0;
  }
  for (int32_t i = 0; i < ws.num_elems; ++i) ws.elem_mark[ws.elems[i]] = 0;
  ws.num_active = ws.num_candidates = ws.num_elems = 0;
}

}  // namespace idms::internal
