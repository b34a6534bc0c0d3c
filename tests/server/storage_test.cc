// The blob directory, the SQLite model store and session index: content addressing, crash
// leftovers collected at start-up, version numbers never reused, deletes, the sessions' order.
#include "idms/server/storage.h"

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <filesystem>
#include <fstream>
#include <thread>

#include "child_process.h"

namespace idms::server {
namespace {

namespace fs = std::filesystem;

ModelVersion Version(const std::string& name, const std::string& fem_sha) {
  ModelVersion v;
  v.name = name;
  v.description = "d";
  v.atoms = 3;
  v.bytes = 10;
  v.fem_sha256 = fem_sha;
  v.plg_sha256 = std::string(64, 'b');
  v.obj_sha256 = std::string(64, 'c');
  return v;
}

TEST(BlobDirectory, StoresByContentHashAndReadsBack) {
  const std::string dir = test::TempDir("blobs");
  std::string error, sha;
  auto blobs = OpenBlobDirectory(dir, &error);
  ASSERT_TRUE(blobs) << error;
  ASSERT_TRUE(blobs->Put("hello", &sha, &error)) << error;
  EXPECT_EQ(sha, "2cf24dba5fb0a30e26e83b2ac5b9e29e1b161e5c1fa7425e73043362938b9824");  // sha256("hello")
  std::string back;
  ASSERT_TRUE(blobs->Get(sha, &back));
  EXPECT_EQ(back, "hello");
  EXPECT_TRUE(blobs->Has(sha));
  EXPECT_EQ(blobs->List(), std::vector<std::string>{sha});
  // A second Put of the same bytes is the same blob.
  std::string again;
  ASSERT_TRUE(blobs->Put("hello", &again, &error));
  EXPECT_EQ(again, sha);
  EXPECT_EQ(blobs->List().size(), 1u);
  blobs->Remove(sha);
  EXPECT_FALSE(blobs->Has(sha));
  // Not a hash: never a path.
  EXPECT_FALSE(blobs->Get("../../etc/passwd", &back));
}

TEST(Storage, StartUpRemovesTemporaryFilesAndBlobsNoRowNames) {
  const std::string dir = test::TempDir("storage-gc");
  std::string error, kept, orphan;
  {
    Storage s;
    ASSERT_TRUE(OpenStorage(dir, &s, &error)) << error;
    ASSERT_TRUE(s.blobs->Put("kept", &kept, &error));
    ASSERT_TRUE(s.blobs->Put("orphan", &orphan, &error));
    ModelVersion v = Version("m", kept);
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

TEST(SqliteModelStore, VersionsCountUpAndAreNeverReusedAfterDelete) {
  const std::string dir = test::TempDir("sqlite-versions");
  std::string error;
  auto store = OpenSqliteModelStore(dir + "/idms.db", &error);
  ASSERT_TRUE(store) << error;
  ModelVersion a = Version("m", std::string(64, '1')), b = Version("m", std::string(64, '2'));
  ASSERT_TRUE(store->AddVersion(&a, &error));
  ASSERT_TRUE(store->AddVersion(&b, &error));
  EXPECT_EQ(a.version, 1);
  EXPECT_EQ(b.version, 2);
  ASSERT_TRUE(store->Get("m"));
  EXPECT_EQ(store->Get("m")->versions.size(), 2u);
  EXPECT_EQ(store->Get("m")->latest().fem_sha256, std::string(64, '2'));
  EXPECT_EQ(store->NumModels(), 1);
  EXPECT_EQ(store->LibraryBytes(), 20);
  // Delete one version, then the model; the next upload is version 3, not 1.
  EXPECT_TRUE(store->Delete("m", 2));
  EXPECT_FALSE(store->Delete("m", 2));
  EXPECT_EQ(store->Get("m")->latest().version, 1);
  EXPECT_TRUE(store->BlobReferenced(std::string(64, '1')));
  EXPECT_FALSE(store->BlobReferenced(std::string(64, '2')));
  EXPECT_TRUE(store->Delete("m", 0));
  EXPECT_FALSE(store->Get("m"));
  EXPECT_TRUE(store->ListLatest().empty());
  ModelVersion c = Version("m", std::string(64, '3'));
  ASSERT_TRUE(store->AddVersion(&c, &error));
  EXPECT_EQ(c.version, 3);
}

TEST(SqliteModelStore, SurvivesReopenAndListsLatestByName) {
  const std::string dir = test::TempDir("sqlite-reopen");
  std::string error;
  {
    auto store = OpenSqliteModelStore(dir + "/idms.db", &error);
    ASSERT_TRUE(store) << error;
    for (const char* n : {"zeta", "alpha", "alpha"}) {
      ModelVersion v = Version(n, std::string(64, 'a'));
      ASSERT_TRUE(store->AddVersion(&v, &error));
    }
  }
  auto store = OpenSqliteModelStore(dir + "/idms.db", &error);
  ASSERT_TRUE(store) << error;
  const std::vector<ModelVersion> list = store->ListLatest();
  ASSERT_EQ(list.size(), 2u);
  EXPECT_EQ(list[0].name, "alpha");
  EXPECT_EQ(list[0].version, 2);
  EXPECT_EQ(list[1].name, "zeta");
  EXPECT_FALSE(list[0].created.empty());
}

// Sessions started within one second (an agent restarted at once) are listed newest first: their
// start has milliseconds, not a tie broken by the random part of their ids.
TEST(SqliteSessionIndex, SessionsStartedWithinOneSecondAreListedNewestFirst) {
  const std::string dir = test::TempDir("sqlite-sessions");
  std::string error;
  auto index = OpenSqliteSessionIndex(dir + "/idms.db", &error);
  ASSERT_TRUE(index) << error;
  // Ids in the opposite order to the starts, so that a tie on the start lists the older first.
  for (const char* id : {"2026-11-27-ffffff", "2026-11-27-000000"}) {
    SessionRow row;
    row.id = id;
    row.state = "live";
    row.started = UtcNowMs();
    ASSERT_TRUE(index->Put(row, &error)) << error;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const std::vector<SessionRow> list = index->List();
  ASSERT_EQ(list.size(), 2u);
  EXPECT_EQ(list[0].id, "2026-11-27-000000") << "started " << list[0].started << " and " << list[1].started;
  EXPECT_LT(list[1].started, list[0].started);
}

// A note added after the end is stored with its row (the notes counter in its summary) or not at
// all: a note whose id is taken leaves the row as it was.
TEST(SqliteSessionIndex, ANoteIsStoredWithItsRowOrNotAtAll) {
  const std::string dir = test::TempDir("sqlite-notes");
  std::string error;
  auto index = OpenSqliteSessionIndex(dir + "/idms.db", &error);
  ASSERT_TRUE(index) << error;
  SessionRow row;
  row.id = "s1";
  row.state = "ended";
  row.summary_json = R"({"notes":1})";
  ASSERT_TRUE(
      index->PutWithNote(row, SessionNote{1, 0.5, "first", "admin 127.0.0.1:1", "2026-11-28T01:00:00Z"}, &error))
      << error;
  row.summary_json = R"({"notes":2})";
  EXPECT_FALSE(index->PutWithNote(row, SessionNote{1, 0.7, "same id", "admin", "x"}, &error));
  EXPECT_NE(error.find("UNIQUE"), std::string::npos) << error;
  EXPECT_EQ(index->Get("s1")->summary_json, R"({"notes":1})") << "the row rolled back with the note";
  ASSERT_TRUE(index->PutWithNote(row, SessionNote{2, 0.25, "second", "observer", "y"}, &error)) << error;
  const std::vector<SessionNote> notes = index->Notes("s1");
  ASSERT_EQ(notes.size(), 2u);
  EXPECT_EQ(notes[0].text, "first");
  EXPECT_EQ(notes[1].time_s, 0.25);
  EXPECT_EQ(notes[0].author, "admin 127.0.0.1:1");
  EXPECT_TRUE(index->Notes("other").empty());
  ASSERT_TRUE(index->Delete("s1"));
  EXPECT_TRUE(index->Notes("s1").empty());
}

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

}  // namespace
}  // namespace idms::server
