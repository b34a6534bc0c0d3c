// Draping (thesis 5.6.1): stage 1 places a slab above a sphere, stage 2 runs the full DSM step
// with the form's attraction/contact forces as external forces until equilibrium, stage 3 takes
// the equilibrium as the new rest shape and adds home elements.
#include "idms/sim/drape.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>
#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "idms/sim/check.h"
#include "idms/sim/integrate.h"
#include "idms/sim/reorder.h"
#include "idms/sim/stability.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms {
namespace {

double RoundTo(double v, int decimals) {
  if (decimals < 0) return v;
  const double scale = std::pow(10.0, decimals);
  const double rounded = std::round(v * scale) / scale;
  return rounded == 0.0 ? 0.0 : rounded;  // no negative zero in files
}

bool HasHomeElements(const Model& m) {
  return std::any_of(m.elem_home.begin(), m.elem_home.end(), [](uint8_t h) { return h != 0; });
}

// Kinetic energy, fastest atom and form potential of a state; the form's forces at the same
// state (thesis 5.6.1) land in `force` (num_atoms x 3, zero on fixed atoms).
struct StageTwoState {
  double kinetic = 0, max_speed = 0, form = 0;
};

// AddSphereFormForce's body for d = p - c at distance r = |d| (inv_r = 1 / r), inline in FormPass
// (a call per atom was a tenth of a 10^6-atom drape's tick).
[[gnu::always_inline]] inline double FormForceAt(const SphereForm& form, const double d[3], double r, double inv_r,
                                                 const Real v[3], Real f[3]) {
  double dir[3] = {0, 0, 1};  // at the centre itself any direction is "out"
  if (r > 0) dir[0] = d[0] * inv_r, dir[1] = d[1] * inv_r, dir[2] = d[2] * inv_r;
  if (r > form.radius) {
    // Outside: attractive force towards the surface, -k_f^o (r - R_f) d^.
    const double mag = -form.k_out * (r - form.radius);
    for (int c = 0; c < 3; ++c) f[c] += static_cast<Real>(mag * dir[c]);
    return 0.5 * form.k_out * (r - form.radius) * (r - form.radius);
  }
  // Inside: contact force k_f^i (R_f - r) d^ - b_f x1'.
  const double mag = form.k_in * (form.radius - r);
  for (int c = 0; c < 3; ++c) f[c] += static_cast<Real>(mag * dir[c] - form.b * v[c]);
  return 0.5 * form.k_in * (form.radius - r) * (form.radius - r);
}

inline void FormOffset(const SphereForm& form, const Real p[3], double d[3]) {
  d[0] = p[0] - form.center[0], d[1] = p[1] - form.center[1], d[2] = p[2] - form.center[2];
}

// r = sqrt(r2) and inv = 1 / r for n values (a multiple of 4), several lanes at a time: a scalar
// square root and division per atom, which share the divider, were a fifth of a 10^5-atom drape's
// tick. Correctly rounded either way, so the same bits as one at a time.
#if defined(__SSE2__)
[[gnu::target("avx2")]] void SqrtInverseAvx2(int32_t n, const double* r2, double* r, double* inv) {
  for (int32_t i = 0; i < n; i += 4) {
    const __m256d s = _mm256_sqrt_pd(_mm256_loadu_pd(r2 + i));
    _mm256_storeu_pd(r + i, s);
    _mm256_storeu_pd(inv + i, _mm256_div_pd(_mm256_set1_pd(1.0), s));
  }
}
void SqrtInverse(int32_t n, const double* r2, double* r, double* inv) {
  if (internal::UseAvx2(true)) return SqrtInverseAvx2(n, r2, r, inv);
  for (int32_t i = 0; i < n; i += 2) {
    const __m128d s = _mm_sqrt_pd(_mm_loadu_pd(r2 + i));
    _mm_storeu_pd(r + i, s);
    _mm_storeu_pd(inv + i, _mm_div_pd(_mm_set1_pd(1.0), s));
  }
}
#else
void SqrtInverse(int32_t n, const double* r2, double* r, double* inv) {
  for (int32_t i = 0; i < n; ++i) r[i] = std::sqrt(r2[i]), inv[i] = 1 / r[i];
}
#endif

// Atoms per block of the form pass: their r^2, r and 1 / r stay in L1.
constexpr int32_t kFormBlock = 64;

StageTwoState FormPass(const Model& m, const SphereForm& form, const State& s, std::vector<Real>* force) {
  // Sums in locals: a member of `out` may alias the forces stored in the loop, so the compiler
  // kept it in memory, a store and a reload per atom on the sum's critical path.
  double kinetic = 0, form_energy = 0, max_speed2 = 0;
  alignas(32) double r2[kFormBlock], r[kFormBlock], inv_r[kFormBlock];
  for (int32_t a0 = 0; a0 < m.num_atoms; a0 += kFormBlock) {
    const int32_t n = std::min(kFormBlock, m.num_atoms - a0);
    for (int32_t j = 0; j < n; ++j) {
      double d[3];
      FormOffset(form, &s.atom_pos[3 * (a0 + j)], d);
      r2[j] = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    }
    for (int32_t j = n; j % 4 != 0; ++j) r2[j] = 1;
    SqrtInverse((n + 3) / 4 * 4, r2, r, inv_r);
    for (int32_t j = 0; j < n; ++j) {
      const int32_t a = a0 + j;
      Real* f = &(*force)[3 * a];
      f[0] = f[1] = f[2] = 0;
      if (m.atom_fixed[a]) continue;
      const Real* v = &s.atom_vel[3 * a];
      const double speed2 = double(v[0]) * v[0] + double(v[1]) * v[1] + double(v[2]) * v[2];
      kinetic += 0.5 * m.atom_mass[a] * speed2;
      max_speed2 = std::max(max_speed2, speed2);
      double d[3];
      FormOffset(form, &s.atom_pos[3 * a], d);
      form_energy += FormForceAt(form, d, r[j], inv_r[j], v, f);
    }
  }
  StageTwoState out;
  out.kinetic = kinetic;
  out.form = form_energy;
  out.max_speed = std::sqrt(max_speed2);
  return out;
}

// Stage 1 (thesis 5.6.1): the slab's bounding-box centre over the form's centre, its lowest atom
// `gap` above the sphere's top, at rest, with the eq. 4.6 filters restarted there.
void PlaceAboveForm(const Model& m, const SphereForm& form, double gap, State& s) {
  double lo[3], hi[3];
  for (int c = 0; c < 3; ++c) lo[c] = std::numeric_limits<double>::infinity(), hi[c] = -lo[c];
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], m.atom_pos_eq[3 * a + c]);
      hi[c] = std::max(hi[c], m.atom_pos_eq[3 * a + c]);
    }
  }
  const double offset[3] = {form.center[0] - 0.5 * (lo[0] + hi[0]), form.center[1] - 0.5 * (lo[1] + hi[1]),
                            form.center[2] + form.radius + gap - lo[2]};
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    for (int c = 0; c < 3; ++c) s.atom_pos[3 * a + c] = static_cast<Real>(m.atom_pos_eq[3 * a + c] + offset[c]);
  }
  SyncFilterToPositions(m, s);
}

