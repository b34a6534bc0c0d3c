// Recordings in an S3 bucket (a real OpenStack Swift with s3api, started by the test): segments
// uploaded as Persist asks, in order, each request answered once its bytes are stored; the store
// stopped (the bytes wait, the newest request is answered when it is back, nothing lost); the
// finished recording published whole and fetched by another server; a live recording whose owner
// died rebuilt from its segments and read by CopyRecording.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <future>
#include <thread>

#include "../../server/src/recordings.h"
#include "../../server/src/s3_stores.h"
#include "child_process.h"
#include "server_process.h"
#include "swift_s3.h"

namespace idms::server {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using test::SwiftS3;

#define IDMS_REQUIRE_SWIFT()                                                                                      \
  if (!SwiftS3::Installed()) GTEST_SKIP() << "OpenStack Swift is not installed (swift-proxy, swift-object, ...)"; \
  SwiftS3 swift;                                                                                                  \
  ASSERT_TRUE(swift.ok()) << swift.error()

constexpr const char* kId = "2026-11-28-0123456789ab";

S3Location LocationOf(const SwiftS3& swift) {
  S3Location l;
  std::string error;
  EXPECT_TRUE(ParseS3Url(swift.Url(), &l, &error)) << error;
  return l;
}
S3Credentials Credentials() { return {SwiftS3::access_key(), SwiftS3::secret_key()}; }

std::unique_ptr<RecordingStore> Open(const SwiftS3& swift, const std::string& cache) {
  std::string error;
  S3RecordingOptions options;
  options.drain_timeout = 1s;
  auto store = OpenS3RecordingStore(LocationOf(swift), Credentials(), cache, &error, options);
  EXPECT_TRUE(store) << error;
  return store;
}

// A session's recording written as the recorder writes it: batches of device ticks, a chunk
// closed when asked, so that the file's length is what Persist is told.
class TestRecording {
 public:
  explicit TestRecording(const std::string& path) {
    RecordingWriterOptions options;
    options.session = {{"session_id", kId}, {"model", "hex_4x5_home"}};
    std::string error;
    EXPECT_TRUE(writer_.Open(path, options, &error)) << error;
  }
  // `n` more ticks in batches of 20, then the chunk closed: the bytes written so far.
  uint64_t Ticks(int n) {
    std::string error;
    for (int i = 0; i < n; i += 20) {
      v1::Envelope e;
      for (int j = 0; j < 20 && i + j < n; ++j) {
        v1::DeviceSample* s = e.mutable_device_samples()->add_samples();
        s->set_tick(next_tick_);
        s->set_time_s(static_cast<double>(next_tick_) * 1e-3);
        s->mutable_tool_pos()->set_x(static_cast<double>(next_tick_ % 100) * 0.01);
        ++next_tick_;
      }
      EXPECT_TRUE(writer_.Write(e, 1000000000ULL + next_tick_ * 1000000ULL, 0, &error)) << error;
    }
    EXPECT_TRUE(writer_.CloseChunk(&error)) << error;
    return writer_.mcap().bytes_written();
  }
  uint64_t Close() {
    std::string error;
    EXPECT_TRUE(writer_.Close(&error)) << error;
    return writer_.mcap().bytes_written();
  }
  uint64_t next_tick() const { return next_tick_; }

