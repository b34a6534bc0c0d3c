// McapWriter and McapReader (protocol/src/mcap_*.cc): round trips across many chunks, chunk
// closing by size and time, index seeks against scans, recovery of cut files, damaged CRCs and
// garbage reported with their byte offset, and a sweep of every truncation and byte flip of a
// small file. McapCheck.WriteFiles writes the files tests/protocol/mcap_check.py checks.
#include "idms/protocol/mcap.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace idms {
namespace {

namespace fs = std::filesystem;

std::string TempPath(const std::string& name) {
  return (fs::path(testing::TempDir()) / ("idms_mcap_" + std::to_string(::getpid()) + "_" + name)).string();
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string bytes(fs::file_size(path), '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return bytes;
}

void WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

uint64_t U64At(const std::string& bytes, size_t at) {
  uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(bytes[at + i]);
  return v;
}

struct Msg {
  uint16_t channel = 0;
  uint64_t log_ns = 0;
  uint64_t publish_ns = 0;
  std::string data;
  bool operator==(const Msg&) const = default;
};

// Deterministic test messages: channel 1 at 1 kHz, channel 2 at ~60 Hz, channel 3 now and then
// and up to 5 ms late (log times not monotonic). Payloads partly compressible.
std::vector<Msg> MakeMessages(int num, uint64_t t0_ns = 1'700'000'000'000'000'000) {
  std::vector<Msg> out;
  uint32_t seed = 12345;
  const auto next = [&]() { return seed = seed * 1664525u + 1013904223u; };
  for (int i = 0; i < num; ++i) {
    Msg m;
    const uint32_t r = next();
    m.channel = static_cast<uint16_t>(i % 16 == 0 ? 2 : (r % 23 == 0 ? 3 : 1));
    m.log_ns = t0_ns + uint64_t(i) * 1'000'000 - (m.channel == 3 ? (r >> 8) % 5'000'000 : 0);
    m.publish_ns = m.log_ns - 1000;
    const size_t size = (r >> 4) % 120;
    for (size_t k = 0; k < size; ++k) m.data.push_back(static_cast<char>(k % 7 == 0 ? next() : 'a' + k % 5));
    out.push_back(std::move(m));
  }
  return out;
}

// Writes the messages on three channels (two schemas) and returns the writer's chunk count.
uint32_t WriteMessages(const std::string& path, const McapWriterOptions& options, const std::vector<Msg>& messages,
                       bool close = true) {
  McapWriter writer;
  std::string error;
  EXPECT_TRUE(writer.Open(path, options, &error)) << error;
  const uint16_t a = writer.AddSchema("test.A", "protobuf",
                                      std::string("\x0a\x03"
                                                  "abc",
                                                  5),
                                      &error);
  const uint16_t b = writer.AddSchema("test.B", "jsonschema", "{}", &error);
  EXPECT_EQ(writer.AddChannel(a, "/device", "protobuf", {}, &error), 1) << error;
  EXPECT_EQ(writer.AddChannel(b, "/mesh", "json", {{"k", "v"}}, &error), 2) << error;
  EXPECT_EQ(writer.AddChannel(a, "/events", "protobuf", {}, &error), 3) << error;
  EXPECT_TRUE(writer.AddMetadata("idms.session", {{"session_id", "s1"}, {"scene", "model: \"hex\""}}, &error));
  for (const Msg& m : messages) EXPECT_TRUE(writer.Write(m.channel, m.log_ns, m.publish_ns, m.data, &error)) << error;
  const uint32_t chunks = writer.num_chunks();
  if (close) {
    EXPECT_TRUE(writer.Close(&error)) << error;
  }
  return chunks;
}

// What the reader should return: stable sort by log time (ties in write order = file order),
// filtered by range and channels.
std::vector<Msg> Expected(std::vector<Msg> messages, uint64_t start = 0, uint64_t end = UINT64_MAX,
                          std::vector<uint16_t> channels = {}) {
  std::vector<Msg> out;
  for (Msg& m : messages) {
    if (m.log_ns < start || m.log_ns > end) continue;
    if (!channels.empty() && std::find(channels.begin(), channels.end(), m.channel) == channels.end()) continue;
    out.push_back(std::move(m));
  }
  std::stable_sort(out.begin(), out.end(), [](const Msg& x, const Msg& y) { return x.log_ns < y.log_ns; });
  return out;
}

std::vector<Msg> ReadAll(McapReader& reader, std::string* error, uint64_t start = 0, uint64_t end = UINT64_MAX,
                         std::vector<uint16_t> channels = {}) {
  reader.Seek(start, end, channels);
  std::vector<Msg> out;
  McapMessage m;
  while (reader.Next(&m, error)) out.push_back({m.channel_id, m.log_time_ns, m.publish_time_ns, std::string(m.data)});
  return out;
}

McapReaderOptions Scanning() {
  McapReaderOptions options;
  options.use_summary = false;
  return options;
}

McapWriterOptions SmallChunks(bool compress) {
  McapWriterOptions options;
  options.compress = compress;
  options.chunk_bytes = 4096;
  return options;
}

class McapRoundTrip : public testing::TestWithParam<bool> {};

TEST_P(McapRoundTrip, ManyMessagesAcrossManyChunks) {
  const std::string path = TempPath("roundtrip.mcap");
  const std::vector<Msg> messages = MakeMessages(5000);
  const uint32_t chunks = WriteMessages(path, SmallChunks(GetParam()), messages);
  EXPECT_GT(chunks, 50u);
  for (const bool use_summary : {true, false}) {
    McapReaderOptions options;
    options.use_summary = use_summary;
    McapReader reader;
    std::string error;
    ASSERT_TRUE(reader.Open(path, options, &error)) << error;
    EXPECT_EQ(reader.indexed(), use_summary);
    EXPECT_EQ(reader.recovery_note(), "");
    EXPECT_EQ(reader.library(), "idms");
    EXPECT_EQ(reader.profile(), "");
    // Records.
    ASSERT_EQ(reader.schemas().size(), 2u);
    EXPECT_EQ(reader.schemas().at(1).name, "test.A");
    EXPECT_EQ(reader.schemas().at(1).data, std::string("\x0a\x03"
                                                       "abc",
                                                       5));
    EXPECT_EQ(reader.schemas().at(2).encoding, "jsonschema");
    ASSERT_EQ(reader.channels().size(), 3u);
    EXPECT_EQ(reader.channels().at(2).topic, "/mesh");
    EXPECT_EQ(reader.channels().at(2).metadata.at("k"), "v");
    ASSERT_NE(reader.FindChannel("/events"), nullptr);
    EXPECT_EQ(reader.FindChannel("/events")->schema_id, 1);
    ASSERT_EQ(reader.metadata().size(), 1u);
    EXPECT_EQ(reader.metadata()[0].first, "idms.session");
    EXPECT_EQ(reader.metadata()[0].second.at("scene"), "model: \"hex\"");
    // Statistics, per channel.
    const McapStatistics& stats = reader.statistics();
    EXPECT_EQ(stats.num_messages, messages.size());
    EXPECT_EQ(stats.num_chunks, chunks + 1);  // the last one closed by Close()
    const std::vector<Msg> expected = Expected(messages);
    EXPECT_EQ(stats.start_ns, expected.front().log_ns);
    EXPECT_EQ(stats.end_ns, expected.back().log_ns);
    for (uint16_t c = 1; c <= 3; ++c) {
      const std::vector<Msg> on = Expected(messages, 0, UINT64_MAX, {c});
      EXPECT_EQ(stats.channels.at(c).num_messages, on.size());
      EXPECT_EQ(stats.channels.at(c).start_ns, on.front().log_ns);
      EXPECT_EQ(stats.channels.at(c).end_ns, on.back().log_ns);
    }
    // Every message, in log-time order.
    const std::vector<Msg> read = ReadAll(reader, &error);
    EXPECT_EQ(error, "");
    ASSERT_EQ(read.size(), expected.size());
    EXPECT_TRUE(read == expected);
  }
  // Chunks: compressed when asked, never larger than their records, their channels known.
  McapReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, McapReaderOptions{}, &error)) << error;
  for (const McapChunkInfo& c : reader.chunks()) {
    EXPECT_EQ(c.compression, GetParam() ? "zstd" : "");
    EXPECT_LE(c.compressed_bytes, c.uncompressed_bytes);
    EXPECT_FALSE(c.channels.empty());
  }
}

