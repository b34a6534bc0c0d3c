// The command lines' shared parts (cli.h).
#include "idms/protocol/cli.h"

#include <cctype>
#include <fstream>
#include <sstream>

namespace idms {

bool ParseServerUrl(std::string_view url, std::string_view option, ServerUrl* out, std::string* error) {
  const auto fail = [&](const std::string& why) {
    *error = std::string(option) + " '" + std::string(url) + "': " + why;
    return false;
  };
  std::string_view rest = url;
  bool schemed = false;
  for (std::string_view scheme : {"http://", "ws://"}) {
    if (rest.substr(0, scheme.size()) == scheme) rest.remove_prefix(scheme.size()), schemed = true;
  }
  if (!schemed) {
    if (url.substr(0, 8) == "https://" || url.substr(0, 6) == "wss://") {
      return fail("TLS (https://, wss://) is not spoken by this tool yet; use http:// or ws://");
    }
    return fail("expected http://HOST:PORT or ws://HOST:PORT");
  }
  const size_t slash = rest.find('/');
  const std::string_view authority = rest.substr(0, slash);
  const size_t colon = authority.rfind(':');
  ServerUrl u;
  u.host = std::string(authority.substr(0, colon));
  u.port = colon == std::string_view::npos ? "8740" : std::string(authority.substr(colon + 1));
  if (slash != std::string_view::npos && slash + 1 < rest.size()) u.path = std::string(rest.substr(slash));
  if (u.host.empty()) return fail("no host");
  if (u.port.empty() || u.port.size() > 5 || u.port.find_first_not_of("0123456789") != std::string::npos ||
      std::stoi(u.port) == 0 || std::stoi(u.port) > 65535) {
    return fail("the port must be a number from 1 to 65535");
  }
  *out = std::move(u);
  return true;
}

bool ReadTokenFile(const std::string& path, std::string* token, std::string* error) {
  std::ifstream in(path);
  if (!in) return *error = "--token-file " + path + ": cannot be read", false;
  std::ostringstream text;
  text << in.rdbuf();
  std::istringstream words(text.str());
  std::string first, second;
  words >> first >> second;
  if (first.empty()) return *error = "--token-file " + path + ": is empty", false;
  if (!second.empty()) {
    return *error = "--token-file " + path + ": holds more than one word (the token alone is expected)", false;
  }
  *token = first;
  return true;
}

}  // namespace idms
