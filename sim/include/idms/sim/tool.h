// Tools: the master interaction object (MIO, thesis 5.5.1) a device drives — sphere fingertip,
// tweezers (6.1.3) and scalpel (3.2.6) — the per-tick device input, and the contact geometry.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "idms/sim/state.h"

namespace idms {

enum class ContactLaw : uint8_t {
  kThesis,  // thesis 5.5.1 as written: f = k (r - |d|) / |d| along d^ (note the extra 1/|d|)
  kLinear,  // plain penetration: f = k (r - |d|) along d^
};

// One device's sample for one tick, in the model frame (after registration, thesis 5.3).
// Non-finite or negative values are not an error: the step holds the last valid pose and counts
// a warning (validate at the boundary; this is the last line of defence).
// A straight needle's parameters (needle.cc). The tip is a sphere MIO of the tool's radius and
// stiffness until the axial force it puts on the tissue exceeds puncture_force; then the shaft
// holds the atoms near it laterally and slides along its axis against Coulomb friction whose
// normal force is the tissue's grip: grip per unit of inserted length (Okamura et al. 2004: needle
// friction grows with the inserted length) plus the lateral forces' magnitudes. A circular-arc
// needle would add a radius of curvature here (not built: the shaft would be an arc about a centre
// in the needle's plane, the capture a distance to that arc).
struct NeedleParams {
  double length = 10;            // model units, > 0: the shaft runs from tip - length * axis to the tip
  double puncture_force = 1;     // force units, > 0: axial tip force at which the surface yields
  double mu = 0.5;               // >= 0: axial Coulomb coefficient (stick and slip alike)
  double grip = 0;               // force / length, >= 0: the tissue's clamping force per inserted length
  double capture_radius = 0;     // model units, >= 0 (0 = 2 x the tip radius): atoms this near the shaft follow it
  double lateral_stiffness = 0;  // force / length, >= 0 (0 = the tool's stiffness)
  double lateral_damping = -1;   // force / (length / s) (< 0 = lateral_stiffness * dt)
  double axial_stiffness = 0;    // force / length, >= 0 (0 = the tool's stiffness): the stick spring
  double axial_damping = -1;     // force / (length / s) (< 0 = axial_stiffness * dt)
};

// A suture thread a needle draws (suture.cc; SutureState). length 0: none. Read once, when the
// thread is laid behind the needle's tail.
struct SutureParams {
  double length = 0;          // model units, >= 0 (0 = no thread)
  int32_t segments = 64;      // 1 .. kSutureSegments
  double mass = 0.05;         // mass units, > 0: the whole thread
  double stiffness = 0;       // force / length, >= 0 per segment (0 = the stiffest one step holds)
  double damping = -1;        // force / (length / s) per segment (< 0 = critical for a node pair)
  double strength = 0;        // force units, >= 0: a segment's tension that breaks it (0 = never)
  double hold_stiffness = 0;  // force / length, >= 0: a puncture's hold on the thread (0 = the needle's lateral one)
  double tie_force = 2;       // force units, > 0: how hard a knot is drawn
  double tie_speed = 5;       // model units / s, > 0: how fast a knot cinches the loop
  double drag = 5;            // 1 / s, >= 0: air damping on the thread's nodes (it settles a slack thread)
};

struct ToolCommand {
  ToolKind kind = ToolKind::kNone;
  double pos[3] = {0, 0, 0};  // device endpoint = MIO centre (sphere, tweezers) or blade base
  double radius = 1.5;        // sphere/tweezers: MIO radius r, model units (thesis 6.1: 1.5)
  double stiffness = 400;     // sphere/tweezers: MIO k, force / length (thesis 6.1: 400)
  ContactLaw law = ContactLaw::kThesis;
  bool closed = false;           // tweezers: closed this tick
  double blade[3] = {0, 0, -1};  // scalpel: the blade runs from pos to pos + blade, model units
  // Coulomb friction with stiction at this sphere/tweezers' contacts (friction.cc). mu_s = 0 is
  // no friction (the thesis: frictionless, and it costs nothing). 0 <= mu_d <= mu_s. The
  // tangential spring-damper to the anchor: stiffness k_t (force / length; <= 0 = the MIO's k)
  // and damping b_t (force / (length / s); < 0 = k_t * dt, twice Colgate's passivity bound
  // k_t dt / 2 for a sampled spring).
  double mu_s = 0;
  double mu_d = 0;
  double friction_stiffness = 0;
  double friction_damping = -1;
  // Needle: pos is the tip, axis its unit direction from tail to tip (normalised by the step; zero
  // or non-finite is bad input), radius and stiffness the tip's sphere MIO.
  double axis[3] = {0, 0, -1};
  NeedleParams needle;
  // Needle: the thread it draws, and the tie command (a rising edge ties off the current stitch:
  // the thread at its first and last punctures is knotted).
  SutureParams suture;
  bool tie = false;
};

// A needle's axis (tail to tip) for the tool's orientation, a unit quaternion (w, x, y, z): its
// local -z (idms.proto, DeviceSample.tool_orientation). Pure; does not allocate.
void NeedleAxisOf(const double orientation[4], double axis[3]);

// The needle's parameters as a boundary checks them (finite, in range). False with *error naming
// the field ("needle.puncture_force must be a finite number > 0, got 0").
bool ValidateNeedle(const ToolCommand& tool, std::string* error);

// The suture's parameters as a boundary checks them. False with *error naming the field
// ("suture.segments must be an integer in 1..128, got 0").
bool ValidateSuture(const ToolCommand& tool, std::string* error);

// One item of a friction spec on a command line ("mu_s=0.6", "mu_d", "k_t", "b_t") into the
// tool; false when the key is not one of them or the value is not a finite number.
bool SetFrictionItem(std::string_view key, std::string_view value, ToolCommand* tool);

// The tool's friction as a boundary checks it: finite, mu_s >= 0, 0 <= mu_d <= mu_s, k_t finite,
// b_t finite. False with *error naming the field ("mu_d must be <= mu_s (0.4), got 0.6").
bool ValidateFriction(const ToolCommand& tool, std::string* error);

// A friction spec as idms-agent's --friction takes it: "mu_s=0.6[,mu_d=0.4,k_t=K,b_t=B]", items
// in any order; mu_s is required and mu_d defaults to it. Sets *tool's friction fields and says
// which were given (a scene keeps the others at its defaults). False with *error naming the item
// or the field, *tool and *given then unspecified.
struct FrictionGiven {
  bool mu_s = false, mu_d = false, k_t = false, b_t = false;
};
bool ParseFrictionSpec(std::string_view spec, ToolCommand* tool, FrictionGiven* given, std::string* error);

// A tool as idms-sim run's --tool takes it: "sphere:r=1.5,k=400,law=thesis|linear" or
// "tweezers:...", with the friction items above among them (mu_d defaults to mu_s). Sets *tool's
// kind and the given fields. False with *error quoting the spec and naming the bad item.
bool ParseToolSpec(std::string_view spec, ToolCommand* tool, std::string* error);

struct ToolInput {
  std::array<ToolCommand, kMaxTools> tools{};
  int32_t num_tools = 0;  // slots [0, num_tools) are read
};

// Force of a sphere MIO on an atom at offset d = p_atom - centre (thesis 5.5.1), with the
// normal stiffness -d|f|/d|d| the stability prediction and implicit Euler use. |d| is clamped
// below at min_distance_fraction * r for the thesis law (whose 1/|d| would otherwise diverge);
// at |d| = 0 the direction is +z. Zero force outside the sphere. Does not allocate.
struct ContactForce {
  double f[3] = {0, 0, 0};  // on the atom, force units
  double stiffness = 0;     // normal stiffness, force / length
  double energy = 0;        // penalty potential, force * length (0 at |d| >= r)
  bool touching = false;
};
ContactForce SphereContact(ContactLaw law, double k, double r, double min_distance_fraction, const double d[3]);

// True when segment pq crosses triangle abc (Moller-Trumbore; grazing/parallel = no).
bool SegmentCrossesTriangle(const double p[3], const double q[3], const double a[3], const double b[3],
                            const double c[3]);

// True when segment pq crosses the quad a0 b0 b1 a1 that a blade sweeps moving from a0b0 to a1b1.
bool SegmentCrossesSweep(const double p[3], const double q[3], const double a0[3], const double b0[3],
                         const double a1[3], const double b1[3]);

}  // namespace idms
