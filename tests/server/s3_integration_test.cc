// The real idms-server with its blobs (--blobs) and recordings (--recordings) in a real S3 store
// (OpenStack Swift with s3api, started by the test): problems with the store named at start-up; a
// model uploaded through the REST API served by a server with a fresh data directory; the store
// stopped (REST 503 with Retry-After, recovery by itself); a live session's segments stored as it
// runs, its acknowledgements following them and pausing while the store is down (issue 29,
// failure 7), nothing lost; a finished recording downloaded, by ranges too, from another server.
#include <gtest/gtest.h>

#include <csignal>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <thread>

#include "child_process.h"
#include "pg_cluster.h"
#include "server_process.h"
#include "session_checks.h"
#include "swift_s3.h"
#include "test_clients.h"

namespace idms::test {
namespace {

using json = nlohmann::json;
using namespace std::chrono_literals;

#define IDMS_REQUIRE_SWIFT()                                                                                      \
  if (!SwiftS3::Installed()) GTEST_SKIP() << "OpenStack Swift is not installed (swift-proxy, swift-object, ...)"; \
  SwiftS3 swift;                                                                                                  \
  ASSERT_TRUE(swift.ok()) << swift.error()

// The server's credentials come from its environment, which it inherits from the test's.
void SetCredentials(const std::string& access, const std::string& secret) {
  ::setenv("AWS_ACCESS_KEY_ID", access.c_str(), 1);
  ::setenv("AWS_SECRET_ACCESS_KEY", secret.c_str(), 1);
}

const std::string kFem = ReadText(std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home.fem");
const std::string kPlg = ReadText(std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home.plg");

HttpReply Upload(uint16_t port, const std::string& token, const std::string& name) {
  return Http(port, HttpCall{"PUT",
                             "/api/models/" + name,
                             {{"Authorization", "Bearer " + token}, {"Content-Type", "application/json"}},
                             JsonUpload(kFem, kPlg, "through S3")});
}

TEST(S3Server, RefusesToStartWhenTheStoreRefusesOrIsMissingCredentials) {
  IDMS_REQUIRE_SWIFT();
  const std::string dir = TempDir("s3-refused");
  // Wrong secret: S3's own reason, naming the option.
  SetCredentials(SwiftS3::access_key(), "not-the-secret");
  ServerProcess wrong(dir + "/wrong", {"--blobs", swift.Url(), "--models-dir", "none"});
  EXPECT_FALSE(wrong.ready());
  EXPECT_EQ(wrong.process().Wait(30s), 1);
  EXPECT_NE(wrong.Log().find("--blobs: S3 GET idms: 403 SignatureDoesNotMatch"), std::string::npos) << wrong.Log();
  // No bucket of that name.
  SetCredentials(SwiftS3::access_key(), SwiftS3::secret_key());
  ServerProcess absent(dir + "/absent", {"--blobs", swift.Url("absent"), "--models-dir", "none"});
  EXPECT_EQ(absent.process().Wait(30s), 1);
  EXPECT_NE(absent.Log().find("404 NoSuchBucket"), std::string::npos) << absent.Log();
  // No credentials at all.
  ::unsetenv("AWS_SECRET_ACCESS_KEY");
  ServerProcess none(dir + "/none", {"--blobs", swift.Url(), "--models-dir", "none"});
  EXPECT_EQ(none.process().Wait(30s), 1);
  EXPECT_NE(none.Log().find("set AWS_SECRET_ACCESS_KEY in the environment"), std::string::npos) << none.Log();
  // A URL that is not one: refused by the command line.
  ServerProcess bad(dir + "/bad", {"--blobs", "s3://no-port/idms"});
  EXPECT_NE(bad.process().Wait(30s), 0);
  EXPECT_NE(bad.Log().find("expected s3://HOST:PORT/BUCKET"), std::string::npos) << bad.Log();
}

// Several servers share the library: its rows in PostgreSQL, its files in S3. A model uploaded to
// one server is served, byte for byte, by a server with a fresh data directory.
TEST(S3Server, AModelUploadedToOneServerIsServedByAnotherWithAFreshDataDirectory) {
  IDMS_REQUIRE_SWIFT();
  if (!PgCluster::BinDir()) GTEST_SKIP() << "PostgreSQL is not installed (initdb, pg_ctl, postgres)";
  PgCluster pg;
  ASSERT_TRUE(pg.ok()) << pg.error();
  SetCredentials(SwiftS3::access_key(), SwiftS3::secret_key());
  const std::string dir = TempDir("s3-library");
  const std::vector<std::string> shared = {"--store", pg.Url(), "--blobs", swift.Url(), "--models-dir", "none"};
  std::string observer;
  {
    ServerProcess a(dir + "/a", shared);
    ASSERT_TRUE(a.ready()) << a.Log();
    observer = a.Token("observer");
    const HttpReply up = Upload(a.port(), a.Token("admin"), "shared_model");
    ASSERT_EQ(up.status, 201) << up.body;
    const std::string sha = json::parse(up.body)["fem_sha256"];
    // In the bucket, under its hash; nothing in the data directory.
    std::string stored;
    EXPECT_EQ(swift.Curl("GET", "blobs/" + sha, &stored), 200);
    EXPECT_TRUE(stored == kFem);
    EXPECT_FALSE(std::filesystem::exists(dir + "/a/blobs"));
    a.process().Signal(SIGTERM);
    EXPECT_EQ(a.process().Wait(30s), 0) << a.Log();
  }
  std::vector<std::string> b_args = shared;
  b_args.insert(b_args.end(), {"--tokens", dir + "/a/tokens"});
  ServerProcess b(dir + "/b", b_args);
  ASSERT_TRUE(b.ready()) << b.Log();
  const HttpReply fem = Get(b.port(), "/api/models/shared_model/fem?version=1", observer);
  ASSERT_EQ(fem.status, 200) << fem.body;
  EXPECT_TRUE(fem.body == kFem);
  const HttpReply plg = Get(b.port(), "/api/models/shared_model/plg", observer);
  ASSERT_EQ(plg.status, 200) << plg.body;
  EXPECT_TRUE(plg.body == kPlg);
  EXPECT_EQ(Get(b.port(), "/api/models/shared_model/obj", observer).status, 200);
}

// The store stopped under a running server: the library's files answer 503 with Retry-After (as
// a database outage does), uploads too; back, everything answers by itself.
TEST(S3Server, AStoppedStoreIsA503WithRetryAfterAndTheServerRecoversByItself) {
  IDMS_REQUIRE_SWIFT();
  SetCredentials(SwiftS3::access_key(), SwiftS3::secret_key());
  const std::string dir = TempDir("s3-outage");
  ServerProcess server(dir + "/data", {"--blobs", swift.Url()});
  ASSERT_TRUE(server.ready()) << server.Log();
  const std::string admin = server.Token("admin"), observer = server.Token("observer");
  // The shipped models were imported into the bucket at first start.
  const HttpReply before = Get(server.port(), "/api/models/hex_4x5_home/fem", observer);
  ASSERT_EQ(before.status, 200) << before.body;
  EXPECT_TRUE(before.body == kFem);

  ASSERT_TRUE(swift.Stop());
  const auto down = std::chrono::steady_clock::now();
  const HttpReply fem = Get(server.port(), "/api/models/hex_4x5_home/fem", observer);
  EXPECT_EQ(fem.status, 503) << fem.body;
  EXPECT_EQ(fem.headers.count("retry-after") ? fem.headers.at("retry-after") : "", "1");
  EXPECT_NE(fem.body.find("unavailable"), std::string::npos) << fem.body;
  const HttpReply upload = Upload(server.port(), admin, "while_down");
  EXPECT_EQ(upload.status, 503) << upload.body;
  const double answer_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - down).count();
  EXPECT_LT(answer_ms, 2000) << "a refused connection is answered at once, not after a timeout";
  // What needs no blob still answers.
  EXPECT_EQ(Get(server.port(), "/api/models", observer).status, 200);
  EXPECT_EQ(Get(server.port(), "/api/health", "").status, 200);

  ASSERT_TRUE(swift.Start()) << swift.error();
  const auto up = std::chrono::steady_clock::now();
  ASSERT_TRUE(
      Eventually([&] { return Get(server.port(), "/api/models/hex_4x5_home/fem", observer).status == 200; }, 10000ms))
      << server.Log();
  const double recover_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - up).count();
  const HttpReply again = Upload(server.port(), admin, "after_the_outage");
  EXPECT_EQ(again.status, 201) << again.body;
  std::printf("store down: REST answered 503 in %.0f ms; 200 again %.0f ms after the store was back\n", answer_ms,
              recover_ms);
  RecordProperty("recover_ms", static_cast<int>(recover_ms));
}

// The acknowledgements a fake agent reads within `timeout`: the newest next_tick, 0 when none.
uint64_t NewestAck(FakeAgent& agent, std::chrono::milliseconds timeout) {
  uint64_t newest = 0;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    const auto e =
        agent.Read(std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()));
    if (!e) break;
    if (e->has_ack()) newest = std::max(newest, e->ack().next_tick());
  }
  return newest;
}

