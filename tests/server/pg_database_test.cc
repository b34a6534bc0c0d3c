// PostgreSQL's schema migrations (applied once, also when servers start at once; a newer schema
// refused) and the pool's reconnection after the database restarts.
#include <gtest/gtest.h>

#include <thread>

#include "idms/server/postgres.h"
#include "pg_cluster.h"

namespace idms::server {
namespace {

using namespace std::chrono_literals;

#define IDMS_REQUIRE_POSTGRES()                                                                             \
  if (!test::PgCluster::BinDir()) GTEST_SKIP() << "PostgreSQL is not installed (initdb, pg_ctl, postgres)"; \
  test::PgCluster pg;                                                                                       \
  ASSERT_TRUE(pg.ok()) << pg.error()

TEST(PostgresMigrations, AFreshDatabaseGetsTheSchemaAndASecondStartAppliesNothing) {
  IDMS_REQUIRE_POSTGRES();
  std::string error;
  EXPECT_EQ(MigratePostgres(pg.Url(), &error), PostgresSchemaVersion()) << error;
  EXPECT_EQ(pg.Psql("postgres", "SELECT string_agg(version::text, ',' ORDER BY version) FROM schema_migrations"),
            "1,2");
  EXPECT_EQ(pg.Psql("postgres",
                    "SELECT string_agg(tablename, ',' ORDER BY tablename) FROM pg_tables WHERE schemaname = 'public'"),
            "logins,model_names,model_versions,schema_migrations,session_leases,session_notes,sessions");
  EXPECT_EQ(MigratePostgres(pg.Url(), &error), 0) << error;
  EXPECT_EQ(pg.Psql("postgres", "SELECT count(*) FROM schema_migrations"), std::to_string(PostgresSchemaVersion()));
}

// Servers started at once: the advisory lock lets one apply each migration; the others wait, then
// find it applied. Nobody fails, nothing is applied twice.
TEST(PostgresMigrations, ServersStartingAtOnceApplyEachMigrationOnce) {
  IDMS_REQUIRE_POSTGRES();
  for (int round = 0; round < 3; ++round) {
    const std::string url = pg.CreateDatabase("race" + std::to_string(round));
    ASSERT_FALSE(url.empty()) << pg.error();
    constexpr int kServers = 6;
    std::vector<int> applied(kServers, -2);
    std::vector<std::string> errors(kServers);
    std::vector<std::thread> threads;
    for (int i = 0; i < kServers; ++i) {
      threads.emplace_back([&, i] { applied[i] = MigratePostgres(url, &errors[i]); });
    }
    for (std::thread& t : threads) t.join();
    int total = 0;
    for (int i = 0; i < kServers; ++i) {
      EXPECT_GE(applied[i], 0) << errors[i];
      total += applied[i];
    }
    EXPECT_EQ(total, PostgresSchemaVersion());
    EXPECT_EQ(pg.Psql("race" + std::to_string(round), "SELECT count(*) FROM schema_migrations"),
              std::to_string(PostgresSchemaVersion()));
  }
}

// A database a newer server migrated: this one refuses it, saying why, and changes nothing.
TEST(PostgresMigrations, ASchemaNewerThanTheServerIsRefused) {
  IDMS_REQUIRE_POSTGRES();
  std::string error;
  ASSERT_EQ(MigratePostgres(pg.Url(), &error), PostgresSchemaVersion()) << error;
  ASSERT_TRUE(pg.Psql("postgres", "INSERT INTO schema_migrations(version, what) VALUES (999, 'from the future')"));
  EXPECT_EQ(MigratePostgres(pg.Url(), &error), -1);
  EXPECT_NE(error.find("version 999, newer than this server's " + std::to_string(PostgresSchemaVersion())),
            std::string::npos)
      << error;
  PostgresStores stores;
  EXPECT_FALSE(OpenPostgres(pg.Url(), 3600s, 1, &stores, &error));
  EXPECT_EQ(pg.Psql("postgres", "SELECT count(*) FROM schema_migrations"), std::to_string(PostgresSchemaVersion() + 1));
}

TEST(PostgresMigrations, AnUnreachableDatabaseIsAClearError) {
  IDMS_REQUIRE_POSTGRES();
  ASSERT_TRUE(pg.Stop()) << pg.error();
  std::string error;
  PostgresStores stores;
  EXPECT_FALSE(OpenPostgres(pg.Url(), 3600s, 1, &stores, &error));
  EXPECT_NE(error.find("PostgreSQL"), std::string::npos) << error;
  EXPECT_NE(error.find(std::to_string(pg.port())), std::string::npos) << error;
}

// The database restarts under open stores: calls throw StoreUnavailable while it is down (at
// once, not after a timeout), and work again by themselves once it is back.
TEST(PostgresPool, StoresThrowStoreUnavailableWhileTheDatabaseIsDownAndRecoverByThemselves) {
  IDMS_REQUIRE_POSTGRES();
  PostgresStores stores;
  std::string error;
  ASSERT_TRUE(OpenPostgres(pg.Url(), 3600s, 2, &stores, &error)) << error;
  ModelVersion v;
  v.name = "m";
  v.fem_sha256 = v.plg_sha256 = v.obj_sha256 = std::string(64, 'a');
  ASSERT_TRUE(stores.models->AddVersion(&v, &error)) << error;
  EXPECT_EQ(stores.models->NumModels(), 1);
  // A login this server has seen.
  const Digest token = DigestOf("a-token-of-sixteen-or-more");
  const std::string cookie = stores.logins->Create(token);
  ASSERT_EQ(stores.logins->Find(cookie), token);
  ASSERT_TRUE(pg.Stop()) << pg.error();
  const auto down = std::chrono::steady_clock::now();
  EXPECT_THROW(stores.models->ListLatest(), StoreUnavailable);
  EXPECT_THROW(stores.sessions->List(), StoreUnavailable);
  // A login seen before stays valid while the database is down (browsers keep watching); an
  // unknown cookie cannot be checked.
  EXPECT_THROW(stores.logins->Find("cookie"), StoreUnavailable);
  EXPECT_THROW(stores.leases->Acquire("s", "node", 1000ms), StoreUnavailable);
  // A session that ends during the outage: its row is kept and stored once the database is back.
  SessionRow row;
  row.id = "s";
  row.state = "ended";
  EXPECT_THROW(stores.sessions->Put(row, &error), StoreUnavailable);
  EXPECT_LT(std::chrono::steady_clock::now() - down, 1s) << "failing takes no connection timeout";
  std::this_thread::sleep_for(2100ms);  // past the 2 s in which a login is trusted without asking
  EXPECT_EQ(stores.logins->Find(cookie), token);
  ASSERT_TRUE(pg.Start()) << pg.error();
  // Back: within the 250 ms the pool waits after a failed attempt.
  const auto up = std::chrono::steady_clock::now();
  int64_t models = -1;
  while (std::chrono::steady_clock::now() - up < 5s) {
    try {
      models = stores.models->NumModels();
      break;
    } catch (const StoreUnavailable&) {
      std::this_thread::sleep_for(20ms);
    }
  }
  EXPECT_EQ(models, 1);
  const double recovered_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - up).count();
  std::printf("stores answered again %.0f ms after PostgreSQL was back\n", recovered_ms);
  RecordProperty("recovered_ms", static_cast<int>(recovered_ms));
  PostgresStores other;  // another server
  ASSERT_TRUE(OpenPostgres(pg.Url(), 3600s, 1, &other, &error)) << error;
  EXPECT_FALSE(other.sessions->Get("s")) << "not stored until this index reaches the database";
  ASSERT_EQ(stores.sessions->List().size(), 1u);
  ASSERT_TRUE(other.sessions->Get("s"));
  EXPECT_EQ(other.sessions->Get("s")->state, "ended");
  EXPECT_EQ(stores.leases->Acquire("s", "node", 1000ms), 1);
}

}  // namespace
}  // namespace idms::server
