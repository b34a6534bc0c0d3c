// Who may do what: roles, the tokens file (plain or sha256-hashed tokens, one per line), and
// browser login sessions (a cookie standing for a token). Tokens, cookies and their digests are
// never logged; every comparison of digests is constant-time (CRYPTO_memcmp).
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace idms::server {

// Ordered by what they may do; admin may do everything an observer may.
enum class Role { kNone = 0, kObserver = 1, kAgent = 2, kAdmin = 3 };

const char* RoleName(Role role);
// "admin" | "agent" | "observer" -> the role; kNone otherwise.
Role ParseRole(std::string_view text);

// What a role may do. Admin: model writes and deletes, recording deletes, commands to agents;
// agent: publish sessions and read models; observer: read the library, watch, replay.
enum class Permission { kRead, kPublish, kWrite };
bool Allows(Role role, Permission permission);

using Digest = std::array<uint8_t, 32>;  // SHA-256
Digest DigestOf(std::string_view token);
// 64 hex digits (either case) into a digest; false when they are not.
bool HexToDigest(std::string_view hex, Digest* out);

// The tokens file, parsed. Immutable once built; swapped whole on reload.
class TokenTable {
 public:
  // Lines "ROLE TOKEN" or "ROLE sha256:HEX" ('#' starts a comment, blank lines ignored). False
  // with "FILE:LINE: what was expected" on the first bad line.
  static bool Parse(std::string_view text, std::string_view file, TokenTable* table, std::string* error);
  static bool Load(const std::string& path, TokenTable* table, std::string* error);

  // The role of `token`, kNone when unknown. Compares against every entry in constant time.
  Role Lookup(std::string_view token) const { return LookupDigest(DigestOf(token)); }
  Role LookupDigest(const Digest& digest) const;
  size_t size() const { return entries_.size(); }

 private:
  struct Entry {
    Role role;
    Digest digest;
  };
  std::vector<Entry> entries_;
};

// A new random token: 32 bytes from OpenSSL's RAND_bytes as 43 base64url characters.
std::string NewToken();
// Appends "ROLE sha256:HEX" for a new token to `path` (created 0600 when missing) and returns
// the token; empty with *error on failure.
std::string AppendNewToken(const std::string& path, Role role, std::string* error);
// Writes a new tokens file with one plain token per role (mode 0600). For first start-up.
bool CreateDefaultTokens(const std::string& path, std::string* error);

// Browser sessions: a random cookie value standing for the token it was made from. Keyed by the
// cookie's digest (the cookie itself is never stored); each remembers the token's digest, so a
// token removed from the file (SIGHUP) ends its cookies too. Thread-safe. Two implementations:
// MemoryLoginSessions (the default: lost on restart) and PostgreSQL's (idms/server/postgres.h:
// survives a restart, shared by every server on the database). Find runs during admission, on a
// connection's strand.
class LoginSessions {
 public:
  virtual ~LoginSessions() = default;
  // A new cookie value for a token, valid for lifetime().
  virtual std::string Create(const Digest& token_digest) = 0;
  // The token digest behind a live cookie; nullopt when unknown or expired.
  virtual std::optional<Digest> Find(std::string_view cookie) = 0;
  virtual void Remove(std::string_view cookie) = 0;
  std::chrono::seconds lifetime() const { return lifetime_; }

 protected:
  explicit LoginSessions(std::chrono::seconds lifetime) : lifetime_(lifetime) {}

 private:
  std::chrono::seconds lifetime_;
};

// Logins in this process's memory: expired ones are dropped whenever a new one is made.
class MemoryLoginSessions final : public LoginSessions {
 public:
  explicit MemoryLoginSessions(std::chrono::seconds lifetime) : LoginSessions(lifetime) {}
  std::string Create(const Digest& token_digest) override;
  std::optional<Digest> Find(std::string_view cookie) override;
  void Remove(std::string_view cookie) override;

 private:
  struct Login {
    Digest token_digest;
    std::chrono::steady_clock::time_point expires;
  };

  std::mutex mu_;
  std::unordered_map<std::string, Login> logins_;  // key: the cookie's digest, as bytes
};

}  // namespace idms::server
