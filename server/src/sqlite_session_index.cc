// The session index in SQLite (the same database file as the model library, its own connection):
// one row per session, replaced whole on every update (a few per second per live session).
#include <sqlite3.h>

#include <algorithm>
#include <mutex>
#include <vector>

#include "idms/server/storage.h"

namespace idms::server {
namespace {

constexpr const char* kSchema = R"sql(
CREATE TABLE IF NOT EXISTS sessions (
  id TEXT PRIMARY KEY,
  state TEXT NOT NULL,
  model TEXT NOT NULL,
  device TEXT NOT NULL,
  identity TEXT NOT NULL,
  started TEXT NOT NULL,
  duration_s REAL NOT NULL,
  samples INTEGER NOT NULL,
  next_tick INTEGER NOT NULL,
  resume_sha256 TEXT NOT NULL,
  recording TEXT NOT NULL,
  summary_json TEXT NOT NULL,
  scene_text TEXT NOT NULL,
  trainee TEXT NOT NULL DEFAULT ''
);
CREATE TABLE IF NOT EXISTS session_notes (
  session_id TEXT NOT NULL,
  id INTEGER NOT NULL,
  time_s REAL NOT NULL,
  text TEXT NOT NULL,
  author TEXT NOT NULL,
  created TEXT NOT NULL,
  PRIMARY KEY (session_id, id)
);
)sql";

// Columns added since the first schema, each with what brings an older table up to date.
struct AddedColumn {
  const char* name;
  const char* sql;
};
constexpr AddedColumn kAddedColumns[] = {
    {"trainee", "ALTER TABLE sessions ADD COLUMN trainee TEXT NOT NULL DEFAULT ''"},
};

constexpr const char* kColumns =
    "id, state, model, device, identity, started, duration_s, samples, next_tick, resume_sha256, recording, "
    "summary_json, scene_text, trainee";

class SqliteSessionIndex final : public SessionIndex {
 public:
  ~SqliteSessionIndex() override {
    for (sqlite3_stmt* s : {put_, get_, list_, delete_, delete_notes_, put_note_, notes_, begin_, commit_, rollback_}) {
      sqlite3_finalize(s);
    }
    sqlite3_close_v2(db_);
  }

  bool Open(const std::string& path, std::string* error) {
    if (sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX,
                        nullptr) != SQLITE_OK) {
      *error = "cannot open the database " + path;
      return false;
    }
    sqlite3_busy_timeout(db_, 5000);
    char* msg = nullptr;
    if (sqlite3_exec(db_, "PRAGMA journal_mode=WAL; PRAGMA synchronous=NORMAL;", nullptr, nullptr, &msg) != SQLITE_OK ||
        sqlite3_exec(db_, kSchema, nullptr, nullptr, &msg) != SQLITE_OK) {
      *error = std::string("SQLite: ") + (msg ? msg : "error");
      sqlite3_free(msg);
      return false;
    }
    if (!AddMissingColumns(error)) return false;
    const std::string cols = kColumns;
    return Prepare("INSERT OR REPLACE INTO sessions(" + cols +
                       ") VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14)",
                   &put_, error) &&
           Prepare("SELECT " + cols + " FROM sessions WHERE id = ?1", &get_, error) &&
           Prepare("SELECT " + cols + " FROM sessions ORDER BY started DESC, id DESC", &list_, error) &&
           Prepare("DELETE FROM sessions WHERE id = ?1", &delete_, error) &&
           Prepare("DELETE FROM session_notes WHERE session_id = ?1", &delete_notes_, error) &&
           Prepare(
               "INSERT INTO session_notes(session_id, id, time_s, text, author, created) "
               "VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
               &put_note_, error) &&
           Prepare("SELECT id, time_s, text, author, created FROM session_notes WHERE session_id = ?1 ORDER BY id",
                   &notes_, error) &&
           Prepare("BEGIN IMMEDIATE", &begin_, error) && Prepare("COMMIT", &commit_, error) &&
           Prepare("ROLLBACK", &rollback_, error);
  }

  bool Put(const SessionRow& r, std::string* error) override {
    std::lock_guard lock(mu_);
    return PutLocked(r, error);
  }

  bool PutWithNote(const SessionRow& r, const SessionNote& note, std::string* error) override {
    std::lock_guard lock(mu_);
    if (!Run(begin_, error)) return false;
    Text(put_note_, 1, r.id);
    sqlite3_bind_int64(put_note_, 2, static_cast<int64_t>(note.id));
    sqlite3_bind_double(put_note_, 3, note.time_s);
    Text(put_note_, 4, note.text);
    Text(put_note_, 5, note.author);
    Text(put_note_, 6, note.created);
    if (PutLocked(r, error) && Run(put_note_, error) && Run(commit_, error)) return true;
    std::string ignored;
    Run(rollback_, &ignored);
    return false;
  }

  std::vector<SessionNote> Notes(const std::string& id) override {
    std::lock_guard lock(mu_);
    Text(notes_, 1, id);
    std::vector<SessionNote> out;
    while (sqlite3_step(notes_) == SQLITE_ROW) {
      out.push_back({static_cast<uint64_t>(sqlite3_column_int64(notes_, 0)), sqlite3_column_double(notes_, 1),
                     Col(notes_, 2), Col(notes_, 3), Col(notes_, 4)});
    }
    sqlite3_reset(notes_);
    return out;
  }

