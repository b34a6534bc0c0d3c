// The stores' contract, run against both back ends: SQLite (the default) and PostgreSQL (a real
// server started by the test). Model versions never reused, the library's order and totals, the
// session index's order, notes stored with their row or not at all, logins that expire and that
// a second server sees, and ownership leases that two nodes can never both hold.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>

#include "child_process.h"
#include "idms/server/auth.h"
#include "idms/server/postgres.h"
#include "idms/server/storage.h"
#include "pg_cluster.h"
#include "store_checks.h"

namespace idms::server {
namespace {

using namespace std::chrono_literals;

enum class Backend { kSqlite, kPostgres };

std::string BackendName(const testing::TestParamInfo<Backend>& info) {
  return info.param == Backend::kSqlite ? "Sqlite" : "Postgres";
}

using test::TestModelVersion;

// One "server's" view of the stores: SQLite on a file, or a new pool on the shared database.
struct Opened {
  std::unique_ptr<ModelStore> models;
  std::unique_ptr<SessionIndex> sessions;
  std::unique_ptr<LoginSessions> logins;
  std::unique_ptr<LeaseStore> leases;
};

class Stores : public testing::TestWithParam<Backend> {
 protected:
  void SetUp() override {
    if (GetParam() == Backend::kPostgres) {
      if (!test::PgCluster::BinDir()) GTEST_SKIP() << "PostgreSQL is not installed (initdb, pg_ctl, postgres)";
      pg_ = std::make_unique<test::PgCluster>();
      ASSERT_TRUE(pg_->ok()) << pg_->error();
    } else {
      dir_ = test::TempDir("stores");
    }
  }

  // Each call opens the stores anew: a reopen, or (PostgreSQL) a second server on the same data.
  Opened Open(std::chrono::seconds login_lifetime = 3600s) {
    Opened o;
    std::string error;
    if (GetParam() == Backend::kSqlite) {
      o.models = OpenSqliteModelStore(dir_ + "/idms.db", &error);
      o.sessions = OpenSqliteSessionIndex(dir_ + "/idms.db", &error);
      o.logins = std::make_unique<MemoryLoginSessions>(login_lifetime);
      o.leases = MakeMemoryLeaseStore();
      EXPECT_TRUE(o.models && o.sessions) << error;
    } else {
      PostgresStores s;
      EXPECT_TRUE(OpenPostgres(pg_->Url(), login_lifetime, 2, &s, &error)) << error;
      o = {std::move(s.models), std::move(s.sessions), std::move(s.logins), std::move(s.leases)};
    }
    return o;
  }

