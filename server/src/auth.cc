// Tokens and login sessions. Only digests are kept; comparisons are CRYPTO_memcmp over all entries.
#include "idms/server/auth.h"

#include <fcntl.h>
#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/rand.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "idms/protocol/digest.h"

namespace idms::server {
namespace {

// Appends `text` to `path`, creating it with mode 0600.
bool AppendPrivate(const std::string& path, const std::string& text, bool truncate, std::string* error) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC | (truncate ? O_TRUNC : O_APPEND), 0600);
  if (fd < 0) {
    *error = "cannot open " + path + ": " + std::strerror(errno);
    return false;
  }
  const bool ok = ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size()) && ::fsync(fd) == 0;
  ::close(fd);
  if (!ok) *error = "cannot write " + path + ": " + std::strerror(errno);
  return ok;
}

// A login's key: the cookie's digest, as bytes.
std::string CookieKey(std::string_view cookie) {
  const Digest d = DigestOf(cookie);
  return std::string(reinterpret_cast<const char*>(d.data()), d.size());
}

}  // namespace

bool HexToDigest(std::string_view hex, Digest* out) {
  if (hex.size() != 64) return false;
  auto nibble = [](char c) -> int {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
  };
  for (size_t i = 0; i < 32; ++i) {
    const int hi = nibble(hex[2 * i]), lo = nibble(hex[2 * i + 1]);
    if (hi < 0 || lo < 0) return false;
    (*out)[i] = static_cast<uint8_t>(hi * 16 + lo);
  }
  return true;
}

const char* RoleName(Role role) {
  switch (role) {
    case Role::kAdmin:
      return "admin";
    case Role::kAgent:
      return "agent";
    case Role::kObserver:
      return "observer";
    case Role::kNone:
      break;
  }
  return "none";
}

Role ParseRole(std::string_view text) {
  if (text == "admin") return Role::kAdmin;
  if (text == "agent") return Role::kAgent;
  if (text == "observer") return Role::kObserver;
  return Role::kNone;
}

bool Allows(Role role, Permission permission) {
  switch (permission) {
    case Permission::kRead:
      return role != Role::kNone;
    case Permission::kPublish:
      return role == Role::kAgent || role == Role::kAdmin;
    case Permission::kWrite:
      return role == Role::kAdmin;
  }
  return false;
}

Digest DigestOf(std::string_view token) {
  Digest d{};
  unsigned int len = 0;
  EVP_Digest(token.data(), token.size(), d.data(), &len, EVP_sha256(), nullptr);
  return d;
}

bool TokenTable::Parse(std::string_view text, std::string_view file, TokenTable* table, std::string* error) {
  TokenTable t;
  std::istringstream in{std::string(text)};
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    // Comments and blank lines.
    if (const size_t hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream fields(line);
    std::string role_text, token, extra;
    if (!(fields >> role_text)) continue;
    const std::string where = std::string(file) + ":" + std::to_string(number) + ": ";
    const Role role = ParseRole(role_text);
    if (role == Role::kNone) {
      *error = where + "unknown role '" + role_text + "' (expected admin, agent or observer)";
      return false;
    }
    if (!(fields >> token) || (fields >> extra)) {
      *error = where + "expected 'ROLE TOKEN' or 'ROLE sha256:HEX', two fields";
      return false;
    }
    Entry e{role, {}};
    if (token.rfind("sha256:", 0) == 0) {
      if (!HexToDigest(std::string_view(token).substr(7), &e.digest)) {
        *error = where + "expected 64 hex digits after 'sha256:'";
        return false;
      }
    } else {
      if (token.size() < 16) {
        *error = where + "a token must have at least 16 characters";
        return false;
      }
      e.digest = DigestOf(token);
    }
    t.entries_.push_back(e);
  }
  *table = std::move(t);
  return true;
}

bool TokenTable::Load(const std::string& path, TokenTable* table, std::string* error) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    *error = "cannot read the tokens file " + path + ": " + std::strerror(errno);
    return false;
  }
  std::ostringstream ss;
  ss << in.rdbuf();
  return Parse(ss.str(), path, table, error);
}

Role TokenTable::LookupDigest(const Digest& digest) const {
  // Every entry is compared, so the time does not depend on which (if any) matches.
  Role found = Role::kNone;
  for (const Entry& e : entries_) {
    const bool match = CRYPTO_memcmp(e.digest.data(), digest.data(), digest.size()) == 0;
    if (match && found == Role::kNone) found = e.role;
  }
  return found;
}

std::string NewToken() {
  unsigned char raw[32];
  if (RAND_bytes(raw, sizeof raw) != 1) return {};
  static constexpr char kB64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";
  std::string out;
  uint32_t acc = 0;
  int bits = 0;
  for (unsigned char c : raw) {
    acc = (acc << 8) | c;
    bits += 8;
    while (bits >= 6) {
      bits -= 6;
      out += kB64[(acc >> bits) & 63];
    }
  }
  if (bits > 0) out += kB64[(acc << (6 - bits)) & 63];
  return out;
}

std::string AppendNewToken(const std::string& path, Role role, std::string* error) {
  const std::string token = NewToken();
  if (token.empty()) {
    *error = "RAND_bytes failed";
    return {};
  }
  const std::string line = std::string(RoleName(role)) + " sha256:" + HexEncode(DigestOf(token)) + "\n";
  if (!AppendPrivate(path, line, false, error)) return {};
  return token;
}

bool CreateDefaultTokens(const std::string& path, std::string* error) {
  std::string text =
      "# idms-server tokens: ROLE TOKEN or ROLE sha256:HEX per line. SIGHUP reloads this file.\n"
      "# Add one with: idms-server token create ROLE --tokens " +
      path + "\n";
  for (Role r : {Role::kAdmin, Role::kAgent, Role::kObserver}) {
    const std::string token = NewToken();
    if (token.empty()) {
      *error = "RAND_bytes failed";
      return false;
    }
    text += std::string(RoleName(r)) + " " + token + "\n";
  }
  return AppendPrivate(path, text, true, error);
}

std::string MemoryLoginSessions::Create(const Digest& token_digest) {
  const std::string cookie = NewToken();
  const auto now = std::chrono::steady_clock::now();
  std::lock_guard lock(mu_);
  // Expired logins go whenever a new one comes.
  std::erase_if(logins_, [&](const auto& kv) { return kv.second.expires <= now; });
  logins_[CookieKey(cookie)] = Login{token_digest, now + lifetime()};
  return cookie;
}

std::optional<Digest> MemoryLoginSessions::Find(std::string_view cookie) {
  // Looked up by digest: the map's own comparison then never touches the secret itself.
  const std::string key = CookieKey(cookie);
  std::lock_guard lock(mu_);
  const auto it = logins_.find(key);
  if (it == logins_.end()) return std::nullopt;
  if (it->second.expires <= std::chrono::steady_clock::now()) {
    logins_.erase(it);
    return std::nullopt;
  }
  return it->second.token_digest;
}

void MemoryLoginSessions::Remove(std::string_view cookie) {
  const std::string key = CookieKey(cookie);
  std::lock_guard lock(mu_);
  logins_.erase(key);
}

}  // namespace idms::server
