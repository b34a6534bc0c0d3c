#include "idms/sim/preset.h"

namespace idms {

PresetSettings SettingsOf(Preset preset) {
  switch (preset) {
    case Preset::kThesis:
      return {.integrator = Integrator::kExplicitEuler, .local_radius_per_tool_radius = 1.5};
    case Preset::kDefault:
      break;
  }
  return {.integrator = Integrator::kSymplecticEuler, .local_radius_per_tool_radius = 2.0};
}

const char* PresetName(Preset preset) { return preset == Preset::kThesis ? "thesis" : "default"; }

bool ParsePresetName(std::string_view name, Preset* preset) {
  for (Preset p : {Preset::kDefault, Preset::kThesis}) {
    if (name == PresetName(p)) {
      *preset = p;
      return true;
    }
  }
  return false;
}

}  // namespace idms