 private:
  RecordingWriter writer_;
  uint64_t next_tick_ = 0;
};

// Persist, with its answer as a future.
std::future<bool> Persist(RecordingStore& store, uint64_t bytes) {
  auto promise = std::make_shared<std::promise<bool>>();
  store.Persist(kId, bytes, [promise](bool ok) { promise->set_value(ok); });
  return promise->get_future();
}

bool Answered(std::future<bool>& f, std::chrono::milliseconds within) {
  return f.wait_for(within) == std::future_status::ready;
}

// The objects under `prefix`, as key -> size.
std::map<std::string, uint64_t> Objects(const SwiftS3& swift, const std::string& prefix) {
  S3Client s3(LocationOf(swift), Credentials());
  std::vector<S3Object> objects;
  std::string error;
  EXPECT_EQ(s3.List(prefix, &objects, &error), S3Result::kOk) << error;
  std::map<std::string, uint64_t> out;
  for (const S3Object& o : objects) out[o.key] = o.size;
  return out;
}

std::string Segment(int generation, uint64_t offset) {
  char name[64];
  std::snprintf(name, sizeof name, "recordings/%s/%06d-%020llu", kId, generation,
                static_cast<unsigned long long>(offset));
  return name;
}

// Every tick CopyRecording reads from `path`, which must be 0, 1, ..., n-1.
uint64_t ContiguousTicks(const std::string& path) {
  CopyStats stats;
  std::string error;
  EXPECT_TRUE(CopyRecording(path, nullptr, &stats, &error)) << error;
  EXPECT_EQ(static_cast<uint64_t>(stats.samples), stats.any_tick ? stats.last_tick + 1 : 0)
      << "ticks missing or repeated";
  return static_cast<uint64_t>(stats.samples);
}

TEST(S3RecordingStore, SegmentsFollowPersistThenTheFinishedFileReplacesThem) {
  IDMS_REQUIRE_SWIFT();
  const std::string dir = test::TempDir("s3-recordings");
  auto store = Open(swift, dir + "/a");
  TestRecording rec(store->LivePath(kId));
  // Each request is answered once its bytes are a segment: the first from byte 0, the next from
  // where it ended.
  const uint64_t first = rec.Ticks(1000);
  auto a = Persist(*store, first);
  ASSERT_TRUE(Answered(a, 10s));
  EXPECT_TRUE(a.get());
  EXPECT_EQ(Objects(swift, "recordings/"), (std::map<std::string, uint64_t>{{Segment(1, 0), first}}));
  const uint64_t second = rec.Ticks(1000);
  auto b = Persist(*store, second);
  ASSERT_TRUE(Answered(b, 10s));
  EXPECT_TRUE(b.get());
  EXPECT_EQ(Objects(swift, "recordings/"),
            (std::map<std::string, uint64_t>{{Segment(1, 0), first}, {Segment(1, first), second - first}}));
  // Nothing new: answered at once.
  auto again = Persist(*store, second);
  ASSERT_TRUE(Answered(again, 0ms));
  EXPECT_TRUE(again.get());
  // Finished: the closed file durable, published as one object, the segments gone.
  const uint64_t total = rec.Close();
  auto last = Persist(*store, total);
  ASSERT_TRUE(Answered(last, 10s));
  std::string error;
  ASSERT_TRUE(store->Publish(kId, &error)) << error;
  EXPECT_TRUE(fs::exists(store->FinishedPath(kId)));
  ASSERT_TRUE(test::Eventually(
      [&] {
        return Objects(swift, "recordings/") ==
               std::map<std::string, uint64_t>{{"recordings/" + std::string(kId) + ".mcap", total}};
      },
      10s));
  // Another server (another cache) reads the same bytes from the store.
  auto other = Open(swift, dir + "/b");
  ASSERT_TRUE(other->Fetch(kId, &error)) << error;
  EXPECT_TRUE(test::ReadText(other->FinishedPath(kId)) == test::ReadText(store->FinishedPath(kId)));
  EXPECT_EQ(ContiguousTicks(other->FinishedPath(kId)), 2000u);
  EXPECT_NE(other->MetricsText().find("idms_object_store_available 1"), std::string::npos);
  // Deleted: from the store and the caches.
  other->Remove(kId);
  EXPECT_TRUE(Objects(swift, "recordings/").empty());
  EXPECT_FALSE(fs::exists(other->FinishedPath(kId)));
  EXPECT_FALSE(other->Fetch(kId, &error));
  EXPECT_NE(error.find("no recording of session " + std::string(kId)), std::string::npos) << error;
}

// Issue 29, failure 7, at the store: stopped, the bytes wait in the local file; the newest request
// waits (older ones are answered false: the newest covers them); back, it is answered and the
// segments hold every byte, in order.
TEST(S3RecordingStore, WhileTheStoreIsDownSegmentsWaitAndNothingIsLost) {
  IDMS_REQUIRE_SWIFT();
  const std::string dir = test::TempDir("s3-recordings-down");
  auto store = Open(swift, dir + "/a");
  TestRecording rec(store->LivePath(kId));
  auto up = Persist(*store, rec.Ticks(500));
  ASSERT_TRUE(Answered(up, 10s));
  ASSERT_TRUE(swift.Stop());
  auto older = Persist(*store, rec.Ticks(500));
  auto newest = Persist(*store, rec.Ticks(500));
  ASSERT_TRUE(Answered(older, 1s)) << "superseded at once";
  EXPECT_FALSE(older.get());
  EXPECT_FALSE(Answered(newest, 2s)) << "answered while the store was down";
  EXPECT_NE(store->MetricsText().find("idms_object_store_available 0"), std::string::npos) << store->MetricsText();
  ASSERT_TRUE(swift.Start()) << swift.error();
  const auto back = std::chrono::steady_clock::now();
  ASSERT_TRUE(Answered(newest, 10s));
  EXPECT_TRUE(newest.get());
  std::printf("the waiting segment was stored %.0f ms after the store was back\n",
              std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - back).count());
  // The segments, in order, are the file's first bytes: every tick of the 1500 is there.
  const std::string local = test::ReadText(store->LivePath(kId));
  std::string joined;
  S3Client s3(LocationOf(swift), Credentials());
  for (const auto& [key, size] : Objects(swift, "recordings/" + std::string(kId) + "/")) {
    std::string bytes, error;
    ASSERT_EQ(s3.Get(key, &bytes, 1 << 30, &error), S3Result::kOk) << error;
    EXPECT_EQ(key, Segment(1, joined.size()));
    joined += bytes;
  }
  EXPECT_EQ(joined.size(), local.size());
  EXPECT_TRUE(joined == local);
  const std::string copy = dir + "/joined.mcap";
  std::ofstream(copy, std::ios::binary) << joined;
  EXPECT_EQ(ContiguousTicks(copy), 1500u);
}

