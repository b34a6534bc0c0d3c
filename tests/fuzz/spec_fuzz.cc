// libFuzzer target: the command lines' tool, friction and drag specs (idms-sim run --tool and
// --script drag:..., idms-agent --friction and --device scripted:drag,...) accept or refuse any
// text cleanly; what they accept is within the ranges ValidateFriction and the drag document.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "idms/sim/drag.h"
#include "idms/sim/tool.h"

namespace {

void CheckFriction(const idms::ToolCommand& t) {
  if (!(std::isfinite(t.mu_s) && t.mu_s >= 0 && std::isfinite(t.mu_d) && t.mu_d >= 0 && t.mu_d <= t.mu_s)) std::abort();
  if (!(std::isfinite(t.friction_stiffness) && t.friction_stiffness >= 0 && std::isfinite(t.friction_damping)))
    std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  std::string error;
  idms::ToolCommand tool;
  if (idms::ParseToolSpec(text, &tool, &error)) {
    if (tool.kind != idms::ToolKind::kSphere && tool.kind != idms::ToolKind::kTweezers) std::abort();
    if (!(std::isfinite(tool.radius) && tool.radius > 0 && std::isfinite(tool.stiffness) && tool.stiffness > 0))
      std::abort();
    CheckFriction(tool);
  } else if (error.empty()) {
    std::abort();
  }
  error.clear();
  tool = {};
  idms::FrictionGiven given;
  if (idms::ParseFrictionSpec(text, &tool, &given, &error)) {
    if (!given.mu_s) std::abort();
    CheckFriction(tool);
  } else if (error.empty()) {
    std::abort();
  }
  error.clear();
  idms::DragOptions drag;
  if (idms::ParseDragSpec(text, &drag, &error)) {
    if (!(std::isfinite(drag.fraction) && drag.fraction >= 0 && std::isfinite(drag.depth) && drag.depth >= 0 &&
          std::isfinite(drag.hand_mass) && drag.hand_mass > 0 && std::isfinite(drag.push_s) &&
          drag.push_s > drag.ramp_s))
      std::abort();
  } else if (error.empty()) {
    std::abort();
  }
  return 0;
}
