// The model library's metadata in PostgreSQL (--store): the SQLite store's semantics on a shared
// database. A version number comes from the per-name counter row, taken and bumped by one upsert
// under its row lock, so two servers uploading the same name at once get different numbers and a
// number is never reused after a delete.
#include "pg_database.h"

namespace idms::server {
namespace {

constexpr const char* kColumns =
    "name, version, description, created, atoms, elements, triangles, bytes, fem_sha256, plg_sha256, obj_sha256, "
    "metadata";
// The list of latest versions without the metadata (ModelVersion::metadata).
constexpr const char* kListColumns =
    "name, version, description, created, atoms, elements, triangles, bytes, fem_sha256, plg_sha256, obj_sha256, "
    "'' AS metadata";

ModelVersion RowToVersion(const pqxx::row& r) {
  ModelVersion v;
  v.name = r[0].as<std::string>();
  v.version = r[1].as<int64_t>();
  v.description = r[2].as<std::string>();
  v.created = r[3].as<std::string>();
  v.atoms = r[4].as<int64_t>();
  v.elements = r[5].as<int64_t>();
  v.triangles = r[6].as<int64_t>();
  v.bytes = r[7].as<int64_t>();
  v.fem_sha256 = r[8].as<std::string>();
  v.plg_sha256 = r[9].as<std::string>();
  v.obj_sha256 = r[10].as<std::string>();
  v.metadata = r[11].as<std::string>();
  return v;
}

class PgModelStore final : public ModelStore {
 public:
  explicit PgModelStore(std::shared_ptr<PgDatabase> db) : db_(std::move(db)) {
    const std::string cols = kColumns;
    db_->Prepare("models_latest", "SELECT DISTINCT ON (name) " + std::string(kListColumns) +
                                      " FROM model_versions ORDER BY name, version DESC");
    db_->Prepare("models_get", "SELECT " + cols + " FROM model_versions WHERE name = $1 ORDER BY version");
    db_->Prepare("models_next_version",
                 "INSERT INTO model_names(name, next_version) VALUES ($1, 2) ON CONFLICT (name) DO UPDATE "
                 "SET next_version = model_names.next_version + 1 RETURNING next_version - 1");
    db_->Prepare("models_insert",
                 "INSERT INTO model_versions(" + cols + ") VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12)");
    db_->Prepare("models_delete_version", "DELETE FROM model_versions WHERE name = $1 AND version = $2");
    db_->Prepare("models_delete", "DELETE FROM model_versions WHERE name = $1");
    db_->Prepare("models_referenced",
                 "SELECT 1 FROM model_versions WHERE fem_sha256 = $1 OR plg_sha256 = $1 OR obj_sha256 = $1 LIMIT 1");
    db_->Prepare("models_totals", "SELECT COUNT(DISTINCT name), COALESCE(SUM(bytes), 0)::BIGINT FROM model_versions");
  }

  std::vector<ModelVersion> ListLatest() override {
    return db_->Run([](pqxx::connection& c) {
      pqxx::read_transaction t(c);
      std::vector<ModelVersion> out;
      for (const pqxx::row& r : t.exec_prepared("models_latest")) out.push_back(RowToVersion(r));
      return out;
    });
  }

  std::optional<ModelRecord> Get(const std::string& name) override {
    return db_->Run([&](pqxx::connection& c) -> std::optional<ModelRecord> {
      pqxx::read_transaction t(c);
      ModelRecord rec;
      rec.name = name;
      for (const pqxx::row& r : t.exec_prepared("models_get", name)) rec.versions.push_back(RowToVersion(r));
      if (rec.versions.empty()) return std::nullopt;
      return rec;
    });
  }

  bool AddVersion(ModelVersion* v, std::string* error) override {
    if (v->created.empty()) v->created = UtcNow();
    try {
      v->version = db_->Run([&](pqxx::connection& c) {
        pqxx::work w(c);
        const int64_t version = w.exec_prepared1("models_next_version", v->name)[0].as<int64_t>();
        w.exec_prepared0("models_insert", v->name, version, v->description, v->created, v->atoms, v->elements,
                         v->triangles, v->bytes, v->fem_sha256, v->plg_sha256, v->obj_sha256, v->metadata);
        w.commit();
        return version;
      });
      return true;
    } catch (const pqxx::sql_error& e) {
      *error = std::string("PostgreSQL: ") + e.what();
      return false;
    }
  }

  bool Delete(const std::string& name, int64_t version) override {
    return db_->Run([&](pqxx::connection& c) {
      pqxx::work w(c);
      const pqxx::result r = version > 0 ? w.exec_prepared("models_delete_version", name, version)
                                         : w.exec_prepared("models_delete", name);
      w.commit();
      return r.affected_rows() > 0;
    });
  }

  bool BlobReferenced(const std::string& sha) override {
    return db_->Run([&](pqxx::connection& c) {
      pqxx::read_transaction t(c);
      return !t.exec_prepared("models_referenced", sha).empty();
    });
  }

  int64_t NumModels() override { return Totals().first; }
  int64_t LibraryBytes() override { return Totals().second; }

 private:
  std::pair<int64_t, int64_t> Totals() {
    return db_->Run([](pqxx::connection& c) {
      pqxx::read_transaction t(c);
      const pqxx::row r = t.exec_prepared1("models_totals");
      return std::pair<int64_t, int64_t>{r[0].as<int64_t>(), r[1].as<int64_t>()};
    });
  }

  std::shared_ptr<PgDatabase> db_;
};

}  // namespace

std::unique_ptr<ModelStore> MakePgModelStore(std::shared_ptr<PgDatabase> db) {
  return std::make_unique<PgModelStore>(std::move(db));
}

}  // namespace idms::server