// Issue 29, failure 7, with an agent that sends exactly what the test says: every tick is
// acknowledged once its segment is in the store; while the store is down no acknowledgement comes
// (the ticks wait on the server's disk); back, every tick is acknowledged. Then the finished
// recording is served from the store by a server with a fresh data directory, by ranges too.
TEST(S3Server, AcknowledgementsFollowTheSegmentsAndWaitWhileTheStoreIsDown) {
  IDMS_REQUIRE_SWIFT();
  if (!PgCluster::BinDir()) GTEST_SKIP() << "PostgreSQL is not installed (initdb, pg_ctl, postgres)";
  PgCluster pg;
  ASSERT_TRUE(pg.ok()) << pg.error();
  SetCredentials(SwiftS3::access_key(), SwiftS3::secret_key());
  const std::string dir = TempDir("s3-acks");
  // The fake agent answers the server's pings only while the test reads: the idle timeout spans
  // the test's own waits (a restart of Swift takes seconds).
  const std::vector<std::string> shared = {
      "--store", pg.Url(), "--blobs", swift.Url(), "--recordings", swift.Url(), "--agent-idle-timeout-ms", "60000"};
  auto a = std::make_unique<ServerProcess>(dir + "/a", shared);
  ASSERT_TRUE(a->ready()) << a->Log();
  const std::string observer = a->Token("observer");
  FakeAgent agent(a->port(), a->Token("agent"));
  const auto welcome = agent.Hello("", "", "s3-test", "hex_4x5_home");
  ASSERT_TRUE(welcome && welcome->has_welcome()) << a->Log();
  const std::string id = welcome->welcome().session_id();
  // Up: the ticks sent are acknowledged within about a second, and their segments are there.
  uint64_t sent = 0;
  for (; sent < 2000; sent += 100) ASSERT_TRUE(agent.SendSamples(sent, 100));
  ASSERT_TRUE(agent.ReadUntil([](const v1::Envelope& e) { return e.has_ack() && e.ack().next_tick() == 2000; }, 10s));
  const std::vector<std::string> segments = swift.Keys("recordings/" + id + "/");
  EXPECT_GE(segments.size(), 1u);
  for (const std::string& k : segments) EXPECT_EQ(k.rfind("recordings/" + id + "/000001-", 0), 0u) << k;

  // Down for 5 s: ticks keep coming, nothing more is acknowledged.
  ASSERT_TRUE(swift.Stop());
  const auto down = std::chrono::steady_clock::now();
  for (; sent < 4000; sent += 100) ASSERT_TRUE(agent.SendSamples(sent, 100));
  const uint64_t acked_while_down = NewestAck(agent, 5s);
  EXPECT_LE(acked_while_down, 2000u) << "a tick acknowledged while the store was down";
  EXPECT_GT(MetricValue(a->port(), observer, "idms_recording_pending_bytes"), 0);
  EXPECT_EQ(MetricValue(a->port(), observer, "idms_object_store_available"), 0);
  // Back: everything sent is acknowledged.
  ASSERT_TRUE(swift.Start()) << swift.error();
  const auto up = std::chrono::steady_clock::now();
  ASSERT_TRUE(agent.ReadUntil([&](const v1::Envelope& e) { return e.has_ack() && e.ack().next_tick() == sent; }, 15s))
      << a->Log();
  const double ack_after_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - up).count();
  EXPECT_EQ(MetricValue(a->port(), observer, "idms_object_store_available"), 1);
  // Ended: the final acknowledgement once the whole file is stored; the segments replaced by
  // the finished object.
  const auto final_ack = agent.End(sent - 1);
  ASSERT_TRUE(final_ack) << a->Log();
  EXPECT_EQ(final_ack->ack().next_tick(), sent);
  ASSERT_TRUE(Eventually([&] { return swift.Keys("recordings/" + id).size() == 1; }, 10s));
  EXPECT_EQ(swift.Keys("recordings/" + id), std::vector<std::string>{"recordings/" + id + ".mcap"});
  const std::string from_a = dir + "/from-a.mcap";
  ASSERT_TRUE(DownloadRecording(a->port(), id, observer, from_a));
  EXPECT_EQ(RecordedTicks(from_a).size(), sent);

  // Another server, its own empty data directory: the recording comes from the store, whole and
  // by ranges.
  a.reset();
  std::vector<std::string> b_args = shared;
  b_args.insert(b_args.end(), {"--tokens", dir + "/a/tokens"});
  ServerProcess b(dir + "/b", b_args);
  ASSERT_TRUE(b.ready()) << b.Log();
  const std::string from_b = dir + "/from-b.mcap";
  ASSERT_TRUE(DownloadRecording(b.port(), id, observer, from_b));
  const std::string whole = ReadText(from_a);
  EXPECT_TRUE(ReadText(from_b) == whole);
  const std::vector<uint64_t> ticks = RecordedTicks(from_b);
  ASSERT_EQ(ticks.size(), sent);
  for (uint64_t t = 0; t < sent; ++t) ASSERT_EQ(ticks[t], t) << "every tick once, in order";
  IndependentReaderAccepts(from_b, sent);
  const HttpReply part = Http(b.port(), HttpCall{"GET",
                                                 "/api/sessions/" + id + "/recording.mcap",
                                                 {{"Authorization", "Bearer " + observer}, {"Range", "bytes=100-1123"}},
                                                 ""});
  EXPECT_EQ(part.status, 206);
  EXPECT_TRUE(part.body == whole.substr(100, 1024));
  EXPECT_EQ(part.headers.count("content-range") ? part.headers.at("content-range") : "",
            "bytes 100-1123/" + std::to_string(whole.size()));
  std::printf(
      "store down %.1f s: %llu ticks acknowledged while down (of %llu sent); every tick acknowledged %.0f ms "
      "after the store was back\n",
      std::chrono::duration<double>(up - down).count(), static_cast<unsigned long long>(acked_while_down),
      static_cast<unsigned long long>(sent), ack_after_ms);
  RecordProperty("ack_after_ms", static_cast<int>(ack_after_ms));
}

