// Helpers shared by the step, tool and stability tests: tiny hand-built models, the shipped ones,
// tool inputs, and a hash of a State's bits for determinism checks.
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <string>

#include "idms/sim/model.h"
#include "idms/sim/model_io.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"
#include "idms/sim/tool.h"

namespace idms::test {

// A model shipped in models/ ("hex_4x5_home", "slab_40x40", ...), loaded as idms-sim loads it; a
// test failure naming the file if it does not load.
inline Model LoadShippedModel(const std::string& name) {
  Model m;
  LoadError error;
  const std::string prefix = std::string(IDMS_SOURCE_DIR) + "/models/" + name;
  EXPECT_TRUE(LoadModel(prefix + ".fem", prefix + ".plg", {}, &m, &error)) << error.ToString();
  return m;
}

// Two atoms of `mass` joined by one element (k, b): atom 0 at the origin, atom 1 at `end`.
struct SpringPair {
  const char* name = "spring";
  double end[3] = {1, 0, 0};
  bool first_fixed = true;       // atom 0 immobile
  uint8_t external[2] = {0, 1};  // surface condition of each atom
};
inline Model TwoAtomModel(const SpringPair& pair, double k, double b, double mass) {
  Model m;
  m.name = pair.name;
  m.atom_pos_eq = {0, 0, 0, pair.end[0], pair.end[1], pair.end[2]};
  m.atom_mass = {mass, mass};
  m.atom_fixed = {static_cast<uint8_t>(pair.first_fixed), 0};
  m.atom_external = {pair.external[0], pair.external[1]};
  m.elem_atoms = {0, 1};
  m.elem_k = {k};
  m.elem_b = {b};
  FinalizeModel(m);
  return m;
}

// Atom 0 fixed at the origin, atom 1 free at (leq, 0, 0), one element between them.
inline Model OneSpring(double k, double b, double mass, double leq = 1.0) {
  return TwoAtomModel({.name = "spring", .end = {leq, 0, 0}}, k, b, mass);
}

// Full mode (local simulation off) with the given integrator and step.
inline StepOptions FullOptions(Integrator integrator, double dt) {
  StepOptions o;
  o.full = true;
  o.integrator = integrator;
  o.dt_s = dt;
  return o;
}

inline ToolInput SphereAt(double x, double y, double z, double r = 1.5, double k = 400,
                          ContactLaw law = ContactLaw::kThesis) {
  ToolInput in;
  in.num_tools = 1;
  ToolCommand& c = in.tools[0];
  c.kind = ToolKind::kSphere;
  c.pos[0] = x, c.pos[1] = y, c.pos[2] = z;
  c.radius = r;
  c.stiffness = k;
  c.law = law;
  return in;
}

// FNV-1a over the bits of everything a step evolves.
inline uint64_t HashState(const State& s) {
  uint64_t h = 1469598103934665603ull;
  auto mix = [&h](const void* data, size_t bytes) {
    const unsigned char* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 1099511628211ull;
  };
  mix(s.atom_pos.data(), s.atom_pos.size() * sizeof(Real));
  mix(s.atom_vel.data(), s.atom_vel.size() * sizeof(Real));
  // The eq. 4.6 filter as its next update reads it: a restart mark whatever the stored rate.
  for (size_t e = 0; e < s.elem_len.size(); ++e) {
    const bool restarts = s.elem_len[e] == kFilterRestart;
    const Real filter[2] = {s.elem_len[e], restarts ? Real(0) : s.elem_rate[e]};
    mix(filter, sizeof(filter));
  }
  mix(&s.tick, sizeof(s.tick));
  mix(&s.time_s, sizeof(s.time_s));
  for (const ToolState& t : s.tools) mix(t.force, sizeof(t.force)), mix(&t.grasp_atom, sizeof(t.grasp_atom));
  // A needle's puncture, entry and axial friction (needle.cc).
  for (const ToolState& t : s.tools) {
    const NeedleState& n = t.needle;
    const double values[] = {n.tip_scale,   n.tip_ramp,     n.tip_max_step, n.tip_axial,
                             n.entry_depth, n.axial_offset, n.axial_u};
    mix(values, sizeof(values));
    mix(n.entry_atoms, sizeof(n.entry_atoms)), mix(n.entry_w, sizeof(n.entry_w));
    const uint8_t flags[2] = {static_cast<uint8_t>(n.punctured), static_cast<uint8_t>(n.axial)};
    mix(flags, sizeof(flags));
  }
  for (const WarningKind& k : WarningKinds(s.warnings)) mix(&k.count, sizeof(k.count));  // every counter
  return h;
}

}  // namespace idms::test