// Issue 29: a server dies under a live session; another takes it over. Recover rebuilds the live
// file from the segments (what was acknowledged, not what was written after); the new owner's
// writer copies it and carries on in a new generation, and the old one's segments go.
TEST(S3RecordingStore, RecoverRebuildsALiveRecordingFromItsSegmentsForTheNextOwner) {
  IDMS_REQUIRE_SWIFT();
  const std::string dir = test::TempDir("s3-recordings-recover");
  {
    auto owner = Open(swift, dir + "/owner");
    TestRecording rec(owner->LivePath(kId));
    auto a = Persist(*owner, rec.Ticks(700));
    auto b = Persist(*owner, rec.Ticks(600));
    ASSERT_TRUE(Answered(b, 10s));
    rec.Ticks(400);  // written, never persisted: the owner dies before its next second
  }
  auto next = Open(swift, dir + "/next");
  std::string error;
  EXPECT_FALSE(next->Recover("2026-11-28-unknown", &error));
  EXPECT_NE(error.find("no durable recording"), std::string::npos) << error;
  ASSERT_TRUE(next->Recover(kId, &error)) << error;
  EXPECT_EQ(ContiguousTicks(next->LivePath(kId)), 1300u) << "every persisted tick, none after";
  // The new owner's writer starts from the recovered file (as Recorder::Start does for a takeover).
  const std::string taken = next->LivePath(kId) + ".taken";
  fs::rename(next->LivePath(kId), taken);
  RecordingWriter writer;
  RecordingWriterOptions options;
  ASSERT_TRUE(writer.Open(next->LivePath(kId), options, &error)) << error;
  CopyStats stats;
  ASSERT_TRUE(CopyRecording(taken, &writer, &stats, &error)) << error;
  ASSERT_TRUE(writer.CloseChunk(&error)) << error;
  auto first = Persist(*next, writer.mcap().bytes_written());
  ASSERT_TRUE(Answered(first, 10s));
  EXPECT_TRUE(first.get());
  // Generation 2 from byte 0 holds all; generation 1 is gone.
  EXPECT_EQ(Objects(swift, "recordings/"),
            (std::map<std::string, uint64_t>{{Segment(2, 0), writer.mcap().bytes_written()}}));
  ASSERT_TRUE(writer.Close(&error)) << error;
}

// Finished while the store was down and the server stopped before the upload: the segments hold
// the whole file, and another server fetches it from them.
TEST(S3RecordingStore, AFinishedRecordingIsFetchedFromItsSegmentsUntilItsUploadIsDone) {
  IDMS_REQUIRE_SWIFT();
  const std::string dir = test::TempDir("s3-recordings-unpublished");
  std::string error, finished;
  {
    auto store = Open(swift, dir + "/a");
    TestRecording rec(store->LivePath(kId));
    rec.Ticks(800);
    auto all = Persist(*store, rec.Close());
    ASSERT_TRUE(Answered(all, 10s));
    ASSERT_TRUE(swift.Stop());
    ASSERT_TRUE(store->Publish(kId, &error)) << error;  // its upload waits, then the store is closed
    finished = test::ReadText(store->FinishedPath(kId));
  }
  ASSERT_TRUE(swift.Start()) << swift.error();
  EXPECT_EQ(Objects(swift, "recordings/" + std::string(kId) + ".mcap").size(), 0u);
  auto other = Open(swift, dir + "/b");
  ASSERT_TRUE(other->Fetch(kId, &error)) << error;
  EXPECT_TRUE(test::ReadText(other->FinishedPath(kId)) == finished);
  EXPECT_EQ(ContiguousTicks(other->FinishedPath(kId)), 800u);
}

}  // namespace
}  // namespace idms::server
