// Where the thesis's own configuration stops being stable on our fragment (issue 11): for each
// chapter 6 script, the tick T bisected to the measured stability edge of the bare thesis step
// (explicit Euler, eq. 4.6 filter, thesis contact law, r_l 2.25, none of our guards), beside the
// Gershgorin bound and the exact linear analyses, and again with one factor of the
// reconstruction changed at a time. Prints a table (CSV with --csv); never fails on time.
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <cstring>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "idms/sim/haptic_window.h"
#include "idms/sim/integrate.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/model.h"
#include "idms/sim/model_io.h"
#include "idms/sim/stability.h"
#include "idms/sim/step.h"
#include "idms/sim/summary.h"
#include "idms/sim/workspace.h"

#ifndef IDMS_SOURCE_DIR
#define IDMS_SOURCE_DIR "."
#endif

namespace {

using namespace idms;

constexpr double kThesisDt = 1.0 / 700.0;  // thesis 6.1: "refreshed at approximately 700 Hz"
// Divergent: anything non-finite, a free atom farther than kDivergedDisplacement from rest (the
// fragment is 4 x 3.5 x 0.8 units; converged, no script moves an atom 0.08), or a free atom faster than
// kChatterSpeedFactor times the fastest atom of the same script and variant at T = kReferenceDt
// (the converged dynamics) up to the same script time (a stroke at the thesis's speed moves atoms
// fast while it crosses, but not while the tool presses still before it). The speed test is needed: past the edge the
// unstable contact mode often grows only until the atom leaves the MIO, where it loses the contact stiffness that
// destabilised it, and comes back: a bounded limit cycle (chatter) with atoms at 5-90 units/s and
// the device force swinging 0-6 N while the tool is held still, which no displacement bound
// below the fragment's size catches. On the thesis scripts stable runs stay below 2x the
// reference speed and the first unstable ones jump to 7-13x, so the factor 3 is not critical.
constexpr double kDivergedDisplacement = 10.0;
constexpr double kChatterSpeedFactor = 3.0;
constexpr double kReferenceDt = 1e-4;
constexpr double kSpeedBinS = 0.01;
constexpr double kSpeedWindowS = 0.05;

// The speed test's limit against script time, from the reference run: kChatterSpeedFactor times
// the fastest atom up to kSpeedWindowS past that time. A running maximum: chatter that starts
// while the tool presses still is measured against the still press, not against the fast crossing
// that follows; once atoms have moved fast, a run that reaches the same events a little earlier
// or later (lift-off at another tick) is not called divergent for it.
struct SpeedLimit {
  std::vector<double> bin_max;  // reference run's fastest atom per kSpeedBinS of script time
  double At(double t) const {
    if (bin_max.empty()) return std::numeric_limits<double>::infinity();
    const auto bin = [&](double x) {
      return std::clamp<int64_t>(static_cast<int64_t>(x / kSpeedBinS), 0, static_cast<int64_t>(bin_max.size()) - 1);
    };
    double m = 0;
    for (int64_t b = 0; b <= bin(t + kSpeedWindowS); ++b) m = std::max(m, bin_max[b]);
    return kChatterSpeedFactor * m;
  }
};

const Script kScripts[] = {Script::kPalpate, Script::kStrokeSlow, Script::kStrokeFast, Script::kPluck};

// One factor of the reconstruction changed from the bare thesis configuration.
struct Variant {
  const char* factor;  // the part of the reconstruction it changes
  const char* name;
  std::function<void(Model&)> model = nullptr;
  std::function<void(StepOptions&, ToolCommand&)> step = nullptr;
  // > 0: the MIO's k from the tweezers' closure on. The grasp element takes the MIO's k at closure
  // (tool.cc), so this sets its stiffness; atoms still touching the closed tweezers feel it too.
  double grasp_k = 0;
  bool pluck_only = false;  // the factor only exists in the pluck
};

// The thesis's step: explicit Euler (eqs. 4.13-4.15), eq. 4.6 with lambda 1, r_l = 1.5 r (6.2),
// and none of our guards: no substep prediction, no energy check, no implicit fallback, no
// retry with more substeps (max_substeps 1), no settling or waking outside the window.
StepOptions BareOptions() {
  StepOptions o;
  o.integrator = Integrator::kExplicitEuler;
  o.length_rate = LengthRate::kFiltered;
  o.lambda = 1.0;
  o.local_radius = 2.25;
  o.stability.predict = false;
  o.stability.energy_check = false;
  o.stability.implicit_fallback = false;
  o.stability.max_substeps = 1;
  o.settle_time_s = 0;
  o.wake_neighbours = false;
  return o;
}

// Thesis 6.1: sphere MIO r 1.5, k 400, the pseudo-code's law k (r - |d|) / |d|; tweezers to pluck.
ToolCommand BareTool(Script script) {
  ToolCommand t;
  t.kind = script == Script::kPluck ? ToolKind::kTweezers : ToolKind::kSphere;
  t.radius = 1.5;
  t.stiffness = 400;
  t.law = ContactLaw::kThesis;
  return t;
}

// The model without the elements `drop` selects (FinalizeModel rederives the rest).
Model WithoutElements(const Model& base, const std::function<bool(const Model&, int32_t)>& drop) {
  Model m = base;
  m.elem_atoms.clear(), m.elem_k.clear(), m.elem_b.clear();
  for (int32_t e = 0; e < base.num_elems; ++e) {
    if (drop(base, e)) continue;
    m.elem_atoms.push_back(base.elem_atoms[2 * e]), m.elem_atoms.push_back(base.elem_atoms[2 * e + 1]);
    m.elem_k.push_back(base.elem_k[e]), m.elem_b.push_back(base.elem_b[e]);
  }
  FinalizeModel(m);
  return m;
}

// Apex atoms: free and internal (the lower layer of figure 3-1).
bool IsApex(const Model& m, int32_t a) { return !m.atom_fixed[a] && !m.atom_external[a]; }

struct Outcome {
  bool diverged = false;
  double t_s = 0;        // when it diverged
  double max_disp = 0;   // largest free-atom displacement from rest seen (before divergence)
  double max_speed = 0;  // largest free-atom speed seen (before divergence)
  const char* why = "";  // "non-finite", "displacement" or "speed"
};

// One script at tick dt with the variant; divergent past `speed_limit` (units/s at the script's
// time) among the other tests; stops at divergence unless `run_through`; `record` gets the run's
// fastest atom per bin.
Outcome RunScript(const Model& model, Script script, const Variant& v, double dt, const SpeedLimit& speed_limit,
                  bool run_through = false, SpeedLimit* record = nullptr) {
  StepOptions o = BareOptions();
  ToolCommand tool = BareTool(script);
  if (v.step) v.step(o, tool);
  o.dt_s = dt;
  State s = MakeState(model);
  Workspace ws = MakeWorkspace(model, o);
  ResyncWorkspace(model, s, ws);
  const ScriptGeometry g = MakeScriptGeometry(model, tool.radius);
  const int64_t ticks = std::llround(ScriptDuration(script) / dt);
  ToolInput in;
  in.num_tools = 1;
  Outcome out;
  for (int64_t n = 0; n < ticks; ++n) {
    // As idms-sim run: the pose at the end of the tick.
    const ScriptSample a = SampleScript(script, g, static_cast<double>(n + 1) * dt);
    std::copy(a.pos, a.pos + 3, tool.pos);
    tool.closed = a.closed;
    if (v.grasp_k > 0 && a.closed) tool.stiffness = v.grasp_k;
    in.tools[0] = tool;
    const StepReport r = Step(model, s, ws, in);
    // A non-finite attempt is frozen back to the tick's start (the one guard left): count it.
    bool bad = r.unrecovered || s.warnings.state_repaired > 0;
    double disp = 0, speed = 0;
    for (int32_t i = 0; i < model.num_atoms && !bad; ++i) {
      if (model.atom_fixed[i]) continue;
      double v2 = 0;
      for (int c = 0; c < 3; ++c) v2 += static_cast<double>(s.atom_vel[3 * i + c]) * s.atom_vel[3 * i + c];
      speed = std::max(speed, std::sqrt(v2));
      double d2 = 0;
      for (int c = 0; c < 3; ++c) {
        const double d = static_cast<double>(s.atom_pos[3 * i + c]) - model.atom_pos_eq[3 * i + c];
        d2 += d * d;
      }
      if (!std::isfinite(d2)) bad = true;
      disp = std::max(disp, std::sqrt(d2));
    }
    if (!bad) out.max_disp = std::max(out.max_disp, disp), out.max_speed = std::max(out.max_speed, speed);
    if (record) {
      const size_t bin = static_cast<size_t>(s.time_s / kSpeedBinS);
      if (record->bin_max.size() <= bin) record->bin_max.resize(bin + 1, 0.0);
      record->bin_max[bin] = std::max(record->bin_max[bin], speed);
    }
    if (!out.diverged && (bad || disp > kDivergedDisplacement || speed > speed_limit.At(s.time_s))) {
      out.diverged = true;
      out.t_s = s.time_s;
      out.why = bad ? "non-finite" : disp > kDivergedDisplacement ? "displacement" : "speed";
      if (!run_through) return out;
    }
  }
  return out;
}

struct Edge {
  double dt = 0;                // measured edge, s: largest T with every scanned T' <= T stable
  bool islands = false;         // a scanned T above the edge was stable again
  bool at_thesis_rate = false;  // stable at T = 1/700 s
  double diverged_t_s = 0;      // script time at which the run just past the edge diverged
};

// Geometric scan of T from lo to hi (all of it, so that stable islands above the edge show), then
// bisection between the last stable and the first divergent sample.
// The speed limit of the divergence test for a script and variant, from its run at T = kReferenceDt.
SpeedLimit ReferenceLimit(const Model& model, Script script, const Variant& v, Outcome* reference = nullptr) {
  SpeedLimit limit;
  const Outcome o = RunScript(model, script, v, kReferenceDt, SpeedLimit{}, false, &limit);
  if (reference) *reference = o;
  return limit;
}

Edge FindEdge(const Model& model, Script script, const Variant& v, double ratio, int bisections) {
  const double lo = 2e-4, hi = 4e-3;
  const SpeedLimit limit = ReferenceLimit(model, script, v);
  Edge e;
  e.at_thesis_rate = !RunScript(model, script, v, kThesisDt, limit).diverged;
  double stable = 0, divergent = 0;
  for (double dt = lo; dt <= hi * (1 + 1e-9); dt *= ratio) {
    const bool ok = !RunScript(model, script, v, dt, limit).diverged;
    if (ok && divergent == 0) stable = dt;
    if (!ok && divergent == 0) divergent = dt;
    if (ok && divergent > 0) e.islands = true;
  }
  if (divergent == 0) return e.dt = std::numeric_limits<double>::infinity(), e;
  if (stable == 0) return e.dt = 0, e;
  e.diverged_t_s = RunScript(model, script, v, divergent, limit).t_s;
  for (int i = 0; i < bisections; ++i) {
    const double mid = std::sqrt(stable * divergent);
    const Outcome o = RunScript(model, script, v, mid, limit);
    if (o.diverged) e.diverged_t_s = o.t_s;
    (o.diverged ? divergent : stable) = mid;
  }
  e.dt = stable;
  return e;
}

// ---- Linear analyses -------------------------------------------------------------------

// Exact explicit-Euler edge of x'' = -K x - C x' (per unit mass) by the one-step matrix's
// spectral radius: analytic rate (state x, v) or the eq. 4.6 filter with lambda 1, whose rate is
// (x_n - x_{n-1}) / T (state x_n, v_n, x_{n-1}).
double SpectralRadius(const Eigen::MatrixXd& mk, const Eigen::MatrixXd& mc, double dt, bool filtered) {
  const Eigen::Index n = mk.rows();
  const Eigen::MatrixXd id = Eigen::MatrixXd::Identity(n, n);
  Eigen::MatrixXd a;
  if (!filtered) {
    a.setZero(2 * n, 2 * n);
    a.block(0, 0, n, n) = id, a.block(0, n, n, n) = dt * id;
    a.block(n, 0, n, n) = -dt * mk, a.block(n, n, n, n) = id - dt * mc;
  } else {
    a.setZero(3 * n, 3 * n);
    a.block(0, 0, n, n) = id, a.block(0, n, n, n) = dt * id;
    a.block(n, 0, n, n) = -dt * mk - mc, a.block(n, n, n, n) = id, a.block(n, 2 * n, n, n) = mc;
    a.block(2 * n, 0, n, n) = id;
  }
  const Eigen::VectorXcd ev = a.eigenvalues();
  return ev.cwiseAbs().maxCoeff();
}

double LinearEdge(const Eigen::MatrixXd& mk, const Eigen::MatrixXd& mc, bool filtered) {
  auto stable = [&](double dt) { return SpectralRadius(mk, mc, dt, filtered) < 1 - kMarginalTol; };
  double s = 1e-5, u = 0;
  while (s < 0.05) {
    if (!stable(s * 1.1)) {
      u = s * 1.1;
      break;
    }
    s *= 1.1;
  }
  if (u == 0) return std::numeric_limits<double>::infinity();
  for (int i = 0; i < 30; ++i) {
    const double mid = 0.5 * (s + u);
    (stable(mid) ? s : u) = mid;
  }
  return s;
}

// K / m and B / m of the model linearised at rest over the free atoms within r_l of `centre`
// (all free atoms when r_l <= 0); the others are held, as the window holds them. Home elements
// (zero rest length, so no direction at rest) count as isotropic: k I and b I, what they are for
// motion along a line through the home position (the upper envelope of their damping). A sphere
// MIO at `centre` adds its contact stiffness (normal k_n, tangential -|f| / |d|) on the atoms
// it touches.
struct Linearised {
  Eigen::MatrixXd mk, mc;
  int32_t atoms = 0, contacts = 0;
};
Linearised Linearise(const Model& m, double local_radius, const double centre[3], const ToolCommand* tool,
                     double min_distance_fraction) {
  std::vector<int32_t> slot(m.num_atoms, -1);
  Linearised out;
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    if (m.atom_fixed[a]) continue;
    double d2 = 0;
    for (int c = 0; c < 3; ++c) d2 += (m.atom_pos_eq[3 * a + c] - centre[c]) * (m.atom_pos_eq[3 * a + c] - centre[c]);
    if (local_radius > 0 && d2 > local_radius * local_radius) continue;
    slot[a] = out.atoms++;
  }
  const Eigen::Index n = 3 * out.atoms;
  Eigen::MatrixXd k = Eigen::MatrixXd::Zero(n, n), b = Eigen::MatrixXd::Zero(n, n);
  for (int32_t e = 0; e < m.num_elems; ++e) {
    const int32_t a0 = m.elem_atoms[2 * e], a1 = m.elem_atoms[2 * e + 1];
    if (slot[a0] < 0 && slot[a1] < 0) continue;
    Eigen::Matrix3d p = Eigen::Matrix3d::Identity();
    if (!m.elem_home[e]) {
      Eigen::Vector3d sv;
      for (int c = 0; c < 3; ++c) sv[c] = m.atom_pos_eq[3 * a1 + c] - m.atom_pos_eq[3 * a0 + c];
      sv.normalize();
      p = sv * sv.transpose();
    }
    const int32_t ends[2] = {slot[a0], slot[a1]};
    for (int i = 0; i < 2; ++i) {
      if (ends[i] < 0) continue;
      k.block<3, 3>(3 * ends[i], 3 * ends[i]) += m.elem_k[e] * p;
      b.block<3, 3>(3 * ends[i], 3 * ends[i]) += m.elem_b[e] * p;
      if (ends[1 - i] < 0) continue;
      k.block<3, 3>(3 * ends[i], 3 * ends[1 - i]) -= m.elem_k[e] * p;
      b.block<3, 3>(3 * ends[i], 3 * ends[1 - i]) -= m.elem_b[e] * p;
    }
  }
  for (int32_t a = 0; tool && a < m.num_atoms; ++a) {
    if (slot[a] < 0) continue;
    const double d[3] = {m.atom_pos_eq[3 * a] - centre[0], m.atom_pos_eq[3 * a + 1] - centre[1],
                         m.atom_pos_eq[3 * a + 2] - centre[2]};
    const ContactForce cf = SphereContact(tool->law, tool->stiffness, tool->radius, min_distance_fraction, d);
    if (!cf.touching) continue;
    ++out.contacts;
    const Eigen::Vector3d dv(d[0], d[1], d[2]);
    const double dist = dv.norm();
    const Eigen::Vector3d nv = dv / dist;
    const double fmag = std::sqrt(cf.f[0] * cf.f[0] + cf.f[1] * cf.f[1] + cf.f[2] * cf.f[2]);
    const Eigen::Matrix3d nn = nv * nv.transpose();
    k.block<3, 3>(3 * slot[a], 3 * slot[a]) += cf.stiffness * nn - fmag / dist * (Eigen::Matrix3d::Identity() - nn);
  }
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    if (slot[a] < 0) continue;
    k.middleRows(3 * slot[a], 3) /= m.atom_mass[a];
    b.middleRows(3 * slot[a], 3) /= m.atom_mass[a];
  }
  out.mk = std::move(k), out.mc = std::move(b);
  return out;
}

