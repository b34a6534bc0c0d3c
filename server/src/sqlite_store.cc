// The model library's metadata in SQLite (WAL): one connection, statements prepared once, every
// write one transaction. Versions are numbered per name from a counter that outlives deletes, so
// a (name, version) pair always means the same bytes (downloads of a named version are immutable).
#include <sqlite3.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <mutex>

#include "idms/server/storage.h"

namespace idms::server {
namespace {

constexpr const char* kSchema = R"sql(
CREATE TABLE IF NOT EXISTS model_names (
  name TEXT PRIMARY KEY,
  next_version INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS model_versions (
  name TEXT NOT NULL,
  version INTEGER NOT NULL,
  description TEXT NOT NULL,
  created TEXT NOT NULL,
  atoms INTEGER NOT NULL,
  elements INTEGER NOT NULL,
  triangles INTEGER NOT NULL,
  bytes INTEGER NOT NULL,
  fem_sha256 TEXT NOT NULL,
  plg_sha256 TEXT NOT NULL,
  obj_sha256 TEXT NOT NULL,
  PRIMARY KEY (name, version)
);
CREATE INDEX IF NOT EXISTS model_versions_fem ON model_versions(fem_sha256);
CREATE INDEX IF NOT EXISTS model_versions_plg ON model_versions(plg_sha256);
CREATE INDEX IF NOT EXISTS model_versions_obj ON model_versions(obj_sha256);
)sql";

// Columns added since the first schema, each with what brings an older table up to date.
struct AddedColumn {
  const char* name;
  const char* sql;
};
constexpr AddedColumn kAddedColumns[] = {
    {"metadata", "ALTER TABLE model_versions ADD COLUMN metadata TEXT NOT NULL DEFAULT ''"},
};

constexpr const char* kColumns =
    "name, version, description, created, atoms, elements, triangles, bytes, fem_sha256, plg_sha256, obj_sha256, "
    "metadata";
// The list of latest versions without the metadata (ModelVersion::metadata).
constexpr const char* kListColumns =
    "name, version, description, created, atoms, elements, triangles, bytes, fem_sha256, plg_sha256, obj_sha256, "
    "'' AS metadata";

// A prepared statement, reset after each use.
class Statement {
 public:
  Statement() = default;
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;
  ~Statement() { sqlite3_finalize(stmt_); }