// Triangles whose normal (b - a) x (c - a) points towards the form centre.
int32_t CountFolded(const Model& m, const SphereForm& form, const State& s) {
  int32_t folded = 0;
  for (int32_t t = 0; t < m.num_tris; ++t) {
    const Real* a = &s.atom_pos[3 * m.tri_atoms[3 * t]];
    const Real* b = &s.atom_pos[3 * m.tri_atoms[3 * t + 1]];
    const Real* c = &s.atom_pos[3 * m.tri_atoms[3 * t + 2]];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    double out = 0;
    for (int k = 0; k < 3; ++k) out += n[k] * ((a[k] + b[k] + c[k]) / 3 - form.center[k]);
    folded += out <= 0;
  }
  return folded;
}

// How the layers lie on the form: distance ranges from its surface, and folded triangles.
void MeasureLayers(const Model& m, const SphereForm& form, const State& s, DrapeResult* result) {
  double ext[2] = {std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
  double in[2] = {ext[0], ext[1]};
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    if (m.atom_fixed[a]) continue;
    const Real* p = &s.atom_pos[3 * a];
    const double d[3] = {p[0] - form.center[0], p[1] - form.center[1], p[2] - form.center[2]};
    const double gap = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) - form.radius;
    double* range = m.atom_external[a] ? ext : in;
    range[0] = std::min(range[0], gap), range[1] = std::max(range[1], gap);
  }
  result->external_min = ext[0], result->external_max = ext[1];
  result->internal_min = in[0], result->internal_max = in[1];
  result->folded_triangles = CountFolded(m, form, s);
}

}  // namespace