  std::string dir_;
  std::unique_ptr<test::PgCluster> pg_;
};

INSTANTIATE_TEST_SUITE_P(Backends, Stores, testing::Values(Backend::kSqlite, Backend::kPostgres), BackendName);

// A version's metadata (a fit's report) is stored and read back by Get, on a reopen too; the list
// of latest versions leaves it out.
TEST_P(Stores, AVersionsMetadataIsKeptAndTheListLeavesItOut) {
  std::string error;
  {
    Opened o = Open();
    ASSERT_TRUE(o.models);
    ModelVersion a = TestModelVersion("m", std::string(64, '1')), b = TestModelVersion("m", std::string(64, '2'));
    b.metadata = R"({"fit":{"session":"s1","names":["home_k"],"scale":[1.25]}})";
    ASSERT_TRUE(o.models->AddVersion(&a, &error)) << error;
    ASSERT_TRUE(o.models->AddVersion(&b, &error)) << error;
  }
  Opened o = Open();
  const std::optional<ModelRecord> rec = o.models->Get("m");
  ASSERT_TRUE(rec);
  ASSERT_EQ(rec->versions.size(), 2u);
  EXPECT_EQ(rec->versions[0].metadata, "");
  EXPECT_EQ(rec->versions[1].metadata, R"({"fit":{"session":"s1","names":["home_k"],"scale":[1.25]}})");
  const std::vector<ModelVersion> list = o.models->ListLatest();
  ASSERT_EQ(list.size(), 1u);
  EXPECT_EQ(list[0].version, 2);
  EXPECT_EQ(list[0].metadata, "");
}

TEST_P(Stores, ModelVersionsCountUpAndAreNeverReusedAfterDelete) {
  Opened o = Open();
  ASSERT_TRUE(o.models);
  ModelStore& store = *o.models;
  std::string error;
  ModelVersion a = TestModelVersion("m", std::string(64, '1')), b = TestModelVersion("m", std::string(64, '2'));
  ASSERT_TRUE(store.AddVersion(&a, &error)) << error;
  ASSERT_TRUE(store.AddVersion(&b, &error)) << error;
  EXPECT_EQ(a.version, 1);
  EXPECT_EQ(b.version, 2);
  ASSERT_TRUE(store.Get("m"));
  EXPECT_EQ(store.Get("m")->versions.size(), 2u);
  EXPECT_EQ(store.Get("m")->latest().fem_sha256, std::string(64, '2'));
  EXPECT_EQ(store.NumModels(), 1);
  EXPECT_EQ(store.LibraryBytes(), 20);
  // Delete one version, then the model; the next upload is version 3, not 1.
  EXPECT_TRUE(store.Delete("m", 2));
  EXPECT_FALSE(store.Delete("m", 2));
  EXPECT_EQ(store.Get("m")->latest().version, 1);
  EXPECT_TRUE(store.BlobReferenced(std::string(64, '1')));
  EXPECT_FALSE(store.BlobReferenced(std::string(64, '2')));
  EXPECT_TRUE(store.Delete("m", 0));
  EXPECT_FALSE(store.Get("m"));
  EXPECT_TRUE(store.ListLatest().empty());
  ModelVersion c = TestModelVersion("m", std::string(64, '3'));
  ASSERT_TRUE(store.AddVersion(&c, &error));
  EXPECT_EQ(c.version, 3);
}

TEST_P(Stores, ModelsSurviveReopenAndAreListedLatestByName) {
  std::string error;
  {
    Opened o = Open();
    ASSERT_TRUE(o.models);
    for (const char* n : {"zeta", "alpha", "alpha", "Beta"}) {
      ModelVersion v = TestModelVersion(n, std::string(64, 'a'));
      ASSERT_TRUE(o.models->AddVersion(&v, &error)) << error;
    }
  }
  Opened o = Open();
  ASSERT_TRUE(o.models);
  const std::vector<ModelVersion> list = o.models->ListLatest();
  ASSERT_EQ(list.size(), 3u);
  // By the names' bytes, whatever the database's locale: upper case first.
  EXPECT_EQ(list[0].name, "Beta");
  EXPECT_EQ(list[1].name, "alpha");
  EXPECT_EQ(list[1].version, 2);
  EXPECT_EQ(list[2].name, "zeta");
  EXPECT_FALSE(list[1].created.empty());
}

// Two writers adding versions of one name at once (two servers' uploads) never get the same number.
TEST_P(Stores, ConcurrentUploadsOfOneNameGetDistinctVersions) {
  Opened a = Open(), b = Open();
  ASSERT_TRUE(a.models && b.models);
  std::vector<int64_t> got_a, got_b;
  auto upload = [](ModelStore* store, std::vector<int64_t>* got) {
    for (int i = 0; i < 20; ++i) {
      ModelVersion v = TestModelVersion("shared", std::string(64, 'e'));
      std::string error;
      if (store->AddVersion(&v, &error)) got->push_back(v.version);
    }
  };
  std::thread ta(upload, a.models.get(), &got_a), tb(upload, b.models.get(), &got_b);
  ta.join();
  tb.join();
  std::vector<int64_t> all = got_a;
  all.insert(all.end(), got_b.begin(), got_b.end());
  std::sort(all.begin(), all.end());
  ASSERT_EQ(all.size(), 40u);
  for (size_t i = 0; i < all.size(); ++i) EXPECT_EQ(all[i], static_cast<int64_t>(i) + 1);
}

// Sessions started within one second (an agent restarted at once) are listed newest first: their
// start has milliseconds, not a tie broken by the random part of their ids.
TEST_P(Stores, SessionsStartedWithinOneSecondAreListedNewestFirst) {
  Opened o = Open();
  ASSERT_TRUE(o.sessions);
  std::string error;
  // Ids in the opposite order to the starts, so that a tie on the start lists the older first.
  for (const char* id : {"2026-11-27-ffffff", "2026-11-27-000000"}) {
    SessionRow row;
    row.id = id;
    row.state = "live";
    row.started = UtcNowMs();
    ASSERT_TRUE(o.sessions->Put(row, &error)) << error;
    std::this_thread::sleep_for(5ms);
  }
  const std::vector<SessionRow> list = o.sessions->List();
  ASSERT_EQ(list.size(), 2u);
  EXPECT_EQ(list[0].id, "2026-11-27-000000") << "started " << list[0].started << " and " << list[1].started;
  EXPECT_LT(list[1].started, list[0].started);
}

TEST_P(Stores, ASessionRowComesBackWholeAndPutReplacesIt) {
  Opened o = Open();
  ASSERT_TRUE(o.sessions);
  SessionRow r;
  r.id = "2026-11-28-abcdef";
  r.state = "live";
  r.model = "hex_4x5_home@2";
  r.device = "scripted:palpate";
  r.identity = "idms-agent 0.1 pid 7";
  r.started = "2026-11-28T05:00:00.123Z";
  r.duration_s = 12.625;
  r.samples = 12625;
  r.next_tick = (uint64_t{1} << 62) + 5;
  r.resume_sha256 = std::string(64, 'f');
  r.recording = r.id + ".live.mcap";
  r.summary_json = R"({"peak_force_n":1.5,"notes":0})";
  r.scene_text = "model: \"hex_4x5_home\"\nrate_hz: 1000\n";
  r.trainee = "Ada Lovelace é";
  std::string error;
  ASSERT_TRUE(o.sessions->Put(r, &error)) << error;
  std::optional<SessionRow> back = o.sessions->Get(r.id);
  ASSERT_TRUE(back);
  EXPECT_EQ(back->state, r.state);
  EXPECT_EQ(back->model, r.model);
  EXPECT_EQ(back->device, r.device);
  EXPECT_EQ(back->identity, r.identity);
  EXPECT_EQ(back->started, r.started);
  EXPECT_EQ(back->duration_s, r.duration_s);
  EXPECT_EQ(back->samples, r.samples);
  EXPECT_EQ(back->next_tick, r.next_tick);
  EXPECT_EQ(back->resume_sha256, r.resume_sha256);
  EXPECT_EQ(back->recording, r.recording);
  EXPECT_EQ(back->summary_json, r.summary_json);
  EXPECT_EQ(back->scene_text, r.scene_text);
  EXPECT_EQ(back->trainee, r.trainee);
  r.state = "ended";
  r.recording = r.id + ".mcap";
  ASSERT_TRUE(o.sessions->Put(r, &error)) << error;
  EXPECT_EQ(o.sessions->Get(r.id)->state, "ended");
  EXPECT_EQ(o.sessions->List().size(), 1u);
  EXPECT_FALSE(o.sessions->Get("nope"));
  EXPECT_TRUE(o.sessions->Delete(r.id));
  EXPECT_FALSE(o.sessions->Delete(r.id));
}

// A note added after the end is stored with its row (the notes counter in its summary) or not at
// all: a note whose id is taken leaves the row as it was.
TEST_P(Stores, ANoteIsStoredWithItsRowOrNotAtAll) {
  Opened o = Open();
  ASSERT_TRUE(o.sessions);
  SessionIndex& index = *o.sessions;
  std::string error;
  SessionRow row;
  row.id = "s1";
  row.state = "ended";
  row.summary_json = R"({"notes":1})";
  ASSERT_TRUE(index.PutWithNote(row, SessionNote{1, 0.5, "first", "admin 127.0.0.1:1", "2026-11-28T01:00:00Z"}, &error))
      << error;
  row.summary_json = R"({"notes":2})";
  EXPECT_FALSE(index.PutWithNote(row, SessionNote{1, 0.7, "same id", "admin", "x"}, &error));
  EXPECT_TRUE(error.find("UNIQUE") != std::string::npos || error.find("unique") != std::string::npos) << error;
  EXPECT_EQ(index.Get("s1")->summary_json, R"({"notes":1})") << "the row rolled back with the note";
  ASSERT_TRUE(index.PutWithNote(row, SessionNote{2, 0.25, "second", "observer", "y"}, &error)) << error;
  const std::vector<SessionNote> notes = index.Notes("s1");
  ASSERT_EQ(notes.size(), 2u);
  EXPECT_EQ(notes[0].text, "first");
  EXPECT_EQ(notes[1].time_s, 0.25);
  EXPECT_EQ(notes[0].author, "admin 127.0.0.1:1");
  EXPECT_TRUE(index.Notes("other").empty());
  ASSERT_TRUE(index.Delete("s1"));
  EXPECT_TRUE(index.Notes("s1").empty());
}

TEST_P(Stores, LoginCookiesStandForTheirTokenAndExpire) {
  Opened o = Open();
  LoginSessions& logins = *o.logins;
  const Digest d = DigestOf("some-token-value-123");
  const std::string cookie = logins.Create(d);
  ASSERT_TRUE(logins.Find(cookie));
  EXPECT_EQ(*logins.Find(cookie), d);
  EXPECT_FALSE(logins.Find(cookie + "x"));
  logins.Remove(cookie);
  EXPECT_FALSE(logins.Find(cookie));

  Opened short_lived = Open(0s);
  const std::string gone = short_lived.logins->Create(d);
  EXPECT_FALSE(short_lived.logins->Find(gone));
}

// PostgreSQL's logins are every server's: made on one, found and removed on another; the database
// holds only digests, never the cookie.
TEST(PostgresLogins, ASecondServerSeesTheLoginAndItsLogout) {
  if (!test::PgCluster::BinDir()) GTEST_SKIP() << "PostgreSQL is not installed (initdb, pg_ctl, postgres)";
  test::PgCluster pg;
  ASSERT_TRUE(pg.ok()) << pg.error();
  PostgresStores a, b;
  std::string error;
  ASSERT_TRUE(OpenPostgres(pg.Url(), 3600s, 2, &a, &error)) << error;
  ASSERT_TRUE(OpenPostgres(pg.Url(), 3600s, 2, &b, &error)) << error;
  const Digest d = DigestOf("another-token-value-456");
  const std::string cookie = a.logins->Create(d);
  ASSERT_TRUE(b.logins->Find(cookie));
  EXPECT_EQ(*b.logins->Find(cookie), d);
  const std::optional<std::string> stored =
      pg.Psql("postgres", "SELECT cookie_sha256 || ' ' || token_sha256 FROM logins");
  ASSERT_TRUE(stored) << pg.error();
  EXPECT_EQ(*stored, HexEncode(DigestOf(cookie)) + " " + HexEncode(d));
  EXPECT_EQ(stored->find(cookie), std::string::npos);
  b.logins->Remove(cookie);
  EXPECT_FALSE(a.logins->Find(cookie));
}

// The lease (DESIGN.md "scale"): two nodes; one holds it, the other cannot take it until it
// expires, then gets the next epoch, and the first one's renewal fails from then on.
TEST_P(Stores, ALeaseIsHeldByOneNodeUntilItExpiresThenTheNextEpochIsAnothers) {
  Opened a = Open(), b_own = Open();
  // Two servers: PostgreSQL, two pools on one database; in memory, two nodes of one process.
  LeaseStore& node_a = *a.leases;
  LeaseStore& node_b = GetParam() == Backend::kPostgres ? *b_own.leases : *a.leases;
  constexpr auto kTtl = 400ms;
  const std::optional<int64_t> first = node_a.Acquire("s1", "node-a", kTtl);
  ASSERT_TRUE(first);
  EXPECT_EQ(*first, 1);
  EXPECT_FALSE(node_b.Acquire("s1", "node-b", kTtl)) << "held by node-a";
  std::optional<Lease> holder = node_b.Holder("s1");
  ASSERT_TRUE(holder);
  EXPECT_EQ(holder->holder, "node-a");
  EXPECT_EQ(holder->epoch, 1);
  EXPECT_GT(holder->remaining, 0ms);
  EXPECT_LE(holder->remaining, kTtl);
  EXPECT_TRUE(node_a.Renew("s1", "node-a", 1, kTtl));
  EXPECT_FALSE(node_a.Renew("s1", "node-a", 2, kTtl)) << "a wrong epoch";
  EXPECT_FALSE(node_b.Renew("s1", "node-b", 1, kTtl)) << "not the holder";
  // Another session is independent.
  EXPECT_EQ(node_b.Acquire("s2", "node-b", kTtl), 1);
  // node-a stops renewing: once its lease expires node-b takes it, with the next epoch.
  std::this_thread::sleep_for(kTtl + 100ms);
  EXPECT_FALSE(node_b.Holder("s1")) << "expired";
  const std::optional<int64_t> second = node_b.Acquire("s1", "node-b", kTtl);
  ASSERT_TRUE(second);
  EXPECT_EQ(*second, 2);
  EXPECT_FALSE(node_a.Renew("s1", "node-a", 1, kTtl)) << "node-a lost it: it must stop publishing";
  EXPECT_FALSE(node_a.Acquire("s1", "node-a", kTtl));
  EXPECT_EQ(node_a.Holder("s1")->holder, "node-b");
  // A release hands it over at once; the epoch still grows (never reused).
  node_a.Release("s1", "node-a", 1);  // not the holder: no effect
  EXPECT_EQ(node_a.Holder("s1")->holder, "node-b");
  node_b.Release("s1", "node-b", 2);
  EXPECT_FALSE(node_a.Holder("s1"));
  EXPECT_EQ(node_a.Acquire("s1", "node-a", kTtl), 3);
  // The holder taking it again fences its own earlier epoch.
  EXPECT_EQ(node_a.Acquire("s1", "node-a", kTtl), 4);
  EXPECT_FALSE(node_a.Renew("s1", "node-a", 3, kTtl));
  EXPECT_TRUE(node_a.Renew("s1", "node-a", 4, kTtl));
}

// Many nodes racing for the same free sessions: exactly one wins each, every time.
TEST_P(Stores, NodesRacingForALeaseNeverBothGetIt) {
  constexpr int kNodes = 4, kSessions = 25;
  std::vector<Opened> servers;
  for (int i = 0; i < (GetParam() == Backend::kPostgres ? kNodes : 1); ++i) servers.push_back(Open());
  std::atomic<int> winners[kSessions] = {};
  std::vector<std::thread> threads;
  for (int n = 0; n < kNodes; ++n) {
    LeaseStore* store = servers[static_cast<size_t>(n) % servers.size()].leases.get();
    threads.emplace_back([store, n, &winners] {
      for (int s = 0; s < kSessions; ++s) {
        if (store->Acquire("race-" + std::to_string(s), "node-" + std::to_string(n), 10s)) ++winners[s];
      }
    });
  }
  for (std::thread& t : threads) t.join();
  for (int s = 0; s < kSessions; ++s) EXPECT_EQ(winners[s].load(), 1) << "session " << s;
}

}  // namespace
}  // namespace idms::server