  bool Prepare(sqlite3* db, const std::string& sql, std::string* error) {
    if (sqlite3_prepare_v3(db, sql.c_str(), -1, SQLITE_PREPARE_PERSISTENT, &stmt_, nullptr) == SQLITE_OK) return true;
    *error = std::string("SQLite cannot prepare '") + sql + "': " + sqlite3_errmsg(db);
    return false;
  }
  Statement& Bind(int i, const std::string& s) {
    sqlite3_bind_text(stmt_, i, s.data(), static_cast<int>(s.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Statement& Bind(int i, int64_t v) {
    sqlite3_bind_int64(stmt_, i, v);
    return *this;
  }
  // SQLITE_ROW or SQLITE_DONE on success.
  int Step() { return sqlite3_step(stmt_); }
  void Reset() {
    sqlite3_reset(stmt_);
    sqlite3_clear_bindings(stmt_);
  }
  int64_t Int(int col) const { return sqlite3_column_int64(stmt_, col); }
  std::string Text(int col) const {
    const unsigned char* t = sqlite3_column_text(stmt_, col);
    return t == nullptr
               ? std::string()
               : std::string(reinterpret_cast<const char*>(t), static_cast<size_t>(sqlite3_column_bytes(stmt_, col)));
  }

 private:
  sqlite3_stmt* stmt_ = nullptr;
};

// Resets the statement when the scope ends, however it ends.
struct ResetOnExit {
  Statement& s;
  ~ResetOnExit() { s.Reset(); }
};

ModelVersion RowToVersion(const Statement& s) {
  ModelVersion v;
  v.name = s.Text(0);
  v.version = s.Int(1);
  v.description = s.Text(2);
  v.created = s.Text(3);
  v.atoms = s.Int(4);
  v.elements = s.Int(5);
  v.triangles = s.Int(6);
  v.bytes = s.Int(7);
  v.fem_sha256 = s.Text(8);
  v.plg_sha256 = s.Text(9);
  v.obj_sha256 = s.Text(10);
  v.metadata = s.Text(11);
  return v;
}

}  // namespace

std::string UtcNow() {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

std::string UtcNowMs() {
  const auto now = std::chrono::system_clock::now();
  const std::time_t t = std::chrono::system_clock::to_time_t(now);
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[40];
  const size_t n = std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%S", &tm);
  std::snprintf(buf + n, sizeof buf - n, ".%03dZ", static_cast<int>(ms));
  return buf;
}

namespace {

class SqliteModelStore final : public ModelStore {
 public:
  // close_v2 defers each close until the member statements are finalised just after.
  ~SqliteModelStore() override {
    sqlite3_close_v2(rdb_);
    sqlite3_close_v2(db_);
  }

  bool Open(const std::string& path, std::string* error) {
    // Two connections: one writes (uploads, deletes), one reads. In WAL mode a reader never waits
    // for the writer's commit and fsync, so listing the library stays fast during an upload.
    if (!OpenConnection(path, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, &db_, error)) return false;
    // WAL: readers never block the writer; synchronous FULL: a committed upload survives power loss.
    if (!Exec("PRAGMA journal_mode=WAL; PRAGMA synchronous=FULL; PRAGMA foreign_keys=ON;", error) ||
        !Exec(kSchema, error) || !AddMissingColumns(error) || !OpenConnection(path, SQLITE_OPEN_READONLY, &rdb_, error))
      return false;
    const std::string cols = kColumns;
    return list_latest_.Prepare(rdb_,
                                std::string("SELECT ") + kListColumns +
                                    " FROM model_versions v WHERE version = "
                                    "(SELECT MAX(version) FROM model_versions w WHERE w.name = v.name) ORDER BY name",
                                error) &&
           get_.Prepare(rdb_, "SELECT " + cols + " FROM model_versions WHERE name = ?1 ORDER BY version", error) &&
           next_version_.Prepare(db_, "SELECT next_version FROM model_names WHERE name = ?1", error) &&
           upsert_name_.Prepare(db_,
                                "INSERT INTO model_names(name, next_version) VALUES (?1, ?2) "
                                "ON CONFLICT(name) DO UPDATE SET next_version = excluded.next_version",
                                error) &&
           insert_.Prepare(
               db_,
               "INSERT INTO model_versions(" + cols + ") VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)",
               error) &&
           delete_version_.Prepare(db_, "DELETE FROM model_versions WHERE name = ?1 AND version = ?2", error) &&
           delete_model_.Prepare(db_, "DELETE FROM model_versions WHERE name = ?1", error) &&
           referenced_.Prepare(rdb_,
                               "SELECT 1 FROM model_versions WHERE fem_sha256 = ?1 OR plg_sha256 = ?1 OR "
                               "obj_sha256 = ?1 LIMIT 1",
                               error) &&
           totals_.Prepare(rdb_, "SELECT COUNT(DISTINCT name), COALESCE(SUM(bytes), 0) FROM model_versions", error) &&
           begin_.Prepare(db_, "BEGIN IMMEDIATE", error) && commit_.Prepare(db_, "COMMIT", error) &&
           rollback_.Prepare(db_, "ROLLBACK", error);
  }

  std::vector<ModelVersion> ListLatest() override {
    std::lock_guard lock(read_mu_);
    ResetOnExit r{list_latest_};
    std::vector<ModelVersion> out;
    while (list_latest_.Step() == SQLITE_ROW) out.push_back(RowToVersion(list_latest_));
    return out;
  }

  std::optional<ModelRecord> Get(const std::string& name) override {
    std::lock_guard lock(read_mu_);
    ResetOnExit r{get_};
    get_.Bind(1, name);
    ModelRecord rec;
    rec.name = name;
    while (get_.Step() == SQLITE_ROW) rec.versions.push_back(RowToVersion(get_));
    if (rec.versions.empty()) return std::nullopt;
    return rec;
  }

  bool AddVersion(ModelVersion* v, std::string* error) override {
    std::lock_guard lock(mu_);
    if (!Run(begin_, error)) return false;
    // The next number for this name, from the counter that survives deletes.
    int64_t next = 1;
    {
      ResetOnExit r{next_version_};
      next_version_.Bind(1, v->name);
      if (next_version_.Step() == SQLITE_ROW) next = next_version_.Int(0);
    }
    v->version = next;
    if (v->created.empty()) v->created = UtcNow();
    upsert_name_.Bind(1, v->name).Bind(2, next + 1);
    insert_.Bind(1, v->name).Bind(2, v->version).Bind(3, v->description).Bind(4, v->created);
    insert_.Bind(5, v->atoms).Bind(6, v->elements).Bind(7, v->triangles).Bind(8, v->bytes);
    insert_.Bind(9, v->fem_sha256).Bind(10, v->plg_sha256).Bind(11, v->obj_sha256).Bind(12, v->metadata);
    if (!Run(upsert_name_, error) || !Run(insert_, error) || !Run(commit_, error)) {
      std::string ignored;
      Run(rollback_, &ignored);
      return false;
    }
    return true;
  }

  bool Delete(const std::string& name, int64_t version) override {
    std::lock_guard lock(mu_);
    Statement& s = version > 0 ? delete_version_ : delete_model_;
    s.Bind(1, name);
    if (version > 0) s.Bind(2, version);
    std::string error;
    return Run(s, &error) && sqlite3_changes(db_) > 0;
  }

  bool BlobReferenced(const std::string& sha) override {
    std::lock_guard lock(read_mu_);
    ResetOnExit r{referenced_};
    referenced_.Bind(1, sha);
    return referenced_.Step() == SQLITE_ROW;
  }

  int64_t NumModels() override { return Totals().first; }
  int64_t LibraryBytes() override { return Totals().second; }

 private:
  std::pair<int64_t, int64_t> Totals() {
    std::lock_guard lock(read_mu_);
    ResetOnExit r{totals_};
    if (totals_.Step() != SQLITE_ROW) return {0, 0};
    return {totals_.Int(0), totals_.Int(1)};
  }

  static bool OpenConnection(const std::string& path, int flags, sqlite3** db, std::string* error) {
    if (sqlite3_open_v2(path.c_str(), db, flags | SQLITE_OPEN_NOMUTEX, nullptr) == SQLITE_OK) {
      sqlite3_busy_timeout(*db, 5000);
      return true;
    }
    *error = "cannot open the database " + path + ": " + (*db ? sqlite3_errmsg(*db) : "out of memory");
    return false;
  }

  bool Exec(const char* sql, std::string* error) {
    char* msg = nullptr;
    if (sqlite3_exec(db_, sql, nullptr, nullptr, &msg) == SQLITE_OK) return true;
    *error = std::string("SQLite: ") + (msg ? msg : "error");
    sqlite3_free(msg);
    return false;
  }

  // The columns of kAddedColumns an older database lacks, added.
  bool AddMissingColumns(std::string* error) {
    for (const AddedColumn& c : kAddedColumns) {
      sqlite3_stmt* s = nullptr;
      if (sqlite3_prepare_v2(db_, "SELECT 1 FROM pragma_table_info('model_versions') WHERE name = ?1", -1, &s,
                             nullptr) != SQLITE_OK) {
        *error = std::string("SQLite: ") + sqlite3_errmsg(db_);
        return false;
      }
      sqlite3_bind_text(s, 1, c.name, -1, SQLITE_STATIC);
      const bool present = sqlite3_step(s) == SQLITE_ROW;
      sqlite3_finalize(s);
      if (!present && !Exec(c.sql, error)) return false;
    }
    return true;
  }

  bool Run(Statement& s, std::string* error) {
    ResetOnExit r{s};
    const int rc = s.Step();
    if (rc == SQLITE_DONE || rc == SQLITE_ROW) return true;
    *error = std::string("SQLite: ") + sqlite3_errmsg(db_);
    return false;
  }

  std::mutex mu_;       // the writing connection's statements
  std::mutex read_mu_;  // the reading connection's statements (each call is microseconds)
  sqlite3* db_ = nullptr;
  sqlite3* rdb_ = nullptr;
  Statement list_latest_, get_, next_version_, upsert_name_, insert_, delete_version_, delete_model_, referenced_,
      totals_, begin_, commit_, rollback_;
};

}  // namespace

std::unique_ptr<ModelStore> OpenSqliteModelStore(const std::string& db_path, std::string* error) {
  auto store = std::make_unique<SqliteModelStore>();
  if (!store->Open(db_path, error)) return nullptr;
  return store;
}

}  // namespace idms::server
