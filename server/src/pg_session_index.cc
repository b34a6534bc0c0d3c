// The session index in PostgreSQL (--store): one row per session, upserted whole on every update
// (a few per second per live session, from the index's worker strand); notes beside it. A row
// whose Put found the database down is kept (the newest per session) and stored by the first
// call that reaches the database again: a session that ends during an outage is not left "live".
#include <map>
#include <mutex>

#include "pg_database.h"

namespace idms::server {
namespace {

constexpr const char* kColumns =
    "id, state, model, device, identity, started, duration_s, samples, next_tick, resume_sha256, recording, "
    "summary_json, scene_text, trainee";

SessionRow RowToSession(const pqxx::row& r) {
  SessionRow s;
  s.id = r[0].as<std::string>();
  s.state = r[1].as<std::string>();
  s.model = r[2].as<std::string>();
  s.device = r[3].as<std::string>();
  s.identity = r[4].as<std::string>();
  s.started = r[5].as<std::string>();
  s.duration_s = r[6].as<double>();
  s.samples = r[7].as<int64_t>();
  s.next_tick = static_cast<uint64_t>(r[8].as<int64_t>());
  s.resume_sha256 = r[9].as<std::string>();
  s.recording = r[10].as<std::string>();
  s.summary_json = r[11].as<std::string>();
  s.scene_text = r[12].as<std::string>();
  s.trainee = r[13].as<std::string>();
  return s;
}

class PgSessionIndex final : public SessionIndex {
 public:
  explicit PgSessionIndex(std::shared_ptr<PgDatabase> db) : db_(std::move(db)) {
    const std::string cols = kColumns;
    db_->Prepare("sessions_put",
                 "INSERT INTO sessions(" + cols +
                     ") VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14) ON CONFLICT (id) DO "
                     "UPDATE SET state = excluded.state, model = excluded.model, device = excluded.device, "
                     "identity = excluded.identity, started = excluded.started, duration_s = excluded.duration_s, "
                     "samples = excluded.samples, next_tick = excluded.next_tick, resume_sha256 = "
                     "excluded.resume_sha256, recording = excluded.recording, summary_json = excluded.summary_json, "
                     "scene_text = excluded.scene_text, trainee = excluded.trainee");
    db_->Prepare("sessions_get", "SELECT " + cols + " FROM sessions WHERE id = $1");
    db_->Prepare("sessions_list", "SELECT " + cols + " FROM sessions ORDER BY started DESC, id DESC");
    db_->Prepare("sessions_delete", "DELETE FROM sessions WHERE id = $1");
    db_->Prepare("sessions_delete_notes", "DELETE FROM session_notes WHERE session_id = $1");
    db_->Prepare("sessions_put_note",
                 "INSERT INTO session_notes(session_id, id, time_s, text, author, created) "
                 "VALUES ($1, $2, $3, $4, $5, $6)");
    db_->Prepare("sessions_notes",
                 "SELECT id, time_s, text, author, created FROM session_notes WHERE session_id = $1 ORDER BY id");
  }

  bool Put(const SessionRow& row, std::string* error) override {
    try {
      return Write(error, [&](pqxx::work& w) { PutIn(w, row); });
    } catch (const StoreUnavailable&) {
      std::lock_guard lock(pending_mu_);
      pending_[row.id] = row;
      throw;
    }
  }

  bool PutWithNote(const SessionRow& row, const SessionNote& note, std::string* error) override {
    return Write(error, [&](pqxx::work& w) {
      PutIn(w, row);
      w.exec_prepared0("sessions_put_note", row.id, static_cast<int64_t>(note.id), note.time_s, note.text, note.author,
                       note.created);
    });
  }

  std::optional<SessionRow> Get(const std::string& id) override {
    FlushPending();
    return db_->Run([&](pqxx::connection& c) -> std::optional<SessionRow> {
      pqxx::read_transaction t(c);
      const pqxx::result r = t.exec_prepared("sessions_get", id);
      if (r.empty()) return std::nullopt;
      return RowToSession(r[0]);
    });
  }

