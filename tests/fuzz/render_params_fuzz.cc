// libFuzzer target: idms-render's and the server's render parameters (size, camera, seconds)
// accept or refuse any text cleanly, and what they accept is within the documented ranges.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "idms/render/params.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  std::string error;
  int w = 0, h = 0;
  if (idms::render::ParseSize(text, &w, &h, &error)) {
    if (w < idms::render::kMinSize || h < idms::render::kMinSize || w > idms::render::kMaxSize ||
        h > idms::render::kMaxSize || int64_t{w} * h > idms::render::kMaxPixels)
      std::abort();
  } else if (error.empty()) {
    std::abort();
  }
  idms::render::Camera camera;
  error.clear();
  if (idms::render::ParseCamera(text, &camera, &error)) {
    for (int i = 0; i < 3; ++i) {
      if (!camera.automatic && (!std::isfinite(camera.eye[i]) || !std::isfinite(camera.target[i]))) std::abort();
    }
    if (!camera.automatic && camera.eye == camera.target) std::abort();
  } else if (error.empty()) {
    std::abort();
  }
  double seconds = -1;
  if (idms::render::ParseSeconds(text, &seconds, &error) && !(std::isfinite(seconds) && seconds >= 0)) std::abort();
  return 0;
}