// Largest eigenvalue (real part) of a per-unit-mass matrix: the fastest rate it sets.
double LargestEigen(const Eigen::MatrixXd& a) {
  if (a.rows() == 0) return 0;
  return a.eigenvalues().real().maxCoeff();
}

// Gershgorin bound over all free atoms (idms-sim validate's stable_dt_euler when the rate is the
// filter), with `extra_k` on every atom (a tool's stiffness felt by one atom, at worst any).
double GershgorinDt(const Model& m, LengthRate rate, double extra_k) {
  double dt = std::numeric_limits<double>::infinity();
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    if (!m.atom_fixed[a])
      dt = std::min(dt, StableDt(Integrator::kExplicitEuler, GershgorinBound(m, a, extra_k), rate, 1.0));
  }
  return dt;
}

std::vector<Variant> MakeVariants(bool quick) {
  std::vector<Variant> v;
  v.push_back({"thesis", "bare thesis configuration"});
  if (quick) return v;
  v.push_back({"filter", "analytic length rate", nullptr,
               [](StepOptions& o, ToolCommand&) { o.length_rate = LengthRate::kAnalytic; }});
  v.push_back({"contact law", "linear law k (r - |d|)", nullptr,
               [](StepOptions&, ToolCommand& t) { t.law = ContactLaw::kLinear; }});
  v.push_back({"layout", "no home elements", [](Model& m) {
                 m = WithoutElements(m, [](const Model& b, int32_t e) { return b.elem_home[e] != 0; });
               }});
  v.push_back({"layout", "no apex-apex lattice", [](Model& m) {
                 m = WithoutElements(m, [](const Model& b, int32_t e) {
                   return IsApex(b, b.elem_atoms[2 * e]) && IsApex(b, b.elem_atoms[2 * e + 1]);
                 });
               }});
  v.push_back({"layout", "top layer only (no apexes)", [](Model& m) {
                 m = WithoutElements(m, [](const Model& b, int32_t e) {
                   return IsApex(b, b.elem_atoms[2 * e]) || IsApex(b, b.elem_atoms[2 * e + 1]);
                 });
               }});
  v.push_back({"grasp", "grasp k 100", nullptr, nullptr, 100, true});
  v.push_back({"grasp", "grasp k 15 (an element's)", nullptr, nullptr, 15, true});
  v.push_back({"window", "full model", nullptr, [](StepOptions& o, ToolCommand&) { o.full = true; }});
  v.push_back({"window", "r_l 3.0 (2 r)", nullptr, [](StepOptions& o, ToolCommand&) { o.local_radius = 3.0; }});
  v.push_back({"MIO k", "MIO k 200", nullptr, [](StepOptions&, ToolCommand& t) { t.stiffness = 200; }});
  v.push_back({"MIO k", "MIO k 800", nullptr, [](StepOptions&, ToolCommand& t) { t.stiffness = 800; }});
  v.push_back({"mass", "m 0.004 (x2)", [](Model& m) {
                 for (int32_t a = 0; a < m.num_atoms; ++a) m.atom_mass[a] *= 2;
               }});
  v.push_back({"damping", "b 0.1 (x0.5)", [](Model& m) {
                 for (double& b : m.elem_b) b *= 0.5;
               }});
  v.push_back({"damping", "b 0.45 (ch. 4 nominal)", [](Model& m) {
                 for (double& b : m.elem_b) b = 0.45;
               }});
  v.push_back({"integrator", "symplectic Euler (reference)", nullptr,
               [](StepOptions& o, ToolCommand&) { o.integrator = Integrator::kSymplecticEuler; }});
  return v;
}