  std::vector<SessionRow> List() override {
    FlushPending();
    return db_->Run([](pqxx::connection& c) {
      pqxx::read_transaction t(c);
      std::vector<SessionRow> out;
      for (const pqxx::row& r : t.exec_prepared("sessions_list")) out.push_back(RowToSession(r));
      return out;
    });
  }

  bool Delete(const std::string& id) override {
    {
      std::lock_guard lock(pending_mu_);
      pending_.erase(id);
    }
    FlushPending();
    return db_->Run([&](pqxx::connection& c) {
      pqxx::work w(c);
      const bool found = w.exec_prepared("sessions_delete", id).affected_rows() > 0;
      w.exec_prepared0("sessions_delete_notes", id);
      w.commit();
      return found;
    });
  }

  std::vector<SessionNote> Notes(const std::string& id) override {
    return db_->Run([&](pqxx::connection& c) {
      pqxx::read_transaction t(c);
      std::vector<SessionNote> out;
      for (const pqxx::row& r : t.exec_prepared("sessions_notes", id)) {
        out.push_back({static_cast<uint64_t>(r[0].as<int64_t>()), r[1].as<double>(), r[2].as<std::string>(),
                       r[3].as<std::string>(), r[4].as<std::string>()});
      }
      return out;
    });
  }

 private:
  static void PutIn(pqxx::work& w, const SessionRow& r) {
    w.exec_prepared0("sessions_put", r.id, r.state, r.model, r.device, r.identity, r.started, r.duration_s, r.samples,
                     static_cast<int64_t>(r.next_tick), r.resume_sha256, r.recording, r.summary_json, r.scene_text,
                     r.trainee);
  }

  // Stores the rows kept while the database was down, in one transaction; a row a newer Put
  // replaced meanwhile stays replaced. Throws StoreUnavailable while the database is still down.
  void FlushPending() {
    {
      std::lock_guard lock(pending_mu_);
      if (pending_.empty()) return;
    }
    std::lock_guard write(write_mu_);
    FlushPendingLocked();
  }
  void FlushPendingLocked() {
    std::map<std::string, SessionRow> rows;
    {
      std::lock_guard lock(pending_mu_);
      if (pending_.empty()) return;
      rows.swap(pending_);
    }
    try {
      db_->Run([&](pqxx::connection& c) {
        pqxx::work w(c);
        for (const auto& [id, row] : rows) PutIn(w, row);
        w.commit();
      });
    } catch (...) {
      std::lock_guard lock(pending_mu_);
      for (auto& [id, row] : rows) pending_.try_emplace(id, std::move(row));  // newer ones win
      throw;
    }
  }

  // One transaction (after the kept rows); false with *error when a statement is refused (a taken
  // note id, ...).
  template <class F>
  bool Write(std::string* error, F&& statements) {
    // Writes one at a time, so that a kept row never lands after a newer one.
    std::lock_guard write(write_mu_);
    FlushPendingLocked();
    try {
      db_->Run([&](pqxx::connection& c) {
        pqxx::work w(c);
        statements(w);
        w.commit();
      });
      return true;
    } catch (const pqxx::sql_error& e) {
      *error = std::string("PostgreSQL: ") + e.what();
      while (!error->empty() && error->back() == '\n') error->pop_back();
      return false;
    }
  }

  std::shared_ptr<PgDatabase> db_;
  std::mutex write_mu_;                        // held by every write and by the flush of kept rows
  std::mutex pending_mu_;                      // pending_ alone (a Put that failed adds to it under write_mu_ too)
  std::map<std::string, SessionRow> pending_;  // by id: rows whose Put found the database down
};

}  // namespace

std::unique_ptr<SessionIndex> MakePgSessionIndex(std::shared_ptr<PgDatabase> db) {
  return std::make_unique<PgSessionIndex>(std::move(db));
}

}  // namespace idms::server