double AddSphereFormForce(const SphereForm& form, const Real p[3], const Real v[3], Real f[3]) {
  double d[3];
  FormOffset(form, p, d);
  const double r = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  return FormForceAt(form, d, r, 1 / r, v, f);
}

double DrapeStableDt(const Model& slab, const SphereForm& form, const StepOptions& step) {
  const bool euler = step.integrator == Integrator::kExplicitEuler || step.integrator == Integrator::kSymplecticEuler;
  const LengthRate rate =
      euler && step.length_rate != LengthRate::kAnalytic ? LengthRate::kFiltered : LengthRate::kAnalytic;
  const double form_k = std::max(form.k_in, form.k_out);
  double dt = std::numeric_limits<double>::infinity();
  for (int32_t a = 0; a < slab.num_atoms; ++a) {
    if (slab.atom_fixed[a]) continue;
    const double m = slab.atom_mass[a];
    if (step.integrator == Integrator::kImplicitEuler) {
      dt = std::min(dt, SymplecticStableDt({form_k / m, form.b / m}));
      continue;
    }
    AtomBound bound = GershgorinBound(slab, a, form_k, form.b);
    bound.c += step.air_damping;
    dt = std::min(dt, StableDt(step.integrator, bound, rate, step.lambda));
  }
  return dt;
}

Model StripHomeElements(const Model& model) {
  // Atoms to drop: fixed endpoints of home elements that no other element uses.
  std::vector<int32_t> other_uses(model.num_atoms, 0);
  for (int32_t e = 0; e < model.num_elems; ++e) {
    if (model.elem_home[e]) continue;
    ++other_uses[model.elem_atoms[2 * e]];
    ++other_uses[model.elem_atoms[2 * e + 1]];
  }
  std::vector<uint8_t> drop(model.num_atoms, 0);
  for (int32_t e = 0; e < model.num_elems; ++e) {
    if (!model.elem_home[e]) continue;
    for (int c = 0; c < 2; ++c) {
      const int32_t a = model.elem_atoms[2 * e + c];
      if (model.atom_fixed[a] && other_uses[a] == 0) drop[a] = 1;
    }
  }
  // Kept atoms in order, then elements and triangles through the new ids.
  Model out;
  out.name = model.name;
  std::vector<int32_t> new_id(model.num_atoms, -1);
  for (int32_t a = 0; a < model.num_atoms; ++a) {
    if (drop[a]) continue;
    new_id[a] = static_cast<int32_t>(out.atom_mass.size());
    out.atom_pos_eq.insert(out.atom_pos_eq.end(), &model.atom_pos_eq[3 * a], &model.atom_pos_eq[3 * a] + 3);
    out.atom_mass.push_back(model.atom_mass[a]);
    out.atom_fixed.push_back(model.atom_fixed[a]);
    out.atom_external.push_back(model.atom_external[a]);
  }
  for (int32_t e = 0; e < model.num_elems; ++e) {
    if (model.elem_home[e]) continue;
    out.elem_atoms.push_back(new_id[model.elem_atoms[2 * e]]);
    out.elem_atoms.push_back(new_id[model.elem_atoms[2 * e + 1]]);
    out.elem_k.push_back(model.elem_k[e]);
    out.elem_b.push_back(model.elem_b[e]);
  }
  for (int32_t id : model.tri_atoms) {
    IDMS_CHECK(new_id[id] >= 0);  // triangles join external atoms, which are never dropped
    out.tri_atoms.push_back(new_id[id]);
  }
  FinalizeModel(out);
  return out;
}

Model HardenDrape(const Model& slab, const State& state, double home_k, double home_b, int decimals,
                  const std::string& name) {
  IDMS_CHECK(static_cast<int32_t>(state.atom_pos.size()) == 3 * slab.num_atoms);
  Model out = slab;
  out.name = name;
  out.topology_version = 0;
  // p_eq = p for every atom (thesis 5.6.1, stage 3).
  for (int32_t i = 0; i < 3 * slab.num_atoms; ++i) out.atom_pos_eq[i] = RoundTo(state.atom_pos[i], decimals);
  // A fixed home atom at each external atom's new rest position, tied by a zero-length element.
  for (int32_t a : slab.external_atoms) {
    const int32_t home = static_cast<int32_t>(out.atom_mass.size());
    out.atom_pos_eq.insert(out.atom_pos_eq.end(),
                           {out.atom_pos_eq[3 * a], out.atom_pos_eq[3 * a + 1], out.atom_pos_eq[3 * a + 2]});
    out.atom_mass.push_back(slab.atom_mass[a]);
    out.atom_fixed.push_back(1);
    out.atom_external.push_back(0);
    out.elem_atoms.insert(out.elem_atoms.end(), {a, home});
    out.elem_k.push_back(home_k);
    out.elem_b.push_back(home_b);
  }
  FinalizeModel(out);
  return out;
}

