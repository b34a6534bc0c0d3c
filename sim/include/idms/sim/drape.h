// Model generation by draping (thesis 5.6.1): a slab is drawn onto a rigid sphere by the
// thesis's attraction/contact law, run to equilibrium with the full DSM step, then hardened with
// home elements into a new model (thesis figures 5-10 and 6-9).
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "idms/sim/model.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"

namespace idms {

// The parametric rigid form of stage 2: a sphere with the thesis's three material parameters,
// which it leaves to experiment. Defaults found on thesis-material slabs (k = 15, b = 0.2,
// m = 0.002): k_out = 0.75 bends a 21x20 slab onto R_f = 12 in ~5 s of simulated time, squeezes
// the layers by ~6% and reaches the same equilibrium with every integrator; k_out = 1 sometimes
// and k_out = 2 always folds the rim over (the outer layer, unsupported at the edge, is pulled
// down onto the form), and k_out = 0.5 leaves the lower layer lifting off near the edges;
// k_in = 100 lets the lower layer sink ~0.01 in; b = 0.5 is about critical for one atom on k_in
// ("highly inelastic", 5.6.1). The slab must also be able to take the sphere's curvature: a flat
// sheet wrapped to a geodesic radius s must shrink its rim by 1 - sin(s/R_f) / (s/R_f) (19% at
// the corners of the 21x20 slab on R_f = 12, 45% for a 20x20 slab on R_f = 8, which wrinkles).
struct SphereForm {
  double center[3] = {0, 0, 0};  // c, model units
  double radius = 12;            // R_f, model units
  double k_out = 0.75;           // k_f^o: attraction outside the surface, force / length
  double k_in = 100;             // k_f^i: surface stiffness inside, force / length
  double b = 0.5;                // b_f: viscosity inside, force / (length / s)
};

// The thesis's stage 2 force on one atom at position p with velocity v (5.6.1, as written):
//   r > R_f:  f = -k_f^o (r - R_f) d^            (attraction towards the surface)
//   r <= R_f: f =  k_f^i (R_f - r) d^ - b_f v    (contact: pushed out, damped)
// with d = p - c, d^ = d / |d| (+z at the centre). Adds to f[3]; returns the form's potential
// energy at p (1/2 k (r - R_f)^2 with the k of the side p is on). Does not allocate.
double AddSphereFormForce(const SphereForm& form, const Real p[3], const Real v[3], Real f[3]);

// The stage 2 step: full DSM, symplectic Euler (the attraction is undamped outside the form,
// which the thesis's explicit Euler amplifies a little every tick while the slab falls), and no
// energy check (the form does work the check cannot see).
inline StepOptions DefaultDrapeStepOptions() {
  StepOptions o;
  o.full = true;
  o.integrator = Integrator::kSymplecticEuler;
  o.dt_s = 5e-4;
  o.stability.energy_check = false;
  return o;
}

struct DrapeOptions {
  SphereForm form;
  // Stage 1: the slab is moved (its State, not its rest shape) so that its bounding-box centre is
  // over the form's centre and its lowest atom `gap` above the sphere's top. The slab's top
  // surface (its external atoms) faces away from the form, as in figure 6-9.
  double gap = 0.25;  // model units
  // Stage 2: the full DSM step (local simulation is forced off). The form forces are computed at
  // each tick's start and held over its substeps, so dt must be short against the form's
  // stiffness as well as the elements': dt <= DrapeStableDt (IDMS_CHECK).
  StepOptions step = DefaultDrapeStepOptions();
  double max_time_s = 20;  // simulated seconds before giving up on equilibrium
  // Equilibrium: total kinetic energy below settle_kinetic and every atom slower than
  // settle_speed, continuously for settle_hold_s (a single tick can pass through an
  // oscillation's turning point with almost no kinetic energy).
  double settle_kinetic = 1e-6;  // energy units
  double settle_speed = 1e-3;    // model units / s
  double settle_hold_s = 0.1;
  double progress_every_s = 0.05;  // simulated seconds between progress reports
  // Ask for huge pages for the step's arrays (AdviseHugePages: one system call per array, for
  // large slabs; `idms-sim drape` asks).
  bool huge_pages = false;
  // Stage 3.
  double home_k = 15.0;  // stiffness of the added home elements
  double home_b = 0.2;   // viscosity of the added home elements
  // Rest positions are rounded to this many decimals (as the slab generator's are) so that a
  // re-run writes the same bytes unless a coordinate lands within rounding of a boundary; rest
  // lengths are derived from the rounded positions, so the saved model is at rest. -1 = none.
  int decimals = 4;
  std::string name = "drape";
};

struct DrapeProgress {
  double time_s = 0;  // simulated
  int64_t tick = 0;
  double kinetic = 0;    // total kinetic energy, energy units
  double max_speed = 0;  // fastest atom, model units / s
  double energy = 0;     // kinetic + elastic + form potential: what damping drains
  double fraction = 0;   // time_s / max_time_s
  bool settled = false;  // the equilibrium criteria hold (for settle_hold_s)
};

struct DrapeResult {
  Model model;           // stage 3: the hardened draped model (FinalizeModel called)
  bool settled = false;  // equilibrium reached before max_time_s
  double time_s = 0;     // simulated time of stage 2
  int64_t ticks = 0;
  double kinetic = 0, max_speed = 0;        // at the end of stage 2
  double energy_start = 0, energy_end = 0;  // DrapeProgress::energy at the start and end
  double energy_max = 0;                    // the largest energy seen (= start unless it grew)
  // Distances from the form centre at the end of stage 2, minus R_f: how the layers lie on it.
  double external_min = 0, external_max = 0;  // external atoms (the outer surface)
  double internal_min = 0, internal_max = 0;  // internal free atoms (the lower layer)
  // Surface triangles whose outward normal (counter-clockwise winding) points towards the form
  // centre at the end of stage 2: the slab folded or wrinkled there. 0 in a clean drape.
  int32_t folded_triangles = 0;
  int64_t warnings = 0;  // the step's counted warnings (0 in a clean drape)
};

// Largest tick for which `integrator` is predicted stable on `slab` (home elements stripped)
// with the form's stiffness and viscosity added to every atom's Gershgorin row (integrate.h
// StableDt; the form's side with the larger k). Implicit Euler holds the form forces explicitly,
// so it gets symplectic Euler's bound on the form alone. Does not allocate.
double DrapeStableDt(const Model& slab, const SphereForm& form, const StepOptions& step);

// Stage 1 helper: the model without its home elements and without the fixed atoms that only
// home elements used, for a slab generated with them (GenerateSlab always adds them). Other
// fixed atoms, elements and the surface are kept; atom order is kept. Allocates.
Model StripHomeElements(const Model& model);

// Stage 3 (thesis 5.6.1): p_eq = p for every atom of `slab`; for every external atom a fixed
// home atom at its new rest position (appended after the slab's atoms, in external order) and a
// zero-length home element (home_k, home_b); the surface triangles are kept. Rest positions are
// rounded to `decimals` (-1 = none). FinalizeModel is called. Allocates.
Model HardenDrape(const Model& slab, const State& state, double home_k, double home_b, int decimals,
                  const std::string& name);

// Stages 1-3 on `slab` (home elements are stripped first, if it has any): places it above the
// form, runs the full DSM with the form forces until equilibrium or max_time_s, and hardens the
// result. `progress`, if set, is called every progress_every_s of simulated time and at the end.
// Not real time: O(atoms + elements) per tick, allocates at start-up only.
DrapeResult Drape(const Model& slab, const DrapeOptions& options,
                  const std::function<void(const DrapeProgress&)>& progress = {});

}  // namespace idms
