// The real idms-server with --store on a real PostgreSQL (started by the test): logins that survive
// a restart and that a second server honours, a schema newer than the server refused at start-up,
// and failure 6 of issue 29: the database restarted under a live session (REST 503 with
// Retry-After while it is down, working again by itself; the live stream never stops).
#include <gtest/gtest.h>

#include <csignal>
#include <nlohmann/json.hpp>
#include <thread>

#include "child_process.h"
#include "idms/server/postgres.h"
#include "pg_cluster.h"
#include "server_process.h"
#include "session_checks.h"

namespace idms::test {
namespace {

using json = nlohmann::json;
using namespace std::chrono_literals;

#define IDMS_REQUIRE_POSTGRES()                                                                       \
  if (!PgCluster::BinDir()) GTEST_SKIP() << "PostgreSQL is not installed (initdb, pg_ctl, postgres)"; \
  PgCluster pg;                                                                                       \
  ASSERT_TRUE(pg.ok()) << pg.error()

HttpReply WithCookie(uint16_t port, const std::string& target, const std::string& cookie) {
  return Http(port, HttpCall{"GET", target, {{"Cookie", cookie}}, ""});
}

TEST(PostgresServer, LoginsSurviveARestartAndAnotherServerHonoursThem) {
  IDMS_REQUIRE_POSTGRES();
  const std::string dir = TempDir("pg-logins");
  const std::vector<std::string> store = {"--store", pg.Url(), "--models-dir", "none"};
  auto a = std::make_unique<ServerProcess>(dir + "/a", store);
  ASSERT_TRUE(a->ready()) << a->Log();
  const std::string admin = a->Token("admin");
  const HttpReply login = Http(
      a->port(), HttpCall{"POST", "/api/login", {{"Content-Type", "application/json"}}, json{{"token", admin}}.dump()});
  ASSERT_EQ(login.status, 200) << login.body;
  const std::string set_cookie = login.headers.at("set-cookie");
  const std::string cookie = set_cookie.substr(0, set_cookie.find(';'));
  ASSERT_EQ(WithCookie(a->port(), "/api/whoami", cookie).status, 200);
  // The same server restarted (SIGTERM, then a new process): the cookie still logs in.
  a->process().Signal(SIGTERM);
  ASSERT_EQ(a->process().Wait(30s), 0) << a->Log();
  a = std::make_unique<ServerProcess>(dir + "/a", store);
  ASSERT_TRUE(a->ready()) << a->Log();
  const HttpReply again = WithCookie(a->port(), "/api/whoami", cookie);
  ASSERT_EQ(again.status, 200) << again.body;
  EXPECT_EQ(json::parse(again.body)["role"], "admin");
  EXPECT_EQ(json::parse(again.body)["via"], "cookie");
  // A second server on the same database (its own --data, the same tokens file) honours it, and a
  // logout there ends it on the first.
  std::vector<std::string> b_args = store;
  b_args.insert(b_args.end(), {"--tokens", dir + "/a/tokens"});
  ServerProcess b(dir + "/b", b_args);
  ASSERT_TRUE(b.ready()) << b.Log();
  EXPECT_EQ(WithCookie(b.port(), "/api/whoami", cookie).status, 200);
  const HttpReply logout = Http(
      b.port(),
      HttpCall{"POST", "/api/logout", {{"Cookie", cookie}, {"Origin", "http://127.0.0.1:" + b.port_string()}}, ""});
  EXPECT_EQ(logout.status, 200) << logout.body;
  EXPECT_EQ(WithCookie(b.port(), "/api/whoami", cookie).status, 401);
  // The first server trusts a login it checked for 2 s before asking again.
  const auto logged_out = std::chrono::steady_clock::now();
  EXPECT_TRUE(Eventually([&] { return WithCookie(a->port(), "/api/whoami", cookie).status == 401; }, 5000ms));
  EXPECT_LT(std::chrono::steady_clock::now() - logged_out, 2500ms);
  // Only digests in the database and no cookie in either log.
  EXPECT_EQ(pg.Psql("postgres", "SELECT count(*) FROM logins"), "0");
  const std::string value = cookie.substr(cookie.find('=') + 1);
  EXPECT_EQ(a->Log().find(value), std::string::npos);
  EXPECT_EQ(b.Log().find(value), std::string::npos);
}

TEST(PostgresServer, AServerRefusesASchemaNewerThanItKnows) {
  IDMS_REQUIRE_POSTGRES();
  const std::string dir = TempDir("pg-newer");
  {
    ServerProcess first(dir + "/data", {"--store", pg.Url(), "--models-dir", "none"});
    ASSERT_TRUE(first.ready()) << first.Log();
  }
  ASSERT_TRUE(pg.Psql("postgres", "INSERT INTO schema_migrations(version, what) VALUES (999, 'from the future')"));
  ServerProcess second(dir + "/data", {"--store", pg.Url(), "--models-dir", "none"});
  EXPECT_FALSE(second.ready());
  EXPECT_EQ(second.process().Wait(30s), 1);
  EXPECT_NE(second.Log().find("version 999, newer than this server's"), std::string::npos) << second.Log();
}

// Three servers started at once on a fresh database: all start, and each migration is applied by
// one of them (one transaction each: different servers may apply different ones).
TEST(PostgresServer, ServersStartingAtOnceOnAFreshDatabaseAllStartAndTheSchemaIsAppliedOnce) {
  IDMS_REQUIRE_POSTGRES();
  const std::string dir = TempDir("pg-together");
  constexpr int kServers = 3;
  std::vector<std::unique_ptr<ServerProcess>> servers(kServers);
  std::vector<std::thread> starting;
  for (int i = 0; i < kServers; ++i) {
    starting.emplace_back([&, i] {
      servers[static_cast<size_t>(i)] = std::make_unique<ServerProcess>(
          dir + "/" + std::to_string(i), std::vector<std::string>{"--store", pg.Url(), "--models-dir", "none"});
    });
  }
  for (std::thread& t : starting) t.join();
  int applied = 0;
  for (const auto& s : servers) {
    ASSERT_TRUE(s->ready()) << s->Log();
    EXPECT_EQ(Get(s->port(), "/api/models", s->Token("observer")).status, 200);
    const std::string log = s->Log();
    for (size_t at = log.find("applied a schema migration"); at != std::string::npos;
         at = log.find("applied a schema migration", at + 1))
      ++applied;
  }
  EXPECT_EQ(applied, idms::server::PostgresSchemaVersion());
  EXPECT_EQ(pg.Psql("postgres", "SELECT count(*) FROM schema_migrations"),
            std::to_string(idms::server::PostgresSchemaVersion()));
}

// Issue 29, failure 6: PostgreSQL stopped under a live session and started again.
TEST(PostgresServer, TheDatabaseRestartedUnderALiveSessionRestAnswers503ThenRecoversStreamsNeverStop) {
  IDMS_REQUIRE_POSTGRES();
  const std::string dir = TempDir("pg-restart");
  ServerProcess server(dir + "/data", {"--store", pg.Url()});
  ASSERT_TRUE(server.ready()) << server.Log();
  const uint16_t port = server.port();
  const std::string observer = server.Token("observer");
  // A real agent with a scripted device, in real time, and a viewer watching.
  ChildProcess agent(IDMS_AGENT_BIN,
                     {"--server", "ws://127.0.0.1:" + server.port_string(), "--token", server.Token("agent"), "--model",
                      "hex_4x5_home", "--device", "scripted:palpate", "--duration", "10", "--cache-dir", dir + "/cache",
                      "--summary-json", dir + "/summary.json"},
                     dir + "/agent.log");
  const std::string id = WaitForLiveSession(port, observer, 200);
  ASSERT_FALSE(id.empty()) << server.Log() << agent.Log();
  TestViewer viewer(port, id, observer);
  ASSERT_TRUE(Eventually([&] { return viewer.Frames().size() >= 20; })) << server.Log();
  ASSERT_EQ(Get(port, "/api/models", observer).status, 200);
  // A browser logged in (its cookie checked once, as a page load does).
  const HttpReply browser = Http(
      port, HttpCall{"POST", "/api/login", {{"Content-Type", "application/json"}}, json{{"token", observer}}.dump()});
  ASSERT_EQ(browser.status, 200) << browser.body;
  const std::string cookie = browser.headers.at("set-cookie").substr(0, browser.headers.at("set-cookie").find(';'));
  ASSERT_EQ(WithCookie(port, "/api/whoami", cookie).status, 200);

  // Down: the REST routes that need the database answer 503 + Retry-After at once.
  ASSERT_TRUE(pg.Stop()) << pg.error();
  const auto down = std::chrono::steady_clock::now();
  const size_t frames_at_stop = viewer.Frames().size();
  for (const char* target : {"/api/models", "/api/sessions", "/api/models/hex_4x5_home"}) {
    const HttpReply r = Get(port, target, observer);
    EXPECT_EQ(r.status, 503) << target << ": " << r.body;
    EXPECT_EQ(r.headers.count("retry-after") ? r.headers.at("retry-after") : "", "1") << target;
    EXPECT_TRUE(json::parse(r.body, nullptr, false).contains("error")) << r.body;
  }
  const HttpReply login = Http(
      port, HttpCall{"POST", "/api/login", {{"Content-Type", "application/json"}}, json{{"token", observer}}.dump()});
  EXPECT_EQ(login.status, 503) << login.body;
  EXPECT_EQ(Get(port, "/api/health", "").status, 200) << "the health check needs no database";
  EXPECT_EQ(MetricValue(port, observer, "idms_store_available"), 0);
  // The live stream goes on: the viewer's frames keep coming, sampled every 50 ms for 3 s.
  size_t last = viewer.Frames().size();
  auto last_growth = std::chrono::steady_clock::now();
  double longest_stall_ms = 0;
  while (std::chrono::steady_clock::now() - down < 3s) {
    std::this_thread::sleep_for(50ms);
    const size_t n = viewer.Frames().size();
    const auto now = std::chrono::steady_clock::now();
    if (n > last) {
      longest_stall_ms =
          std::max(longest_stall_ms, std::chrono::duration<double, std::milli>(now - last_growth).count());
      last = n;
      last_growth = now;
    }
  }
  const size_t frames_while_down = viewer.Frames().size() - frames_at_stop;
  // A browser that reconnects its viewer now, 3 s into the outage, is let in on its known cookie.
  const WsResult rejoin = WsConnect(port, "/ws/session/" + id, {{"Cookie", cookie}});
  EXPECT_EQ(rejoin.status, 101) << rejoin.error;
  EXPECT_EQ(WithCookie(port, "/api/models", cookie).status, 503);
  EXPECT_FALSE(viewer.closed());
  EXPECT_GT(frames_while_down, 60u) << "frames while the database was down";
  EXPECT_LT(longest_stall_ms, 500) << "the viewer's longest wait for a frame while the database was down";

  // Back: the REST routes recover by themselves (no restart, no request of ours but retries).
  ASSERT_TRUE(pg.Start()) << pg.error();
  const auto up = std::chrono::steady_clock::now();
  ASSERT_TRUE(Eventually([&] { return Get(port, "/api/models", observer).status == 200; }, 10000ms)) << server.Log();
  const double recover_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - up).count();
  EXPECT_EQ(Get(port, "/api/sessions", observer).status, 200);
  EXPECT_EQ(MetricValue(port, observer, "idms_store_available"), 1);
  // The session ends normally and its row reaches the database.
  EXPECT_EQ(agent.Wait(60s), 0) << agent.Log();
  ASSERT_TRUE(Eventually([&] { return Sessions(port, observer)[0]["state"] == "ended"; })) << server.Log();
  EXPECT_EQ(viewer.gaps(), 0) << "no delta the viewer could not apply";
  std::printf(
      "database down for %.1f s: %zu frames reached the viewer meanwhile, longest wait %.0f ms; REST answered 200 "
      "%.0f ms after PostgreSQL was back\n",
      std::chrono::duration<double>(up - down).count(), frames_while_down, longest_stall_ms, recover_ms);
  RecordProperty("frames_while_down", static_cast<int>(frames_while_down));
  RecordProperty("longest_stall_ms", static_cast<int>(longest_stall_ms));
  RecordProperty("recover_ms", static_cast<int>(recover_ms));
}

}  // namespace
}  // namespace idms::test