INSTANTIATE_TEST_SUITE_P(Compression, McapRoundTrip, testing::Bool(),
                         [](const auto& param_info) { return param_info.param ? "zstd" : "none"; });

TEST(McapWriter, ClosesChunksByLogTime) {
  const std::string path = TempPath("by_time.mcap");
  McapWriterOptions options;
  options.chunk_bytes = uint64_t{1} << 30;
  std::vector<Msg> messages;
  for (int i = 0; i <= 35; ++i) messages.push_back({1, 5'000'000'000 + uint64_t(i) * 100'000'000, 0, "x"});
  EXPECT_EQ(WriteMessages(path, options, messages), 3u);
  McapReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, McapReaderOptions{}, &error)) << error;
  ASSERT_EQ(reader.chunks().size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(reader.chunks()[i].message_start_ns, 5'000'000'000 + i * 1'000'000'000);
    EXPECT_EQ(reader.chunks()[i].message_end_ns, std::min<uint64_t>(5'900'000'000 + i * 1'000'000'000, 8'500'000'000));
  }
}

TEST(McapWriter, FlushClosesAQuietChunkAfterItsAge) {
  const std::string path = TempPath("flush.mcap");
  McapWriter writer;
  std::string error;
  ASSERT_TRUE(writer.Open(path, McapWriterOptions{}, &error)) << error;
  const uint16_t channel = writer.AddChannel(0, "/events", "json", {}, &error);
  ASSERT_TRUE(writer.Write(channel, 10'000'000'000, 10'000'000'000, "{}", &error)) << error;
  // Younger than a second: still open, and not on disk.
  ASSERT_TRUE(writer.Flush(10'999'999'999, &error)) << error;
  EXPECT_EQ(writer.num_chunks(), 0u);
  McapReader reader;
  ASSERT_TRUE(reader.Open(path, McapReaderOptions{}, &error)) << error;
  EXPECT_EQ(reader.statistics().num_messages, 0u);
  EXPECT_NE(reader.recovery_note(), "");
  // A second old: closed and readable while the writer still writes.
  ASSERT_TRUE(writer.Flush(11'000'000'000, &error)) << error;
  EXPECT_EQ(writer.num_chunks(), 1u);
  ASSERT_TRUE(reader.Open(path, McapReaderOptions{}, &error)) << error;
  EXPECT_FALSE(reader.indexed());
  EXPECT_EQ(reader.statistics().num_messages, 1u);
  EXPECT_NE(reader.recovery_note().find("without a DataEnd"), std::string::npos) << reader.recovery_note();
  EXPECT_TRUE(writer.Close(&error)) << error;
}

TEST(McapWriter, ClosesChunksBySize) {
  const std::string path = TempPath("by_size.mcap");
  McapWriterOptions options;
  options.chunk_bytes = 1000;
  options.compress = false;
  // Message records of 9 + 22 + 100 bytes: a chunk closes at its 8th (1048 bytes).
  std::vector<Msg> messages;
  for (int i = 0; i < 20; ++i) messages.push_back({1, uint64_t(i), 0, std::string(100, 'm')});
  EXPECT_EQ(WriteMessages(path, options, messages), 2u);
  McapReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, McapReaderOptions{}, &error)) << error;
  ASSERT_EQ(reader.chunks().size(), 3u);
  EXPECT_EQ(reader.chunks()[0].num_messages, 8u);
  EXPECT_EQ(reader.chunks()[0].uncompressed_bytes, 8u * 131);
  EXPECT_EQ(reader.chunks()[2].num_messages, 4u);
}

TEST(McapReader, IndexedSeekEqualsScan) {
  const std::string path = TempPath("seek.mcap");
  const std::vector<Msg> messages = MakeMessages(3000);
  WriteMessages(path, SmallChunks(true), messages);
  McapReader indexed, scanned;
  std::string error;
  ASSERT_TRUE(indexed.Open(path, McapReaderOptions{}, &error)) << error;
  ASSERT_TRUE(scanned.Open(path, Scanning(), &error)) << error;
  ASSERT_TRUE(indexed.indexed());
  ASSERT_FALSE(scanned.indexed());
  const uint64_t t0 = messages.front().log_ns - 10'000'000;
  uint32_t seed = 7;
  for (int q = 0; q < 60; ++q) {
    seed = seed * 1664525u + 1013904223u;
    const uint64_t start = t0 + seed % 3'100'000'000ull;
    const uint64_t end = start + (seed >> 7) % 700'000'000;
    std::vector<uint16_t> channels;
    for (uint16_t c = 1; c <= 3; ++c) {
      if ((seed >> (20 + c)) & 1) channels.push_back(c);
    }
    const std::vector<Msg> a = ReadAll(indexed, &error, start, end, channels);
    ASSERT_EQ(error, "");
    const std::vector<Msg> b = ReadAll(scanned, &error, start, end, channels);
    ASSERT_EQ(error, "");
    EXPECT_TRUE(a == b) << "query " << q;
    EXPECT_TRUE(a == Expected(messages, start, end, channels)) << "query " << q;
  }
}

// Chunk i of a file, in file order.
std::vector<McapChunkInfo> ChunksInFileOrder(const std::string& path) {
  McapReader reader;
  std::string error;
  EXPECT_TRUE(reader.Open(path, McapReaderOptions{}, &error)) << error;
  std::vector<McapChunkInfo> chunks = reader.chunks();
  std::sort(chunks.begin(), chunks.end(), [](const auto& a, const auto& b) { return a.offset < b.offset; });
  return chunks;
}

TEST(McapReader, CutFileRecoversEveryCompleteChunk) {
  const std::string path = TempPath("cut_source.mcap");
  const std::vector<Msg> messages = MakeMessages(2000);
  WriteMessages(path, SmallChunks(true), messages);
  const std::string bytes = ReadFile(path);
  const std::vector<McapChunkInfo> chunks = ChunksInFileOrder(path);
  ASSERT_GT(chunks.size(), 10u);
  // Cut inside chunk k, at its start, and just after it (inside its message indexes).
  const std::string cut_path = TempPath("cut.mcap");
  size_t before = 0;
  for (size_t k = 0; k < chunks.size(); ++k) {
    for (const uint64_t cut :
         {chunks[k].offset + chunks[k].length / 2, chunks[k].offset, chunks[k].offset + chunks[k].length + 5}) {
      const bool kept_k = cut > chunks[k].offset + chunks[k].length;
      WriteFile(cut_path, bytes.substr(0, cut));
      McapReader reader;
      std::string error;
      ASSERT_TRUE(reader.Open(cut_path, McapReaderOptions{}, &error)) << error;
      EXPECT_FALSE(reader.indexed());
      EXPECT_NE(reader.recovery_note(), "");
      const size_t num = before + (kept_k ? chunks[k].num_messages : 0);
      EXPECT_EQ(reader.statistics().num_messages, num) << "cut at " << cut;
      const std::vector<Msg> read = ReadAll(reader, &error);
      EXPECT_EQ(error, "");
      EXPECT_TRUE(read == Expected(std::vector<Msg>(messages.begin(), messages.begin() + num))) << "cut at " << cut;
      // The note names the byte where reading stopped.
      if (cut == chunks[k].offset + chunks[k].length / 2 && cut != bytes.size()) {
        EXPECT_NE(reader.recovery_note().find("byte " + std::to_string(chunks[k].offset)), std::string::npos)
            << reader.recovery_note();
      }
    }
    before += chunks[k].num_messages;
  }
}

TEST(McapReader, FileOfACrashedWriterKeepsItsClosedChunks) {
  const std::string path = TempPath("crash.mcap");
  McapWriterOptions options;
  options.sync = true;
  const std::vector<Msg> messages = MakeMessages(2500);  // 2.5 s of log time
  McapWriter writer;
  std::string error;
  ASSERT_TRUE(writer.Open(path, options, &error)) << error;
  ASSERT_EQ(writer.AddChannel(0, "/device", "x-test", {}, &error), 1);
  ASSERT_EQ(writer.AddChannel(0, "/mesh", "x-test", {}, &error), 2);
  ASSERT_EQ(writer.AddChannel(0, "/events", "x-test", {}, &error), 3);
  for (const Msg& m : messages) ASSERT_TRUE(writer.Write(m.channel, m.log_ns, m.publish_ns, m.data, &error));
  // The file as a crash now would leave it: the two closed chunks (about 2 s), not the open one.
  EXPECT_EQ(writer.num_chunks(), 2u);
  const std::string copy = TempPath("crash_copy.mcap");
  WriteFile(copy, ReadFile(path));
  McapReader reader;
  ASSERT_TRUE(reader.Open(copy, McapReaderOptions{}, &error)) << error;
  const std::vector<Msg> read = ReadAll(reader, &error);
  EXPECT_GE(read.size(), 1990u);
  EXPECT_LE(read.size(), 2010u);
  EXPECT_TRUE(read == Expected(std::vector<Msg>(messages.begin(), messages.begin() + read.size())));
  // Flushed a second after the last message, everything is there.
  ASSERT_TRUE(writer.Flush(messages.back().log_ns + 1'000'000'000, &error)) << error;
  WriteFile(copy, ReadFile(path));
  ASSERT_TRUE(reader.Open(copy, McapReaderOptions{}, &error)) << error;
  EXPECT_TRUE(ReadAll(reader, &error) == Expected(messages));
  EXPECT_TRUE(writer.Close(&error)) << error;
}

// A byte of the file flipped.
std::string Flipped(std::string bytes, size_t at) {
  bytes[at] = static_cast<char>(bytes[at] ^ 0x5A);
  return bytes;
}

TEST(McapReader, DamagedChunkReportsItsOffset) {
  const std::string path = TempPath("crc_source.mcap");
  WriteMessages(path, SmallChunks(false), MakeMessages(800));
  const std::string bytes = ReadFile(path);
  const McapChunkInfo chunk = ChunksInFileOrder(path)[2];
  // Inside the first message's data: records start after 9 + 8 + 8 + 8 + 4 + 4 + 0 + 8 bytes.
  const std::string damaged = TempPath("crc.mcap");
  WriteFile(damaged, Flipped(bytes, chunk.offset + 49 + 31 + 2));
  const std::string where = damaged + ": byte " + std::to_string(chunk.offset) + ": Chunk record: uncompressed CRC";
  // Through the index: found when the chunk is read.
  McapReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(damaged, McapReaderOptions{}, &error)) << error;
  ReadAll(reader, &error);
  EXPECT_EQ(error.rfind(where, 0), 0u) << error;
  McapMessage m;
  EXPECT_FALSE(reader.Next(&m, &error));  // and it stays failed
  EXPECT_EQ(error.rfind(where, 0), 0u) << error;
  // By a scan: found at Open.
  EXPECT_FALSE(reader.Open(damaged, Scanning(), &error));
  EXPECT_EQ(error.rfind(where, 0), 0u) << error;
}

TEST(McapReader, DamagedZstdChunkReportsItsOffset) {
  const std::string path = TempPath("zstd_source.mcap");
  WriteMessages(path, SmallChunks(true), MakeMessages(800));
  const McapChunkInfo chunk = ChunksInFileOrder(path)[1];
  const std::string damaged = TempPath("zstd_damaged.mcap");
  WriteFile(damaged, Flipped(ReadFile(path), chunk.offset + chunk.length - 20));
  McapReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(damaged, McapReaderOptions{}, &error)) << error;
  ReadAll(reader, &error);
  EXPECT_EQ(error.rfind(damaged + ": byte " + std::to_string(chunk.offset) + ": Chunk record: ", 0), 0u) << error;
}

TEST(McapReader, DamagedSummaryAndDataSectionAreReported) {
  const std::string path = TempPath("summary_source.mcap");
  WriteMessages(path, SmallChunks(true), MakeMessages(500));
  const std::string bytes = ReadFile(path);
  const uint64_t summary_start = U64At(bytes, bytes.size() - 8 - 20);
  const std::string damaged = TempPath("summary_damaged.mcap");
  McapReader reader;
  std::string error;
  // A byte of the summary: the footer's CRC catches it.
  WriteFile(damaged, Flipped(bytes, summary_start + 40));
  EXPECT_FALSE(reader.Open(damaged, McapReaderOptions{}, &error));
  EXPECT_EQ(error.rfind(damaged + ": byte " + std::to_string(summary_start) + ": summary CRC", 0), 0u) << error;
  // A byte of a message index (outside any chunk): the scan's data section CRC catches it.
  const McapChunkInfo chunk = ChunksInFileOrder(path)[0];
  WriteFile(damaged, Flipped(bytes, chunk.offset + chunk.length + 9 + 2 + 4 + 3));
  EXPECT_FALSE(reader.Open(damaged, Scanning(), &error));
  EXPECT_NE(error.find(": DataEnd: data section CRC"), std::string::npos) << error;
}

// A summary that contradicts itself (a Statistics count the message indexes do not add up to)
// is not trusted: the file is scanned, every message is read, and index_note() says why.
TEST(McapReader, SummaryThatDisagreesWithItsIndexesIsNotTrusted) {
  const std::string path = TempPath("stats_source.mcap");
  const std::vector<Msg> messages = MakeMessages(500);
  WriteMessages(path, SmallChunks(true), messages);
  std::string bytes = ReadFile(path);
  // The Statistics record's message_count, one too many; the summary CRC zeroed (not checked).
  const size_t footer = bytes.size() - 8 - 20 - 9;
  size_t at = U64At(bytes, footer + 9);
  while (static_cast<uint8_t>(bytes[at]) != 0x0B) at += 9 + U64At(bytes, at + 1);
  bytes[at + 9] = static_cast<char>(bytes[at + 9] + 1);
  for (int i = 0; i < 4; ++i) bytes[footer + 9 + 16 + i] = 0;
  McapReader reader;
  std::string error;
  ASSERT_TRUE(reader.OpenBuffer(bytes, "stats.mcap", McapReaderOptions{}, &error)) << error;
  EXPECT_FALSE(reader.indexed());
  EXPECT_EQ(reader.index_note(), "the Statistics record counts 501 messages, the message indexes 500");
  EXPECT_EQ(reader.statistics().num_messages, 500u);
  EXPECT_TRUE(ReadAll(reader, &error) == Expected(messages));
  EXPECT_EQ(error, "");
}

TEST(McapReader, RejectsGarbageAndOversizeFiles) {
  const std::string path = TempPath("garbage.mcap");
  McapReader reader;
  std::string error;
  // Not MCAP at all, empty, or only the magic.
  std::string garbage;
  for (int i = 0; i < 1000; ++i) garbage.push_back(static_cast<char>(i * 37 + 11));
  WriteFile(path, garbage);
  EXPECT_FALSE(reader.Open(path, McapReaderOptions{}, &error));
  EXPECT_EQ(error, path + ": byte 0: not an MCAP file (it does not start with the magic 89 4D 43 41 50 30 0D 0A)");
  WriteFile(path, "");
  EXPECT_FALSE(reader.Open(path, McapReaderOptions{}, &error));
  EXPECT_NE(error.find("byte 0: not an MCAP file"), std::string::npos);
  WriteFile(path, std::string("\x89MCAP0\r\n", 8));
  EXPECT_FALSE(reader.Open(path, McapReaderOptions{}, &error));
  EXPECT_EQ(error, path + ": byte 8: the Header record is missing or cut short");
  EXPECT_FALSE(reader.Open(TempPath("does_not_exist.mcap"), McapReaderOptions{}, &error));
  EXPECT_NE(error.find("cannot open"), std::string::npos);
  // A real file over the size limit, and one with a chunk over the record limit.
  WriteMessages(path, SmallChunks(false), MakeMessages(300));
  McapReaderOptions small;
  small.max_file_bytes = fs::file_size(path) - 1;
  EXPECT_FALSE(reader.Open(path, small, &error));
  EXPECT_EQ(error, path + ": byte 0: the file is " + std::to_string(fs::file_size(path)) + " bytes, the limit is " +
                       std::to_string(small.max_file_bytes));
  McapReaderOptions tight = Scanning();
  tight.max_record_bytes = 1000;
  EXPECT_FALSE(reader.Open(path, tight, &error));
  EXPECT_NE(error.find("Chunk record of "), std::string::npos) << error;
  EXPECT_NE(error.find("exceeds the limit of 1000"), std::string::npos) << error;
  // A chunk whose length prefix was overwritten: past the end by a scan, not a chunk by the index.
  const std::string bytes = ReadFile(path);
  const McapChunkInfo chunk = ChunksInFileOrder(path)[1];
  std::string huge = bytes;
  huge[chunk.offset + 8] = '\x40';
  WriteFile(path, huge);
  EXPECT_FALSE(reader.Open(path, Scanning(), &error));
  EXPECT_EQ(error.rfind(path + ": byte " + std::to_string(chunk.offset) + ": Chunk record (opcode 6) of ", 0), 0u)
      << error;
  EXPECT_NE(error.find("extends past the end of the file"), std::string::npos) << error;
  ASSERT_TRUE(reader.Open(path, McapReaderOptions{}, &error)) << error;
  ReadAll(reader, &error);
  EXPECT_EQ(error, path + ": byte " + std::to_string(chunk.offset) + ": the chunk index points here, but no Chunk " +
                       "record of " + std::to_string(chunk.length) + " bytes starts here");
}

TEST(McapReader, EmptyRecording) {
  const std::string path = TempPath("empty.mcap");
  WriteMessages(path, McapWriterOptions{}, {});
  for (const McapReaderOptions& options : {McapReaderOptions{}, Scanning()}) {
    McapReader reader;
    std::string error;
    ASSERT_TRUE(reader.Open(path, options, &error)) << error;
    EXPECT_EQ(reader.indexed(), options.use_summary);
    EXPECT_EQ(reader.statistics().num_messages, 0u);
    EXPECT_EQ(reader.channels().size(), 3u);
    EXPECT_TRUE(ReadAll(reader, &error).empty());
    EXPECT_EQ(error, "");
  }
}

// Every prefix and every single-byte change of a small file: Open and reading either succeed or
// fail with a message, never crash, and messages always come in log-time order.
TEST(McapReader, SurvivesEveryTruncationAndByteFlip) {
  const std::string path = TempPath("sweep.mcap");
  McapWriterOptions options = SmallChunks(true);
  options.chunk_bytes = 400;
  WriteMessages(path, options, MakeMessages(60));
  const std::string bytes = ReadFile(path);
  ASSERT_LT(bytes.size(), 8000u);
  const auto check = [](std::string input, const McapReaderOptions& reader_options) {
    McapReader reader;
    std::string error;
    if (!reader.OpenBuffer(std::move(input), "sweep", reader_options, &error)) {
      EXPECT_NE(error, "");
      return;
    }
    McapMessage m;
    uint64_t last = 0;
    while (reader.Next(&m, &error)) {
      EXPECT_GE(m.log_time_ns, last);
      last = m.log_time_ns;
    }
  };
  for (size_t n = 0; n <= bytes.size(); ++n) check(bytes.substr(0, n), McapReaderOptions{});
  for (size_t at = 0; at < bytes.size(); ++at) {
    check(Flipped(bytes, at), McapReaderOptions{});
    check(Flipped(bytes, at), Scanning());
  }
}

// The files tests/protocol/mcap_check.py checks (CTest test mcap.python_check): written into
// $IDMS_MCAP_CHECK_DIR by the CTest fixture mcap.write_check_files.
TEST(McapCheck, WriteFiles) {
  const char* dir = std::getenv("IDMS_MCAP_CHECK_DIR");
  if (dir == nullptr) GTEST_SKIP() << "IDMS_MCAP_CHECK_DIR not set";
  fs::create_directories(dir);
  for (const bool compress : {false, true}) {
    McapWriterOptions options = SmallChunks(compress);
    options.profile = "x-idms-test";
    WriteMessages((fs::path(dir) / (compress ? "zstd.mcap" : "uncompressed.mcap")).string(), options,
                  MakeMessages(1500));
  }
  WriteMessages((fs::path(dir) / "empty.mcap").string(), McapWriterOptions{}, {});
}

}  // namespace
}  // namespace idms
