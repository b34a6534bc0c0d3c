// What both viewers share about colouring a surface (protocol/display.json, embedded at build
// time): the colour map, the range rules for displacement and stiffness, the lights, the tool's
// and the contact markers' look. viewer-web reads the same file; tests/web checks that a value
// takes the same colour in both.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace idms {
struct Model;
}

namespace idms::render {

using Srgb = std::array<uint8_t, 3>;

struct Light {
  std::array<double, 3> towards{0, 0, 1};  // unit, world frame, towards the light
  double intensity = 0;
};

// protocol/display.json, parsed once (immutable; any thread).
struct Display {
  std::vector<Srgb> map;           // the colour map, lightest (0) to darkest
  double range_fraction = 0.1;     // displacement range: this times the mean triangle side, rounded up
  std::vector<double> nice_steps;  // ... to one of these times a power of ten
  int ticks = 5;                   // intervals on the legend
  double rest_note_after_s = 0.1;  // a later rest is named on the legend (a late joiner's)
  std::string length_unit, stiffness_unit;
  double ambient = 0;
  Light key, fill;
  Srgb back{}, plain{};
  Srgb tool_free{}, tool_contact{}, tool_grasp{}, tool_slip{};
  double tool_fill_alpha = 0, tool_outline_px = 0;
  double contact_radius_tolerance = 0;
  Srgb contact_outer{}, contact_inner{};
  double contact_outer_px = 0, contact_inner_px = 0;
  Srgb suture_thread{}, suture_puncture{};  // a needle's thread and the points it passes through
  double suture_puncture_px = 0;
};
const Display& TheDisplay();

// The map's entry for v in [lo, hi]: round(clamp((v - lo) / (hi - lo), 0, 1) * 255); 0 when the
// range has no width beyond rounding (a part in 10^9 of its ends). viewer-web's colourIndex is the
// same arithmetic.
int ColourIndex(double v, double lo, double hi);
// The first of nice_steps times a power of ten at or above x (> 0), within a part in a million;
// 1 for x <= 0 or not finite.
double NiceCeil(double x);
// The displacement colour range's top for a rest surface: NiceCeil(range_fraction x the mean
// length of the triangles' sides, each triangle's three in order). 1 for an empty surface.
double DisplacementRange(std::span<const float> rest, std::span<const int32_t> triangles);
// Per surface vertex (external atom, plg order): the mean k of the elements that end at its atom.
std::vector<double> StiffnessPerVertex(const Model& model);

}  // namespace idms::render
