// One PostgreSQL database shared by the stores of `--store postgres://...`: a small pool of
// connections, each with the stores' statements prepared on first use, reconnecting by itself.
// Internal to the PostgreSQL stores (pg_*.cc).
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <pqxx/pqxx>
#include <string>
#include <utility>
#include <vector>

#include "idms/server/storage.h"

namespace idms::server {

// libpq's multi-line messages as one line (for logs and JSON errors).
std::string OneLine(std::string text);

class PgDatabase {
 public:
  // `conninfo`: a postgres:// URL or a libpq "key=value" string; `max_connections` bounds the pool.
  PgDatabase(std::string conninfo, int max_connections);
  ~PgDatabase();
  PgDatabase(const PgDatabase&) = delete;
  PgDatabase& operator=(const PgDatabase&) = delete;

  // Registers a statement that every connection prepares (libpqxx prepares it on first use, and
  // again after a reconnection). Call before the first Run: connections already open lack it.
  void Prepare(std::string name, std::string sql);

  // Runs fn(connection) on a pooled connection and returns its result. A connection found broken
  // (the server restarted since it was last used) is replaced and fn run once more on the new
  // one, unless a commit may have happened (pqxx::in_doubt_error). Throws StoreUnavailable when
  // the database cannot be reached; any other exception of fn passes through. Blocks while all
  // connections are in use. Once a connection attempt failed, calls that need a new connection
  // fail at once for 250 ms, and after that one call at a time tries again (the others fail at
  // once meanwhile): a down database costs a request microseconds, and at most one thread waits
  // for a connection attempt (up to connect_timeout, 3 s unless the conninfo names one).
  template <class F>
  auto Run(F&& fn) -> decltype(fn(std::declval<pqxx::connection&>())) {
    for (int attempt = 0;; ++attempt) {
      Lease c = Acquire();
      try {
        return fn(*c.conn);
      } catch (const pqxx::in_doubt_error& e) {
        Drop(std::move(c));
        throw StoreUnavailable("PostgreSQL: the connection was lost during a commit: " + OneLine(e.what()));
      } catch (const pqxx::broken_connection& e) {
        Drop(std::move(c));
        if (attempt > 0) throw StoreUnavailable("PostgreSQL: " + OneLine(e.what()));
      } catch (const pqxx::sql_error& e) {
        if (!ConnectionClass(e.sqlstate())) throw;
        Drop(std::move(c));
        if (attempt > 0) throw StoreUnavailable("PostgreSQL: " + OneLine(e.what()));
      }
    }
  }

  const std::string& conninfo() const { return conninfo_; }

 private:
  // A connection taken from the pool; given back when it goes out of scope unless dropped.
  struct Lease {
    PgDatabase* db = nullptr;
    std::unique_ptr<pqxx::connection> conn;
    Lease() = default;
    Lease(PgDatabase* d, std::unique_ptr<pqxx::connection> c) : db(d), conn(std::move(c)) {}
    Lease(Lease&& o) noexcept : db(std::exchange(o.db, nullptr)), conn(std::move(o.conn)) {}
    Lease& operator=(Lease&&) = delete;
    ~Lease();
  };

  Lease Acquire();
  void Drop(Lease lease);
  void Give(std::unique_ptr<pqxx::connection> conn);
  // SQLSTATE classes 08 (connection exception) and 57P (the server shutting down): the
  // connection is gone, whatever the statement was.
  static bool ConnectionClass(const std::string& sqlstate);

  const std::string conninfo_;
  const int max_connections_;
  std::mutex mu_;
  std::condition_variable freed_;
  std::vector<std::unique_ptr<pqxx::connection>> idle_;
  int open_ = 0;  // idle and in use
  std::chrono::steady_clock::time_point down_until_{};
  std::string down_reason_;  // empty: the last connection attempt succeeded
  bool probing_ = false;     // a call is trying to connect while the database is down
  std::vector<std::pair<std::string, std::string>> statements_;  // name, SQL
};

// Runs the schema migrations this server knows that `db` lacks, each in its own transaction under
// a transaction-level advisory lock (two servers starting at once apply each migration once).
// Returns the number applied (0: up to date), or -1 with *error, also when the database's schema
// is newer than this server's.
int ApplyMigrations(PgDatabase& db, std::string* error);

// The store implementations on a migrated database.
std::unique_ptr<ModelStore> MakePgModelStore(std::shared_ptr<PgDatabase> db);
std::unique_ptr<SessionIndex> MakePgSessionIndex(std::shared_ptr<PgDatabase> db);
std::unique_ptr<LeaseStore> MakePgLeaseStore(std::shared_ptr<PgDatabase> db);

}  // namespace idms::server
