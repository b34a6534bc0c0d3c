// libFuzzer target: the .plg parser must reject any input cleanly, never crash or over-allocate.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "idms/sim/model_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  idms::SurfaceMesh mesh;
  idms::LoadError error;
  if (idms::ParsePlg(text, "fuzz.plg", &mesh, &error)) {
    for (int32_t v : mesh.tri_verts) {
      if (v < 0 || v >= mesh.num_verts()) __builtin_trap();
    }
  } else if (error.message.empty()) {
    __builtin_trap();
  }
  return 0;
}
