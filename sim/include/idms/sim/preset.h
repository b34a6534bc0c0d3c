// Named step configurations: the one every entry point uses unless told otherwise, and the
// thesis's own, kept by name for reproductions (idms-sim run --preset, a scene's preset, the
// agent's --preset).
#pragma once

#include <cstdint>
#include <string_view>

#include "idms/sim/step.h"

namespace idms {

enum class Preset : uint8_t {
  // The error-against-run-time bench's choice (docs/error-vs-runtime.md): symplectic Euler with
  // a haptic window of 2 tool radii, on the force-error front within the 1 kHz budget in every
  // case measured.
  kDefault,
  // Thesis chapter 6 (section 6.2): explicit Euler (eqs. 4.13-4.15) with a haptic window of 1.5
  // tool radii (2.25 for the 1.5-unit MIO). docs/figures and docs/thesis-comparison.md use it.
  kThesis,
};

struct PresetSettings {
  Integrator integrator = Integrator::kSymplecticEuler;
  double local_radius_per_tool_radius = 2.0;  // r_l = this * the tool's radius
};

PresetSettings SettingsOf(Preset preset);

const char* PresetName(Preset preset);  // "default", "thesis"

// The inverse of PresetName; false if unknown.
bool ParsePresetName(std::string_view name, Preset* preset);

}  // namespace idms
