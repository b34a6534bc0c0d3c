// The real idms-server with its blobs (--blobs) and recordings (--recordings) in a real S3 store
// (OpenStack Swift with s3api, started by the test): problems with the store named at start-up; a
// model uploaded through the REST API served by a server with a fresh data directory; the store
// stopped (REST 503 with Retry-After, recovery by itself).
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

}  // namespace
}  // namespace idms::test