// Issue 29, failure 7, with the real agent in real time and a viewer: the store stopped for 10 s
// under a live session. The agent's backlog holds what is not acknowledged, the viewer never
// stops, and the recording holds every tick once, in order (our reader and the MCAP project's).
TEST(S3Server, TheStoreStoppedFor10SecondsUnderALiveSessionLosesNoTick) {
  IDMS_REQUIRE_SWIFT();
  SetCredentials(SwiftS3::access_key(), SwiftS3::secret_key());
  const std::string dir = TempDir("s3-failure7");
  ServerProcess server(dir + "/data", {"--recordings", swift.Url()});
  ASSERT_TRUE(server.ready()) << server.Log();
  const uint16_t port = server.port();
  const std::string observer = server.Token("observer");
  ChildProcess agent(IDMS_AGENT_BIN,
                     {"--server", "ws://127.0.0.1:" + server.port_string(), "--token", server.Token("agent"), "--model",
                      "hex_4x5_home", "--device", "scripted:palpate", "--duration", "16", "--cache-dir", dir + "/cache",
                      "--summary-json", dir + "/summary.json"},
                     dir + "/agent.log");
  const std::string id = WaitForLiveSession(port, observer, 500);
  ASSERT_FALSE(id.empty()) << server.Log() << agent.Log();
  TestViewer viewer(port, id, observer);
  ASSERT_TRUE(Eventually([&] { return !swift.Keys("recordings/" + id + "/").empty(); }, 5s)) << server.Log();

  ASSERT_TRUE(swift.Stop());
  const auto down = std::chrono::steady_clock::now();
  const size_t frames_at_stop = viewer.Frames().size();
  std::this_thread::sleep_for(10s);  // the outage itself: nothing to await
  const double pending = MetricValue(port, observer, "idms_recording_pending_bytes");
  const size_t frames_while_down = viewer.Frames().size() - frames_at_stop;
  EXPECT_FALSE(viewer.closed());
  ASSERT_TRUE(swift.Start()) << swift.error();
  const auto up = std::chrono::steady_clock::now();
  ASSERT_TRUE(Eventually([&] { return MetricValue(port, observer, "idms_recording_pending_bytes") == 0; }, 15s))
      << server.Log();
  const double drained_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - up).count();
  EXPECT_EQ(agent.Wait(60s), 0) << agent.Log();
  ASSERT_TRUE(Eventually([&] { return Sessions(port, observer)[0]["state"] == "ended"; })) << server.Log();
  const json summary = json::parse(ReadText(dir + "/summary.json"));
  const std::string path = dir + "/recording.mcap";
  ASSERT_TRUE(DownloadRecording(port, id, observer, path));
  const std::vector<uint64_t> ticks = RecordedTicks(path);
  ASSERT_FALSE(ticks.empty());
  for (size_t i = 0; i < ticks.size(); ++i) ASSERT_EQ(ticks[i], i) << "every tick once, in order";
  IndependentReaderAccepts(path, ticks.size());
  EXPECT_EQ(ticks.size(), summary["ticks"].get<size_t>()) << "every tick the agent's loop ran is recorded";
  EXPECT_EQ(summary["samples_dropped"], 0);
  EXPECT_GT(pending, 0) << "bytes waited on the server's disk";
  EXPECT_GT(frames_while_down, 100u) << "the viewer's frames while the store was down";
  std::printf(
      "store down %.1f s (stopped, 10 s, started): %.0f bytes waited on disk, %zu frames reached the viewer meanwhile; "
      "the backlog "
      "was stored %.0f ms after the store was back; %zu ticks recorded of the agent's %zu, none lost\n",
      std::chrono::duration<double>(up - down).count(), pending, frames_while_down, drained_ms, ticks.size(),
      summary["ticks"].get<size_t>());
  RecordProperty("drained_ms", static_cast<int>(drained_ms));
}

