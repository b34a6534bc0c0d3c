// The PostgreSQL stores' shared part: the connection pool (reconnects by itself, fails fast while
// the database is down), the versioned schema migrations applied at start-up, and OpenPostgres.
#include "pg_database.h"

#include <array>

#include "idms/server/log.h"
#include "idms/server/postgres.h"

namespace idms::server {
namespace {

// Every migration, in order; each runs in one transaction and is recorded in schema_migrations.
// Never edit one that has shipped: add the next. Text columns that are sorted or compared use the
// "C" collation, so the order is the bytes' (as SQLite's), whatever the database's locale.
struct Migration {
  int version;
  const char* what;
  const char* sql;
};
constexpr std::array kMigrations = {
    Migration{1, "models, sessions, notes, logins, leases", R"sql(
CREATE TABLE model_names (
  name TEXT COLLATE "C" PRIMARY KEY,
  next_version BIGINT NOT NULL
);
CREATE TABLE model_versions (
  name TEXT COLLATE "C" NOT NULL,
  version BIGINT NOT NULL,
  description TEXT NOT NULL,
  created TEXT NOT NULL,
  atoms BIGINT NOT NULL,
  elements BIGINT NOT NULL,
  triangles BIGINT NOT NULL,
  bytes BIGINT NOT NULL,
  fem_sha256 TEXT NOT NULL,
  plg_sha256 TEXT NOT NULL,
  obj_sha256 TEXT NOT NULL,
  PRIMARY KEY (name, version)
);
CREATE INDEX model_versions_fem ON model_versions(fem_sha256);
CREATE INDEX model_versions_plg ON model_versions(plg_sha256);
CREATE INDEX model_versions_obj ON model_versions(obj_sha256);
CREATE TABLE sessions (
  id TEXT COLLATE "C" PRIMARY KEY,
  state TEXT NOT NULL,
  model TEXT NOT NULL,
  device TEXT NOT NULL,
  identity TEXT NOT NULL,
  started TEXT COLLATE "C" NOT NULL,
  duration_s DOUBLE PRECISION NOT NULL,
  samples BIGINT NOT NULL,
  next_tick BIGINT NOT NULL,
  resume_sha256 TEXT NOT NULL,
  recording TEXT NOT NULL,
  summary_json TEXT NOT NULL,
  scene_text TEXT NOT NULL,
  trainee TEXT NOT NULL
);
CREATE INDEX sessions_newest ON sessions(started DESC, id DESC);
CREATE TABLE session_notes (
  session_id TEXT COLLATE "C" NOT NULL,
  id BIGINT NOT NULL,
  time_s DOUBLE PRECISION NOT NULL,
  text TEXT NOT NULL,
  author TEXT NOT NULL,
  created TEXT NOT NULL,
  PRIMARY KEY (session_id, id)
);
CREATE TABLE logins (
  cookie_sha256 TEXT PRIMARY KEY,
  token_sha256 TEXT NOT NULL,
  expires TIMESTAMPTZ NOT NULL
);
CREATE INDEX logins_expires ON logins(expires);
CREATE TABLE session_leases (
  session_id TEXT COLLATE "C" PRIMARY KEY,
  holder TEXT NOT NULL,
  epoch BIGINT NOT NULL,
  expires TIMESTAMPTZ NOT NULL
);
)sql"},
    Migration{2, "model versions' metadata (a fit's report)", R"sql(
ALTER TABLE model_versions ADD COLUMN metadata TEXT NOT NULL DEFAULT '';
)sql"},
};

// pg_advisory_xact_lock's key for the migrations: "idms" in ASCII.
constexpr int64_t kMigrationLock = 0x69646d73;

// A failed connection attempt makes every call fail at once for this long.
constexpr std::chrono::milliseconds kRetryAfterFailure{250};

// The connection string with libpq's connect_timeout, unless it names one: a host that does not
// answer must not hold a request (or an admission on an I/O thread) for minutes.
std::string WithConnectTimeout(const std::string& conninfo) {
  if (conninfo.find("connect_timeout") != std::string::npos) return conninfo;
  if (conninfo.rfind("postgres://", 0) == 0 || conninfo.rfind("postgresql://", 0) == 0) {
    return conninfo + (conninfo.find('?') == std::string::npos ? "?" : "&") + "connect_timeout=3";
  }
  return conninfo + " connect_timeout=3";
}

}  // namespace

std::string OneLine(std::string text) {
  for (char& c : text) {
    if (c == '\n' || c == '\t') c = ' ';
  }
  std::string out;
  for (char c : text) {
    if (c != ' ' || (!out.empty() && out.back() != ' ')) out += c;
  }
  while (!out.empty() && out.back() == ' ') out.pop_back();
  return out;
}

PgDatabase::PgDatabase(std::string conninfo, int max_connections)
    : conninfo_(WithConnectTimeout(conninfo)), max_connections_(std::max(1, max_connections)) {}

PgDatabase::~PgDatabase() = default;

void PgDatabase::Prepare(std::string name, std::string sql) {
  std::lock_guard lock(mu_);
  statements_.emplace_back(std::move(name), std::move(sql));
}

PgDatabase::Lease::~Lease() {
  if (db != nullptr && conn) db->Give(std::move(conn));
}

bool PgDatabase::ConnectionClass(const std::string& sqlstate) {
  return sqlstate.rfind("08", 0) == 0 || sqlstate.rfind("57P", 0) == 0;
}

PgDatabase::Lease PgDatabase::Acquire() {
  std::vector<std::pair<std::string, std::string>> statements;
  bool probe = false;
  {
    std::unique_lock lock(mu_);
    freed_.wait(lock, [&] { return !idle_.empty() || open_ < max_connections_; });
    if (!idle_.empty()) {
      std::unique_ptr<pqxx::connection> c = std::move(idle_.back());
      idle_.pop_back();
      return Lease(this, std::move(c));
    }
    // A new connection: while the database is down, only one call at a time tries.
    if (!down_reason_.empty()) {
      if (probing_ || std::chrono::steady_clock::now() < down_until_) throw StoreUnavailable(down_reason_);
      probing_ = probe = true;
    }
    ++open_;
    statements = statements_;
  }
  // Outside the lock: connecting takes a round trip or more.
  try {
    auto c = std::make_unique<pqxx::connection>(conninfo_);
    for (const auto& [name, sql] : statements) c->prepare(name, sql);
    std::lock_guard lock(mu_);
    if (probe) probing_ = false;
    down_reason_.clear();
    return Lease(this, std::move(c));
  } catch (const std::exception& e) {
    std::lock_guard lock(mu_);
    --open_;
    if (probe) probing_ = false;
    freed_.notify_one();
    down_until_ = std::chrono::steady_clock::now() + kRetryAfterFailure;
    down_reason_ = "PostgreSQL unavailable: " + OneLine(e.what());
    throw StoreUnavailable(down_reason_);
  }
}

void PgDatabase::Give(std::unique_ptr<pqxx::connection> conn) {
  std::lock_guard lock(mu_);
  idle_.push_back(std::move(conn));
  freed_.notify_one();
}

void PgDatabase::Drop(Lease lease) {
  lease.db = nullptr;
  lease.conn.reset();
  std::lock_guard lock(mu_);
  --open_;
  freed_.notify_one();
}

int ApplyMigrations(PgDatabase& db, std::string* error) {
  try {
    int applied = 0;
    for (const Migration& m : kMigrations) {
      const bool ran = db.Run([&](pqxx::connection& c) {
        pqxx::work w(c, "migration");
        // Serialises servers starting at once; released with the transaction.
        w.exec("SELECT pg_advisory_xact_lock(" + std::to_string(kMigrationLock) + ")");
        w.exec0(
            "CREATE TABLE IF NOT EXISTS schema_migrations (version INTEGER PRIMARY KEY, what TEXT NOT NULL, "
            "applied TIMESTAMPTZ NOT NULL DEFAULT now())");
        const int current = w.exec1("SELECT COALESCE(MAX(version), 0) FROM schema_migrations")[0].as<int>();
        if (current > PostgresSchemaVersion()) {
          throw std::runtime_error("the database's schema is at version " + std::to_string(current) +
                                   ", newer than this server's " + std::to_string(PostgresSchemaVersion()) +
                                   ": a newer idms-server migrated it; run that version (or a newer one), or "
                                   "point --store at another database");
        }
        if (current >= m.version) return false;
        w.exec(m.sql);
        w.exec_params0("INSERT INTO schema_migrations(version, what) VALUES ($1, $2)", m.version, m.what);
        w.commit();
        return true;
      });
      if (ran) {
        ++applied;
        Log(LogLevel::kInfo, "applied a schema migration", {{"version", m.version}, {"what", m.what}});
      }
    }
    return applied;
  } catch (const StoreUnavailable& e) {
    *error = std::string("--store: ") + e.what();
    return -1;
  } catch (const std::exception& e) {
    *error = std::string("PostgreSQL schema: ") + OneLine(e.what());
    return -1;
  }
}

int PostgresSchemaVersion() { return kMigrations.back().version; }

bool IsPostgresConninfo(const std::string& text) {
  return text.rfind("postgres://", 0) == 0 || text.rfind("postgresql://", 0) == 0 ||
         text.find('=') != std::string::npos;
}

int MigratePostgres(const std::string& conninfo, std::string* error) {
  PgDatabase db(conninfo, 1);
  return ApplyMigrations(db, error);
}

std::unique_ptr<LoginSessions> MakePgLoginSessions(std::shared_ptr<PgDatabase> db, std::chrono::seconds lifetime);

bool OpenPostgres(const std::string& conninfo, std::chrono::seconds login_lifetime, int max_connections,
                  PostgresStores* stores, std::string* error) {
  // The migrations on a connection of their own: the stores' pool prepares their statements on
  // each connection it opens, after they are registered below.
  if (MigratePostgres(conninfo, error) < 0) return false;
  auto db = std::make_shared<PgDatabase>(conninfo, max_connections);
  PostgresStores s;
  s.models = MakePgModelStore(db);
  s.sessions = MakePgSessionIndex(db);
  s.logins = MakePgLoginSessions(db, login_lifetime);
  s.leases = MakePgLeaseStore(db);
  *stores = std::move(s);
  return true;
}

}  // namespace idms::server
