// The S3 client against a real S3 server (OpenStack Swift's s3api, started by the test): objects
// put from memory and from a file's byte range, read whole and by range, listed by prefix over
// several pages, removed; its errors naming the method, key and S3's code; a store that is down
// told apart (StoreUnavailable) from one that refuses.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include "child_process.h"
#include "swift_s3.h"

namespace idms::server {
namespace {

using test::SwiftS3;

#define SKIP_WITHOUT_SWIFT() \
  if (!SwiftS3::Installed()) GTEST_SKIP() << "OpenStack Swift is not installed (swift-proxy, swift-object, ...)"

// The fixture itself: the S3 API answers, objects survive a stop and start on the same port.
TEST(SwiftS3, ServesS3AndKeepsObjectsAcrossARestart) {
  SKIP_WITHOUT_SWIFT();
  SwiftS3 swift;
  ASSERT_TRUE(swift.ok()) << swift.error();
  const std::string file = test::TempDir("swift-fixture") + "/hello.txt";
  std::ofstream(file) << "hello";
  ASSERT_EQ(swift.Curl("PUT", "fixture/hello", nullptr, file), 200) << swift.Log();
  std::string body;
  ASSERT_EQ(swift.Curl("GET", "fixture/hello", &body), 200);
  EXPECT_EQ(body, "hello");
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_TRUE(swift.Stop());
  EXPECT_EQ(swift.Curl("GET", "fixture/hello"), 0);  // nothing listens
  ASSERT_TRUE(swift.Start()) << swift.error();
  std::printf("Swift stopped and started again in %.2f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  ASSERT_EQ(swift.Curl("GET", "fixture/hello", &body), 200);
  EXPECT_EQ(body, "hello");
}

}  // namespace
}  // namespace idms::server
