// Browser logins in PostgreSQL (--store): they survive a restart and every server sharing the
// database knows them. As in memory, only SHA-256 digests are stored (of the cookie, and of the
// token it stands for), never the cookie; expiry is judged by the database's clock.
#include <mutex>
#include <unordered_map>

#include "idms/protocol/digest.h"
#include "idms/server/auth.h"
#include "pg_database.h"

namespace idms::server {
namespace {

// A login found in the database is trusted again without asking for this long: a page load's
// burst of requests (each admitted on an I/O thread) costs one round trip, and a logout on another
// server takes effect here within this time. While the database is down a login already seen
// here is trusted until its own expiry, so that browsers watching live sessions stay logged in.
constexpr std::chrono::seconds kRecheckAfter{2};
constexpr size_t kMaxCached = 10000;  // beyond: the cache starts again (a bound, not an LRU)

class PgLoginSessions final : public LoginSessions {
 public:
  PgLoginSessions(std::shared_ptr<PgDatabase> db, std::chrono::seconds lifetime)
      : LoginSessions(lifetime), db_(std::move(db)) {
    // Expired logins go whenever a new one comes (an index on expires keeps that cheap).
    db_->Prepare("logins_expire", "DELETE FROM logins WHERE expires <= now()");
    db_->Prepare("logins_create",
                 "INSERT INTO logins(cookie_sha256, token_sha256, expires) "
                 "VALUES ($1, $2, now() + make_interval(secs => $3::DOUBLE PRECISION))");
    db_->Prepare("logins_find",
                 "SELECT token_sha256, EXTRACT(EPOCH FROM expires)::DOUBLE PRECISION FROM logins "
                 "WHERE cookie_sha256 = $1 AND expires > now()");
    db_->Prepare("logins_remove", "DELETE FROM logins WHERE cookie_sha256 = $1");
  }

  std::string Create(const Digest& token_digest) override {
    const std::string cookie = NewToken();
    const std::string key = HexEncode(DigestOf(cookie)), token = HexEncode(token_digest);
    const auto seconds = static_cast<double>(lifetime().count());
    db_->Run([&](pqxx::connection& c) {
      pqxx::work w(c);
      w.exec_prepared0("logins_expire");
      w.exec_prepared0("logins_create", key, token, seconds);
      w.commit();
    });
    return cookie;
  }

  std::optional<Digest> Find(std::string_view cookie) override {
    // Looked up by the cookie's digest: the database never sees the secret itself.
    const std::string key = HexEncode(DigestOf(cookie));
    const auto now = std::chrono::steady_clock::now();
    std::optional<Cached> cached;
    {
      std::lock_guard lock(mu_);
      if (const auto it = cache_.find(key); it != cache_.end()) cached = it->second;
    }
    if (cached && now - cached->checked < kRecheckAfter && Live(*cached)) return cached->token;
    std::pair<std::string, double> row;
    try {
      row = db_->Run([&](pqxx::connection& c) {
        pqxx::read_transaction t(c);
        const pqxx::result r = t.exec_prepared("logins_find", key);
        return r.empty() ? std::pair<std::string, double>()
                         : std::pair{r[0][0].as<std::string>(), r[0][1].as<double>()};
      });
    } catch (const StoreUnavailable&) {
      if (cached && Live(*cached)) return cached->token;
      throw;
    }
    Digest d{};
    std::lock_guard lock(mu_);
    if (!HexToDigest(row.first, &d)) {
      cache_.erase(key);
      return std::nullopt;
    }
    if (cache_.size() >= kMaxCached) cache_.clear();
    const auto expires = std::chrono::system_clock::time_point(
        std::chrono::duration_cast<std::chrono::system_clock::duration>(std::chrono::duration<double>(row.second)));
    cache_[key] = Cached{d, now, expires};
    return d;
  }

  void Remove(std::string_view cookie) override {
    const std::string key = HexEncode(DigestOf(cookie));
    {
      std::lock_guard lock(mu_);
      cache_.erase(key);
    }
    db_->Run([&](pqxx::connection& c) {
      pqxx::work w(c);
      w.exec_prepared0("logins_remove", key);
      w.commit();
    });
  }

 private:
  struct Cached {
    Digest token;
    std::chrono::steady_clock::time_point checked;  // when the database last said so
    std::chrono::system_clock::time_point expires;  // the login's own expiry, by the database
  };
  static bool Live(const Cached& c) { return c.expires > std::chrono::system_clock::now(); }

  std::shared_ptr<PgDatabase> db_;
  std::mutex mu_;
  std::unordered_map<std::string, Cached> cache_;  // key: the cookie's digest, hex
};

}  // namespace

std::unique_ptr<LoginSessions> MakePgLoginSessions(std::shared_ptr<PgDatabase> db, std::chrono::seconds lifetime) {
  return std::make_unique<PgLoginSessions>(std::move(db), lifetime);
}

}  // namespace idms::server