std::string Ms(double dt_s) {
  char buf[32];
  if (std::isinf(dt_s)) return ">4";
  std::snprintf(buf, sizeof buf, "%.3f", 1e3 * dt_s);
  return buf;
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false;
  std::string model_prefix = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";
  const char* csv_path = nullptr;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--quick")) {
      quick = true;
    } else if (!std::strcmp(argv[i], "--model") && i + 1 < argc) {
      model_prefix = argv[++i];
    } else if (!std::strcmp(argv[i], "--csv") && i + 1 < argc) {
      csv_path = argv[++i];
    } else {
      std::fprintf(stderr, "usage: %s [--quick] [--model PREFIX] [--csv FILE]\n", argv[0]);
      return 2;
    }
  }
  Model base;
  LoadError error;
  std::string fem, plg;
  ModelPaths(model_prefix, &fem, &plg);
  if (!LoadModel(fem, plg, {}, &base, &error)) {
    std::fprintf(stderr, "%s\n", error.ToString().c_str());
    return 1;
  }
  // Scan ratio 1.15; 7 bisections give the edge to 0.1%, quick's 3 to 2% (the bare row only).
  const double ratio = 1.15;
  const int bisections = quick ? 3 : 7;

  // The bare configuration's linear references.
  const StepOptions bare = BareOptions();
  const ScriptGeometry geometry = MakeScriptGeometry(base, 1.5);
  std::printf("model %s: %d atoms (%d free), %d elements; thesis ch. 6: k 15, b 0.2, m 0.002, MIO r 1.5 k 400\n",
              base.name.c_str(), base.num_atoms, Summarize(base).free_atoms, base.num_elems);
  std::printf(
      "bare thesis configuration: explicit Euler, eq. 4.6 lambda 1, thesis law k (r - |d|)/|d|, r_l 2.25,\n"
      "no prediction, energy check, fallback, retry or settling; divergent = non-finite, a free atom\n"
      "more than %.0f units from rest, or one faster than %.0fx the fastest atom of the same run at\n"
      "T = %.1f ms (chatter). T = 1/700 s = %.3f ms.\n\n",
      kDivergedDisplacement, kChatterSpeedFactor, 1e3 * kReferenceDt, 1e3 * kThesisDt);
  {
    const HapticWindowParams hw{15.0, 0.2, 0.002, 1e-3};
    const Eigen::MatrixXd a = HapticWindowA(hw);
    const Eigen::MatrixXd a_k = HapticWindowA({hw.k, 0.0, hw.m, hw.dt_s});
    const Eigen::MatrixXd a_b = HapticWindowA({0.0, hw.b, hw.m, hw.dt_s});
    Eigen::MatrixXd mk(3, 3), mc(3, 3);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) mk(i, j) = -a_k(2 * i + 1, 2 * j), mc(i, j) = -a_b(2 * i + 1, 2 * j + 1);
    }
    std::printf("references (ms):\n");
    std::printf("  Gershgorin, fragment, no tool (idms-sim validate stable_dt_euler): %s filtered, %s analytic\n",
                Ms(Summarize(base).stable_dt_euler).c_str(), Ms(GershgorinDt(base, LengthRate::kAnalytic, 0)).c_str());
    std::printf("  Gershgorin, fragment, + MIO k 400 on an atom:                    %s filtered, %s analytic\n",
                Ms(GershgorinDt(base, LengthRate::kFiltered, 400)).c_str(),
                Ms(GershgorinDt(base, LengthRate::kAnalytic, 400)).c_str());
    std::printf(
        "  haptic window fig. 4-2 at k 15, b 0.2, m 0.002, exact:            %s filtered, %s analytic"
        " (Gershgorin %s analytic)\n",
        Ms(LinearEdge(mk, mc, true)).c_str(), Ms(StabilityLimitDt(a, Integrator::kExplicitEuler, 0.1)).c_str(),
        Ms(*GershgorinStableDt(hw, Integrator::kExplicitEuler)).c_str());
    // The fragment linearised at rest: all free atoms, and the window at a 0.05 press.
    const double centre[3] = {geometry.center[0], geometry.center[1], geometry.top_z + 1.5 - 0.05};
    const ToolCommand tool = BareTool(Script::kPalpate);
    const Linearised all = Linearise(base, 0, centre, nullptr, bare.min_distance_fraction);
    const Linearised win = Linearise(base, bare.local_radius, centre, &tool, bare.min_distance_fraction);
    std::printf(
        "  fragment linearised at rest, every free atom, exact:             %s filtered, %s analytic"
        " (max eig K/m %.0f /s^2, B/m %.0f /s)\n",
        Ms(LinearEdge(all.mk, all.mc, true)).c_str(), Ms(LinearEdge(all.mk, all.mc, false)).c_str(),
        LargestEigen(all.mk), LargestEigen(all.mc));
    std::printf(
        "  window r_l 2.25 at a 0.05 press (%d atoms, %d in contact), exact: %s filtered, %s analytic"
        " (max eig K/m %.0f /s^2, B/m %.0f /s)\n\n",
        win.atoms, win.contacts, Ms(LinearEdge(win.mk, win.mc, true)).c_str(),
        Ms(LinearEdge(win.mk, win.mc, false)).c_str(), LargestEigen(win.mk), LargestEigen(win.mc));
  }

  // The bare configuration at the thesis's rate, run through (how far it goes).
  {
    const Variant thesis{"thesis", "bare"};
    std::printf("bare configuration at T = 1/700 s, run to the script's end:\n");
    for (Script script : kScripts) {
      Outcome ref;
      const SpeedLimit limit = ReferenceLimit(base, script, thesis, &ref);
      const Outcome o = RunScript(base, script, thesis, kThesisDt, SpeedLimit{}, true);
      const Outcome first = RunScript(base, script, thesis, kThesisDt, limit);
      std::printf("  %-12s largest displacement %9.3g, speed %9.3g (at T = 0.1 ms: %.3g, %.3g)", ScriptName(script),
                  o.max_disp, o.max_speed, ref.max_disp, ref.max_speed);
      if (first.diverged) {
        std::printf(": DIVERGES (%s) at t = %.3f s\n", first.why, first.t_s);
      } else {
        std::printf(": stable\n");
      }
    }
    std::printf("\n");
  }

  std::FILE* csv = csv_path ? std::fopen(csv_path, "w") : nullptr;
  if (csv) {
    std::fprintf(csv,
                 "factor,variant,script,edge_ms,stable_at_700hz,islands,diverged_t_s,gershgorin_ms,linear_window_ms\n");
  }
  std::printf(
      "measured edge, ms (700 Hz: ok = stable at T = 1/700 s, NO = diverges; * = stable again at some T\n"
      "above the edge; @t = script time at which the run just past the edge diverged, s)\n");
  std::printf("%-12s %-30s | %-18s %-18s %-18s %-18s | %8s %8s\n", "factor", "variant", "palpate", "stroke-slow",
              "stroke-fast", "pluck", "Gersh.", "lin.win");
  for (const Variant& v : MakeVariants(quick)) {
    Model model = base;
    if (v.model) v.model(model);
    StepOptions o = BareOptions();
    ToolCommand tool = BareTool(Script::kPalpate);
    if (v.step) v.step(o, tool);
    const LengthRate rate = o.integrator == Integrator::kExplicitEuler ? o.length_rate : LengthRate::kAnalytic;
    const double gersh = o.integrator == Integrator::kExplicitEuler ? GershgorinDt(model, rate, 0) : [&] {
      double dt = std::numeric_limits<double>::infinity();
      for (int32_t a = 0; a < model.num_atoms; ++a) {
        if (!model.atom_fixed[a]) dt = std::min(dt, SymplecticStableDt(GershgorinBound(model, a)));
      }
      return dt;
    }();
    const double centre[3] = {geometry.center[0], geometry.center[1], geometry.top_z + tool.radius - 0.05};
    const Linearised win = Linearise(model, o.full ? 0 : o.local_radius, centre, &tool, o.min_distance_fraction);
    const double lin = o.integrator == Integrator::kExplicitEuler
                           ? LinearEdge(win.mk, win.mc, rate == LengthRate::kFiltered)
                           : std::numeric_limits<double>::quiet_NaN();
    std::printf("%-12s %-30s |", v.factor, v.name);
    for (Script script : kScripts) {
      if (v.pluck_only && script != Script::kPluck) {
        std::printf(" %-18s", "-");
        continue;
      }
      const Edge e = FindEdge(model, script, v, ratio, bisections);
      char at[16];
      std::snprintf(at, sizeof at, " @%.2f", e.diverged_t_s);
      const std::string cell = Ms(e.dt) + (e.islands ? "*" : "") + (e.at_thesis_rate ? " ok" : " NO") + at;
      std::printf(" %-18s", cell.c_str());
      std::fflush(stdout);
      if (csv) {
        std::fprintf(csv, "%s,%s,%s,%.6g,%d,%d,%.4f,%.6g,%.6g\n", v.factor, v.name, ScriptName(script), 1e3 * e.dt,
                     e.at_thesis_rate ? 1 : 0, e.islands ? 1 : 0, e.diverged_t_s, 1e3 * gersh, 1e3 * lin);
      }
    }
    std::printf(" | %8s %8s\n", Ms(gersh).c_str(), std::isnan(lin) ? "-" : Ms(lin).c_str());
  }
  if (csv) std::fclose(csv);
  std::printf(
      "\nGersh. = Gershgorin bound over the variant's free atoms without a tool (filtered or analytic as the\n"
      "variant integrates; symplectic: its own bound); lin.win = exact explicit-Euler edge of the variant's\n"
      "window linearised at rest at a 0.05 press (home elements isotropic). Edges by a geometric scan of T\n"
      "from 0.2 to 4 ms (ratio %.2f) and %d bisections.\n",
      ratio, bisections);
  return 0;
}
