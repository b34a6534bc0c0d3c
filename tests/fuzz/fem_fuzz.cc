// libFuzzer target: the .fem parser must reject any input cleanly, never crash or over-allocate.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "idms/sim/model_io.h"
#include "idms/sim/summary.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  idms::Model model;
  idms::LoadError error;
  if (idms::ParseFem(text, "fuzz.fem", &model, &error)) {
    // A model that parsed must write and re-read to the same text.
    const std::string written = idms::WriteFem(model);
    idms::Model again;
    if (!idms::ParseFem(written, "again.fem", &again, &error) || idms::WriteFem(again) != written) __builtin_trap();
    (void)idms::Summarize(model);
  } else if (error.message.empty()) {
    __builtin_trap();  // every rejection says why
  }
  return 0;
}