// A server killed (SIGKILL) under a live session; its agent resumes on another server, which takes
// the session over once the lease lapses: the recording continues from the dead server's segments
// (the ticks it acknowledged), the agent resends from there, and the recording holds every tick
// exactly once. The dead server's data directory is never read.
TEST(S3Server, ASessionTakenOverAfterItsServerDiedContinuesFromItsSegments) {
  IDMS_REQUIRE_SWIFT();
  if (!PgCluster::BinDir()) GTEST_SKIP() << "PostgreSQL is not installed (initdb, pg_ctl, postgres)";
  PgCluster pg;
  ASSERT_TRUE(pg.ok()) << pg.error();
  SetCredentials(SwiftS3::access_key(), SwiftS3::secret_key());
  const std::string dir = TempDir("s3-takeover");
  const std::vector<std::string> shared = {
      "--store", pg.Url(), "--recordings", swift.Url(), "--lease-ttl-ms", "1500", "--agent-idle-timeout-ms", "60000"};
  auto a = std::make_unique<ServerProcess>(dir + "/a", shared);
  ASSERT_TRUE(a->ready()) << a->Log();
  const std::string observer = a->Token("observer"), agent_token = a->Token("agent");
  std::string id, resume_token;
  uint64_t acked = 0;
  {
    FakeAgent agent(a->port(), agent_token);
    const auto welcome = agent.Hello("", "", "s3-takeover", "hex_4x5_home");
    ASSERT_TRUE(welcome && welcome->has_welcome()) << a->Log();
    id = welcome->welcome().session_id();
    resume_token = welcome->welcome().resume_token();
    for (uint64_t t = 0; t < 3000; t += 100) ASSERT_TRUE(agent.SendSamples(t, 100));
    ASSERT_TRUE(agent.ReadUntil([](const v1::Envelope& e) { return e.has_ack() && e.ack().next_tick() == 3000; }, 10s));
    acked = 3000;
    // More ticks that may or may not reach a segment before the kill: the takeover says which.
    for (uint64_t t = 3000; t < 3500; t += 100) ASSERT_TRUE(agent.SendSamples(t, 100));
    a->process().Signal(SIGKILL);
    ASSERT_TRUE(a->process().Wait(10s));
  }
  const auto killed = std::chrono::steady_clock::now();
  std::vector<std::string> b_args = shared;
  b_args.insert(b_args.end(), {"--tokens", dir + "/a/tokens"});
  ServerProcess b(dir + "/b", b_args);
  ASSERT_TRUE(b.ready()) << b.Log();
  // The agent resumes on B: "later" while A's lease runs, then B takes the session.
  std::unique_ptr<FakeAgent> agent;
  std::optional<v1::Envelope> welcome;
  ASSERT_TRUE(Eventually(
      [&] {
        agent = std::make_unique<FakeAgent>(b.port(), agent_token);
        welcome = agent->Hello(id, resume_token, "s3-takeover", "hex_4x5_home");
        return welcome && welcome->has_welcome();
      },
      20s))
      << b.Log();
  const double takeover_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - killed).count();
  const uint64_t next = welcome->welcome().next_tick();
  EXPECT_GE(next, acked) << "an acknowledged tick was lost";
  EXPECT_LE(next, 3500u);
  for (uint64_t t = next; t < 6000; t += 100)
    ASSERT_TRUE(agent->SendSamples(t, static_cast<int>(std::min<uint64_t>(100, 6000 - t))));
  const auto final_ack = agent->End(5999);
  ASSERT_TRUE(final_ack) << b.Log();
  EXPECT_EQ(final_ack->ack().next_tick(), 6000u);
  const std::string path = dir + "/recording.mcap";
  ASSERT_TRUE(DownloadRecording(b.port(), id, observer, path));
  const std::vector<uint64_t> ticks = RecordedTicks(path);
  ASSERT_EQ(ticks.size(), 6000u);
  for (uint64_t t = 0; t < 6000; ++t) ASSERT_EQ(ticks[t], t) << "every tick exactly once, in order";
  IndependentReaderAccepts(path, 6000);
  // Published: one object, no segment of either generation left.
  ASSERT_TRUE(Eventually([&] { return swift.Keys("recordings/" + id).size() == 1; }, 10s));
  std::printf(
      "taken over %.1f s after the kill (lease 1.5 s); the new owner continued from tick %llu (%llu acknowledged "
      "before the kill)\n",
      takeover_s, static_cast<unsigned long long>(next), static_cast<unsigned long long>(acked));
}

}  // namespace
}  // namespace idms::test
