// A throwaway PostgreSQL server for the tests: initdb into a fresh directory, postgres on a free
// loopback port (its unix socket in that directory, fsync off), stopped and removed at the end.
// As root (CI) initdb and postgres run as the `postgres` system user, who owns the directory.
#pragma once

#include <optional>
#include <string>

namespace idms::test {

class PgCluster {
 public:
  // The directory holding initdb, pg_ctl and postgres: $IDMS_PG_BINDIR, `pg_config --bindir`,
  // the newest /usr/lib/postgresql/*/bin, or nullopt when PostgreSQL is not installed.
  static std::optional<std::string> BinDir();

  PgCluster();   // initdb and start; check ok() (and error())
  ~PgCluster();  // stop (immediate) and remove the directory
  PgCluster(const PgCluster&) = delete;
  PgCluster& operator=(const PgCluster&) = delete;

  bool ok() const { return error_.empty(); }
  const std::string& error() const { return error_; }
  int port() const { return port_; }
  // postgres://postgres@127.0.0.1:PORT/DB
  std::string Url(const std::string& db = "postgres") const;
  // A new empty database; its URL, or "" (with error()) on failure.
  std::string CreateDatabase(const std::string& name);
  // pg_ctl stop -m fast (connections are told the server is shutting down) / start on the same
  // port. False with error() on failure.
  bool Stop();
  bool Start();
  // Runs `sql` with psql on database `db`; its output (tuples only, unaligned), nullopt on failure.
  std::optional<std::string> Psql(const std::string& db, const std::string& sql);
  std::string Log() const;  // the server's log

 private:
  // Runs a shell command as the user that owns the cluster; false (error_ set) unless it exits 0.
  bool Run(const std::string& command, std::string* output = nullptr);

  std::string bin_, dir_, as_user_;  // as_user_: "runuser -u postgres -- " as root, else ""
  int port_ = 0;
  std::string error_;
};

}  // namespace idms::test
