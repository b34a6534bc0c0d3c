// libFuzzer target: a server URL as a user types it (--server of idms-agent and idms-render) is
// accepted with a host and a port from 1 to 65535, or refused with a message; never a crash.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "idms/protocol/cli.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  idms::ServerUrl url;
  std::string error;
  if (idms::ParseServerUrl(text, "--server", &url, &error)) {
    if (url.host.empty() || url.port.empty() || url.port.size() > 5) __builtin_trap();
    const long port = std::stol(url.port);
    if (port < 1 || port > 65535) __builtin_trap();
  } else if (error.empty()) {
    __builtin_trap();
  }
  return 0;
}
