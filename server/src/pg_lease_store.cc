// Session ownership leases in PostgreSQL: each call is one statement on the session's row, so the
// row lock decides between two nodes, and expiry is judged by the database's clock (now()), so
// the nodes' clocks do not matter. The row outlives a release, so epochs are never reused.
#include "pg_database.h"

namespace idms::server {
namespace {

class PgLeaseStore final : public LeaseStore {
 public:
  explicit PgLeaseStore(std::shared_ptr<PgDatabase> db) : db_(std::move(db)) {
    constexpr const char* kExpires = "now() + make_interval(secs => $3::DOUBLE PRECISION / 1000)";
    // Taken when free, expired or ours; ON CONFLICT locks the row, then the WHERE sees its latest
    // version: of two nodes racing, the second finds the first's unexpired lease and gets no row.
    db_->Prepare("lease_acquire", std::string("INSERT INTO session_leases(session_id, holder, epoch, expires) "
                                              "VALUES ($1, $2, 1, ") +
                                      kExpires +
                                      ") ON CONFLICT (session_id) DO UPDATE SET holder = excluded.holder, "
                                      "epoch = session_leases.epoch + 1, expires = excluded.expires "
                                      "WHERE session_leases.expires <= now() OR session_leases.holder = "
                                      "excluded.holder RETURNING epoch");
    db_->Prepare("lease_renew", std::string("UPDATE session_leases SET expires = ") + kExpires +
                                    " WHERE session_id = $1 AND holder = $2 AND epoch = $4 AND expires > now()");
    db_->Prepare("lease_release",
                 "UPDATE session_leases SET expires = '-infinity' "
                 "WHERE session_id = $1 AND holder = $2 AND epoch = $3 AND expires > now()");
    db_->Prepare("lease_holder",
                 "SELECT holder, epoch, EXTRACT(EPOCH FROM (expires - now())) * 1000 FROM session_leases "
                 "WHERE session_id = $1 AND expires > now()");
  }

  std::optional<int64_t> Acquire(const std::string& session_id, const std::string& node_id,
                                 std::chrono::milliseconds ttl) override {
    return db_->Run([&](pqxx::connection& c) -> std::optional<int64_t> {
      pqxx::work w(c);
      const pqxx::result r = w.exec_prepared("lease_acquire", session_id, node_id, static_cast<double>(ttl.count()));
      w.commit();
      if (r.empty()) return std::nullopt;
      return r[0][0].as<int64_t>();
    });
  }

  bool Renew(const std::string& session_id, const std::string& node_id, int64_t epoch,
             std::chrono::milliseconds ttl) override {
    return db_->Run([&](pqxx::connection& c) {
      pqxx::work w(c);
      const pqxx::result r =
          w.exec_prepared("lease_renew", session_id, node_id, static_cast<double>(ttl.count()), epoch);
      w.commit();
      return r.affected_rows() == 1;
    });
  }

  void Release(const std::string& session_id, const std::string& node_id, int64_t epoch) override {
    db_->Run([&](pqxx::connection& c) {
      pqxx::work w(c);
      w.exec_prepared0("lease_release", session_id, node_id, epoch);
      w.commit();
    });
  }

  std::optional<Lease> Holder(const std::string& session_id) override {
    return db_->Run([&](pqxx::connection& c) -> std::optional<Lease> {
      pqxx::read_transaction t(c);
      const pqxx::result r = t.exec_prepared("lease_holder", session_id);
      if (r.empty()) return std::nullopt;
      return Lease{r[0][0].as<std::string>(), r[0][1].as<int64_t>(),
                   std::chrono::milliseconds(static_cast<int64_t>(r[0][2].as<double>()))};
    });
  }

 private:
  std::shared_ptr<PgDatabase> db_;
};

}  // namespace

std::unique_ptr<LeaseStore> MakePgLeaseStore(std::shared_ptr<PgDatabase> db) {
  return std::make_unique<PgLeaseStore>(std::move(db));
}

}  // namespace idms::server
