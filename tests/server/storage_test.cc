// The data directory's stores: crash leftovers collected at start-up, an older session index and
// model library brought up to date.
#include "idms/server/storage.h"

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <filesystem>
#include <fstream>

#include "child_process.h"
#include "store_checks.h"

namespace idms::server {
namespace {

namespace fs = std::filesystem;

using test::TestModelVersion;

// The BlobStore contract (content addressing, idempotent puts, listing) on the directory and on S3
// is in s3_blob_store_test.cc.

TEST(Storage, StartUpRemovesTemporaryFilesAndBlobsNoRowNames) {
  const std::string dir = test::TempDir("storage-gc");
  std::string error, kept, orphan;
  {
    Storage s;
    ASSERT_TRUE(OpenStorage(dir, &s, &error)) << error;
    ASSERT_TRUE(s.blobs->Put("kept", &kept, &error));
    ASSERT_TRUE(s.blobs->Put("orphan", &orphan, &error));
    ModelVersion v = TestModelVersion("m", kept);
    ASSERT_TRUE(s.models->AddVersion(&v, &error)) << error;
  }
  // What a SIGKILL mid-upload leaves: a temporary file.
  std::ofstream(fs::path(dir) / "blobs" / "tmp" / "partial.123") << "half";
  Storage s;
  ASSERT_TRUE(OpenStorage(dir, &s, &error)) << error;
  EXPECT_TRUE(s.blobs->Has(kept));
  EXPECT_FALSE(s.blobs->Has(orphan));
  EXPECT_TRUE(fs::is_empty(fs::path(dir) / "blobs" / "tmp"));
}

// The stores' contract (versions, order, notes), for SQLite and PostgreSQL alike, is in
// pg_store_test.cc.

// A database written before sessions had a trainee opens with the column added, its rows kept.
TEST(SqliteSessionIndex, ADatabaseFromBeforeTheTraineeColumnIsBroughtUpToDate) {
  const std::string dir = test::TempDir("sqlite-old-sessions");
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open((dir + "/idms.db").c_str(), &db), SQLITE_OK);
    ASSERT_EQ(sqlite3_exec(db,
                           "CREATE TABLE sessions (id TEXT PRIMARY KEY, state TEXT NOT NULL, model TEXT NOT NULL, "
                           "device TEXT NOT NULL, identity TEXT NOT NULL, started TEXT NOT NULL, duration_s REAL NOT "
                           "NULL, samples INTEGER NOT NULL, next_tick INTEGER NOT NULL, resume_sha256 TEXT NOT NULL, "
                           "recording TEXT NOT NULL, summary_json TEXT NOT NULL, scene_text TEXT NOT NULL);"
                           "INSERT INTO sessions VALUES ('old', 'ended', 'hex', 'scripted', 'agent', "
                           "'2026-11-01T10:00:00Z', 3.5, 3500, 3500, '', 'old.mcap', '{}', '');",
                           nullptr, nullptr, nullptr),
              SQLITE_OK);
    sqlite3_close(db);
  }
  std::string error;
  auto index = OpenSqliteSessionIndex(dir + "/idms.db", &error);
  ASSERT_TRUE(index) << error;
  std::optional<SessionRow> old = index->Get("old");
  ASSERT_TRUE(old);
  EXPECT_EQ(old->samples, 3500);
  EXPECT_EQ(old->trainee, "");
  old->trainee = "Ada";
  ASSERT_TRUE(index->Put(*old, &error)) << error;
  EXPECT_EQ(index->Get("old")->trainee, "Ada");
}

TEST(SqliteModelStore, ALibraryFromBeforeTheMetadataColumnIsBroughtUpToDate) {
  const std::string dir = test::TempDir("sqlite-old-models");
  const std::string sha(64, 'a');
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open((dir + "/idms.db").c_str(), &db), SQLITE_OK);
    const std::string sql =
        "CREATE TABLE model_names (name TEXT PRIMARY KEY, next_version INTEGER NOT NULL);"
        "CREATE TABLE model_versions (name TEXT NOT NULL, version INTEGER NOT NULL, description TEXT NOT NULL, "
        "created TEXT NOT NULL, atoms INTEGER NOT NULL, elements INTEGER NOT NULL, triangles INTEGER NOT NULL, "
        "bytes INTEGER NOT NULL, fem_sha256 TEXT NOT NULL, plg_sha256 TEXT NOT NULL, obj_sha256 TEXT NOT NULL, "
        "PRIMARY KEY (name, version));"
        "INSERT INTO model_names VALUES ('hex', 2);"
        "INSERT INTO model_versions VALUES ('hex', 1, 'typed in', '2026-11-01T10:00:00Z', 20, 30, 12, 900, '" +
        sha + "', '" + sha + "', '" + sha + "');";
    ASSERT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK);
    sqlite3_close(db);
  }
  std::string error;
  auto store = OpenSqliteModelStore(dir + "/idms.db", &error);
  ASSERT_TRUE(store) << error;
  ASSERT_TRUE(store->Get("hex"));
  EXPECT_EQ(store->Get("hex")->latest().description, "typed in");
  EXPECT_EQ(store->Get("hex")->latest().metadata, "");
  ModelVersion fitted = TestModelVersion("hex", std::string(64, 'b'));
  fitted.metadata = R"({"fit":{}})";
  ASSERT_TRUE(store->AddVersion(&fitted, &error)) << error;
  EXPECT_EQ(fitted.version, 2);
  EXPECT_EQ(store->Get("hex")->latest().metadata, R"({"fit":{}})");
}

}  // namespace
}  // namespace idms::server
