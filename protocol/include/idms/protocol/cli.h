// What every idms command line shares: its version (--version), an idms-server's address as
// users type it, and a token read from a file (so that `ps` does not show it).
#pragma once

#include <string>
#include <string_view>

namespace idms {

// "0.1.0 (git 1a2b3c4)": the project's version and the commit the build was configured at.
const char* Version();

// An idms-server's address: http://HOST:PORT or ws://HOST:PORT (one port answers HTTP and
// WebSocket), an optional path kept as `path`; the port is 8740 when absent.
struct ServerUrl {
  std::string host, port, path;
};
// False with *error naming `option` and saying what was expected (https:// and wss:// included:
// TLS is not spoken by the tools yet).
bool ParseServerUrl(std::string_view url, std::string_view option, ServerUrl* out, std::string* error);

// A token from a file: its content with surrounding whitespace removed (one line, as written by
// `awk '$1 == "agent" {print $2}' DATA/tokens > agent.token`). False with *error when the file
// cannot be read, is empty, or holds more than one word.
bool ReadTokenFile(const std::string& path, std::string* token, std::string* error);

}  // namespace idms