DrapeResult Drape(const Model& slab, const DrapeOptions& o, const std::function<void(const DrapeProgress&)>& progress) {
  IDMS_CHECK(o.form.radius > 0 && o.form.k_out >= 0 && o.form.k_in >= 0 && o.form.b >= 0);
  IDMS_CHECK(o.max_time_s > 0 && o.settle_hold_s >= 0 && o.progress_every_s > 0 && o.gap >= 0);
  const Model stripped = HasHomeElements(slab) ? StripHomeElements(slab) : slab;
  IDMS_CHECK(stripped.num_atoms > 0);
  // On several threads the pass needs the model renumbered (reorder.h): stage 2 runs on the
  // renumbered slab, and its end state is mapped back to the slab's numbering for stage 3.
  Reordering order;
  const bool renumber = o.step.threads > 1;
  const Model renumbered = renumber ? ReorderForLocality(stripped, {}, &order) : Model{};
  const Model& m = renumber ? renumbered : stripped;
  StepOptions step = o.step;
  step.full = true;
  IDMS_CHECK(step.dt_s <= DrapeStableDt(m, o.form, step));

  // Stage 1: initial conditions above the form.
  State s = MakeState(m);
  PlaceAboveForm(m, o.form, o.gap, s);
  Workspace ws = MakeWorkspace(m, step);
  ws.atom_force_external.assign(3 * static_cast<size_t>(m.num_atoms), Real(0));
  if (o.huge_pages) AdviseHugePages(s, ws);

  // Stage 2: the DSM with the form's forces until the slab rests (or time runs out).
  DrapeResult result;
  const ToolInput no_tools;
  const int64_t hold_ticks = static_cast<int64_t>(std::ceil(o.settle_hold_s / step.dt_s - 1e-9));
  const int64_t report_ticks = std::max<int64_t>(1, std::llround(o.progress_every_s / step.dt_s));
  const int64_t max_ticks = static_cast<int64_t>(std::ceil(o.max_time_s / step.dt_s - 1e-9));
  int64_t quiet_ticks = 0;
  for (int64_t tick = 0;; ++tick) {
    // External forces at the tick's start; the equilibrium test on the same state.
    const StageTwoState now = FormPass(m, o.form, s, &ws.atom_force_external);
    quiet_ticks = now.kinetic < o.settle_kinetic && now.max_speed < o.settle_speed ? quiet_ticks + 1 : 0;
    const bool settled = quiet_ticks > hold_ticks;
    const bool last = settled || tick >= max_ticks;
    if (tick == 0 || last || tick % report_ticks == 0) {
      DrapeProgress p;
      p.time_s = s.time_s;
      p.tick = tick;
      p.kinetic = now.kinetic;
      p.max_speed = now.max_speed;
      p.energy = now.kinetic + now.form + internal::ElasticEnergy(m, s);
      p.fraction = std::min(1.0, s.time_s / o.max_time_s);
      p.settled = settled;
      if (tick == 0) result.energy_start = p.energy;
      result.energy_max = std::max(result.energy_max, p.energy);
      result.energy_end = p.energy;
      if (progress) progress(p);
    }
    if (last) {
      result.settled = settled;
      result.time_s = s.time_s;
      result.ticks = tick;
      result.kinetic = now.kinetic;
      result.max_speed = now.max_speed;
      break;
    }
    Step(m, s, ws, no_tools);
  }
  result.warnings = TotalWarnings(s.warnings);
  if (renumber) {
    State back = MakeState(stripped);
    for (int32_t a = 0; a < stripped.num_atoms; ++a) {
      const int32_t b = order.atom_new_id[a];
      for (int c = 0; c < 3; ++c) {
        back.atom_pos[3 * a + c] = s.atom_pos[3 * b + c], back.atom_vel[3 * a + c] = s.atom_vel[3 * b + c];
      }
    }
    back.time_s = s.time_s;
    s = std::move(back);
  }
  MeasureLayers(stripped, o.form, s, &result);

  // Stage 3: the equilibrium becomes the rest shape, hardened by home elements.
  result.model = HardenDrape(stripped, s, o.home_k, o.home_b, o.decimals, o.name);
  return result;
}

}  // namespace idms
