// The BlobStore contract, run on both back ends: the data directory (the default) and an S3 bucket
// (a real OpenStack Swift with s3api, started by the test). Then what only S3 has: start-up checks
// that name the problem, and a store that goes down and comes back.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>

#include "../../server/src/s3_stores.h"
#include "child_process.h"
#include "idms/server/storage.h"
#include "swift_s3.h"

namespace idms::server {
namespace {

using test::SwiftS3;

#define SKIP_WITHOUT_SWIFT() \
  if (!SwiftS3::Installed()) GTEST_SKIP() << "OpenStack Swift is not installed (swift-proxy, swift-object, ...)"

enum class Backend { kDirectory, kS3 };

std::string BackendName(const testing::TestParamInfo<Backend>& info) {
  return info.param == Backend::kDirectory ? "Directory" : "S3";
}

S3Location LocationOf(const SwiftS3& swift, const std::string& bucket) {
  S3Location l;
  std::string error;
  EXPECT_TRUE(ParseS3Url(swift.Url(bucket), &l, &error)) << error;
  return l;
}

// One Swift for the suite; each test its own bucket.
class Blobs : public testing::TestWithParam<Backend> {
 protected:
  static void TearDownTestSuite() {
    delete swift_;
    swift_ = nullptr;
  }
  void SetUp() override {
    std::string error;
    if (GetParam() == Backend::kDirectory) {
      blobs_ = OpenBlobDirectory(test::TempDir("blobs"), &error);
    } else {
      SKIP_WITHOUT_SWIFT();
      if (swift_ == nullptr) swift_ = new SwiftS3();
      ASSERT_TRUE(swift_->ok()) << swift_->error();
      static int n = 0;
      const std::string bucket = "blobs-" + std::to_string(++n);
      ASSERT_TRUE(swift_->CreateBucket(bucket)) << swift_->error();
      blobs_ = OpenS3BlobStore(LocationOf(*swift_, bucket), {SwiftS3::access_key(), SwiftS3::secret_key()}, &error);
    }
    ASSERT_TRUE(blobs_) << error;
  }

  static SwiftS3* swift_;
  std::unique_ptr<BlobStore> blobs_;
};
SwiftS3* Blobs::swift_ = nullptr;

INSTANTIATE_TEST_SUITE_P(Backends, Blobs, testing::Values(Backend::kDirectory, Backend::kS3), BackendName);

TEST_P(Blobs, StoresByContentHashAndReadsBack) {
  std::string error, sha;
  ASSERT_TRUE(blobs_->Put("hello", &sha, &error)) << error;
  EXPECT_EQ(sha, "2cf24dba5fb0a30e26e83b2ac5b9e29e1b161e5c1fa7425e73043362938b9824");  // sha256("hello")
  std::string back;
  ASSERT_TRUE(blobs_->Get(sha, &back));
  EXPECT_EQ(back, "hello");
  EXPECT_TRUE(blobs_->Has(sha));
  EXPECT_EQ(blobs_->List(), std::vector<std::string>{sha});
  // A second Put of the same bytes is the same blob.
  std::string again;
  ASSERT_TRUE(blobs_->Put("hello", &again, &error));
  EXPECT_EQ(again, sha);
  EXPECT_EQ(blobs_->List().size(), 1u);
  blobs_->Remove(sha);
  EXPECT_FALSE(blobs_->Has(sha));
  EXPECT_FALSE(blobs_->Get(sha, &back));
  EXPECT_TRUE(blobs_->List().empty());
  // Not a hash: never a path or a key.
  EXPECT_FALSE(blobs_->Get("../../etc/passwd", &back));
  EXPECT_FALSE(blobs_->Has("../blobs/" + sha));
  EXPECT_FALSE(blobs_->Get(std::string(64, 'A'), &back));
}

TEST_P(Blobs, LargeAndEmptyBlobsComeBackByteForByte) {
  std::string big(5 << 20, '\0');
  for (size_t i = 0; i < big.size(); ++i) big[i] = static_cast<char>((i * 2654435761u) >> 13);
  std::string error, sha_big, sha_empty, back;
  ASSERT_TRUE(blobs_->Put(big, &sha_big, &error)) << error;
  ASSERT_TRUE(blobs_->Put("", &sha_empty, &error)) << error;
  ASSERT_TRUE(blobs_->Get(sha_big, &back));
  EXPECT_TRUE(back == big);
  EXPECT_EQ(Sha256Hex(back), sha_big);
  ASSERT_TRUE(blobs_->Get(sha_empty, &back));
  EXPECT_TRUE(back.empty());
  std::vector<std::string> listed = blobs_->List();
  std::sort(listed.begin(), listed.end());
  std::vector<std::string> expected = {sha_big, sha_empty};
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(listed, expected);
}

// Uploads of the same file race (two servers, or two admins): each gets the blob, stored once.
TEST_P(Blobs, ConcurrentPutsOfOneBlobAllSucceed) {
  std::atomic<int> ok{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 5; ++i) {
        std::string sha, error;
        if (blobs_->Put("the same bytes", &sha, &error) && blobs_->Put("own " + std::to_string(t), &sha, &error)) ++ok;
      }
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(ok.load(), 20);
  EXPECT_EQ(blobs_->List().size(), 5u);
}

// What only the object store has: problems named at start-up, and a store that goes away.
TEST(S3BlobStore, OpeningNamesWhatIsWrong) {
  SKIP_WITHOUT_SWIFT();
  SwiftS3 swift;
  ASSERT_TRUE(swift.ok()) << swift.error();
  std::string error;
  EXPECT_FALSE(OpenS3BlobStore(LocationOf(swift, swift.bucket()), {SwiftS3::access_key(), "wrong"}, &error));
  EXPECT_NE(error.find("403 SignatureDoesNotMatch"), std::string::npos) << error;
  EXPECT_FALSE(OpenS3BlobStore(LocationOf(swift, "absent"), {SwiftS3::access_key(), SwiftS3::secret_key()}, &error));
  EXPECT_NE(error.find("404 NoSuchBucket"), std::string::npos) << error;
  ASSERT_TRUE(swift.Stop());
  EXPECT_FALSE(
      OpenS3BlobStore(LocationOf(swift, swift.bucket()), {SwiftS3::access_key(), SwiftS3::secret_key()}, &error));
  EXPECT_NE(error.find("unreachable"), std::string::npos) << error;
}

TEST(S3BlobStore, AStoppedStoreIsUnavailableUntilItComesBack) {
  SKIP_WITHOUT_SWIFT();
  SwiftS3 swift;
  ASSERT_TRUE(swift.ok()) << swift.error();
  std::string error, sha, back;
  auto blobs =
      OpenS3BlobStore(LocationOf(swift, swift.bucket()), {SwiftS3::access_key(), SwiftS3::secret_key()}, &error);
  ASSERT_TRUE(blobs) << error;
  ASSERT_TRUE(blobs->Put("kept", &sha, &error)) << error;
  ASSERT_TRUE(swift.Stop());
  EXPECT_THROW(blobs->Get(sha, &back), StoreUnavailable);
  EXPECT_THROW(blobs->Has(sha), StoreUnavailable);
  EXPECT_THROW(blobs->Put("new", &sha, &error), StoreUnavailable);
  ASSERT_TRUE(swift.Start()) << swift.error();
  ASSERT_TRUE(blobs->Get(Sha256Hex("kept"), &back));
  EXPECT_EQ(back, "kept");
  ASSERT_TRUE(blobs->Put("new", &sha, &error)) << error;
  EXPECT_TRUE(blobs->Has(sha));
}

}  // namespace
}  // namespace idms::server