  std::optional<SessionRow> Get(const std::string& id) override {
    std::lock_guard lock(mu_);
    Text(get_, 1, id);
    std::optional<SessionRow> out;
    if (sqlite3_step(get_) == SQLITE_ROW) out = Row(get_);
    sqlite3_reset(get_);
    return out;
  }

  std::vector<SessionRow> List() override {
    std::lock_guard lock(mu_);
    std::vector<SessionRow> out;
    while (sqlite3_step(list_) == SQLITE_ROW) out.push_back(Row(list_));
    sqlite3_reset(list_);
    return out;
  }

  bool Delete(const std::string& id) override {
    std::lock_guard lock(mu_);
    Text(delete_, 1, id);
    const bool ok = sqlite3_step(delete_) == SQLITE_DONE && sqlite3_changes(db_) > 0;
    sqlite3_reset(delete_);
    Text(delete_notes_, 1, id);
    std::string ignored;
    Run(delete_notes_, &ignored);
    return ok;
  }

 private:
  // One statement to its end; false with *error (SQLite's message).
  bool Run(sqlite3_stmt* s, std::string* error) {
    const bool ok = sqlite3_step(s) == SQLITE_DONE;
    if (!ok) *error = std::string("SQLite: ") + sqlite3_errmsg(db_);
    sqlite3_reset(s);
    return ok;
  }

  bool PutLocked(const SessionRow& r, std::string* error) {
    int i = 1;
    for (const std::string* t : {&r.id, &r.state, &r.model, &r.device, &r.identity, &r.started}) Text(put_, i++, *t);
    sqlite3_bind_double(put_, i++, r.duration_s);
    sqlite3_bind_int64(put_, i++, r.samples);
    sqlite3_bind_int64(put_, i++, static_cast<int64_t>(r.next_tick));
    for (const std::string* t : {&r.resume_sha256, &r.recording, &r.summary_json, &r.scene_text, &r.trainee}) {
      Text(put_, i++, *t);
    }
    return Run(put_, error);
  }

  // A database from before a column existed gets it (with its default), once, at open.
  bool AddMissingColumns(std::string* error) {
    sqlite3_stmt* info = nullptr;
    if (!Prepare("PRAGMA table_info(sessions)", &info, error)) return false;
    std::vector<std::string> have;
    while (sqlite3_step(info) == SQLITE_ROW) have.push_back(Col(info, 1));
    sqlite3_finalize(info);
    for (const AddedColumn& c : kAddedColumns) {
      if (std::find(have.begin(), have.end(), c.name) != have.end()) continue;
      char* msg = nullptr;
      if (sqlite3_exec(db_, c.sql, nullptr, nullptr, &msg) != SQLITE_OK) {
        *error = std::string("SQLite: adding sessions.") + c.name + ": " + (msg ? msg : "error");
        sqlite3_free(msg);
        return false;
      }
    }
    return true;
  }

  bool Prepare(const std::string& sql, sqlite3_stmt** s, std::string* error) {
    if (sqlite3_prepare_v3(db_, sql.c_str(), -1, SQLITE_PREPARE_PERSISTENT, s, nullptr) == SQLITE_OK) return true;
    *error = "SQLite cannot prepare '" + sql + "': " + sqlite3_errmsg(db_);
    return false;
  }
  static void Text(sqlite3_stmt* s, int i, const std::string& t) {
    sqlite3_bind_text(s, i, t.data(), static_cast<int>(t.size()), SQLITE_TRANSIENT);
  }
  static std::string Col(sqlite3_stmt* s, int c) {
    const unsigned char* t = sqlite3_column_text(s, c);
    return t == nullptr
               ? std::string()
               : std::string(reinterpret_cast<const char*>(t), static_cast<size_t>(sqlite3_column_bytes(s, c)));
  }
  static SessionRow Row(sqlite3_stmt* s) {
    SessionRow r;
    r.id = Col(s, 0), r.state = Col(s, 1), r.model = Col(s, 2), r.device = Col(s, 3), r.identity = Col(s, 4);
    r.started = Col(s, 5);
    r.duration_s = sqlite3_column_double(s, 6);
    r.samples = sqlite3_column_int64(s, 7);
    r.next_tick = static_cast<uint64_t>(sqlite3_column_int64(s, 8));
    r.resume_sha256 = Col(s, 9), r.recording = Col(s, 10), r.summary_json = Col(s, 11), r.scene_text = Col(s, 12);
    r.trainee = Col(s, 13);
    return r;
  }

  std::mutex mu_;
  sqlite3* db_ = nullptr;
  sqlite3_stmt *put_ = nullptr, *get_ = nullptr, *list_ = nullptr, *delete_ = nullptr, *delete_notes_ = nullptr;
  sqlite3_stmt *put_note_ = nullptr, *notes_ = nullptr, *begin_ = nullptr, *commit_ = nullptr, *rollback_ = nullptr;
};

}  // namespace

std::unique_ptr<SessionIndex> OpenSqliteSessionIndex(const std::string& db_path, std::string* error) {
  auto index = std::make_unique<SqliteSessionIndex>();
  if (!index->Open(db_path, error)) return nullptr;
  return index;
}

}  // namespace idms::server
