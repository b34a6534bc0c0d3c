// MCAP (https://mcap.dev/spec, major version 0), written and read from the specification: the
// container idms records sessions in. McapWriter appends zstd chunks with message and chunk indexes
// and a summary, so that a crash loses at most the open chunk; McapReader checks every length, CRC
// and offset, reads by log time through the index, and recovers the complete chunks of an
// unfinished file by scanning. Generic: recording.h puts idms's channels on top.
#pragma once

#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace idms {

// How a channel's messages are encoded. Protobuf (what idms writes): encoding "protobuf", name the
// full message name ("idms.v1.DeviceSamples"), data a serialized google.protobuf.FileDescriptorSet
// holding the message's file and every file it imports.
struct McapSchema {
  uint16_t id = 0;  // >= 1 (0 means "no schema" and is never a schema's id)
  std::string name;
  std::string encoding;
  std::string data;
};

// A stream of messages on a topic, all encoded one way.
struct McapChannel {
  uint16_t id = 0;
  uint16_t schema_id = 0;  // 0 = no schema
  std::string topic;
  std::string message_encoding;  // "protobuf" for idms
  std::map<std::string, std::string> metadata;
};

// One message as read. `data` points into the reader's buffers: valid until the next call on it.
struct McapMessage {
  uint16_t channel_id = 0;
  uint32_t sequence = 0;         // per channel, from 0, assigned by McapWriter
  uint64_t log_time_ns = 0;      // when it was recorded; the order of iteration
  uint64_t publish_time_ns = 0;  // when it was sent
  std::string_view data;
};

struct McapWriterOptions {
  std::string profile;           // Header.profile; "" = no well-known profile (idms's case)
  std::string library = "idms";  // Header.library
  bool compress = true;          // zstd chunks; a chunk zstd does not shrink is stored uncompressed anyway
  int zstd_level = 3;
  // A chunk is closed (compressed, written with its message indexes, flushed) when its
  // uncompressed records reach chunk_bytes, or when its oldest message is chunk_max_age_ns older
  // than a new message's log time or than the `now_ns` of Flush().
  uint64_t chunk_bytes = uint64_t{1} << 20;
  uint64_t chunk_max_age_ns = 1'000'000'000;
  // fdatasync after every chunk and at Close: survives power loss, not only a process crash.
  bool sync = false;
};

// Writes one MCAP file:
//   magic, Header, Schema and Channel records (as registered), Metadata records,
//   { Chunk (Message records, zstd), MessageIndex per channel }...,
//   DataEnd (data CRC), summary (Schemas, Channels, ChunkIndexes, MetadataIndexes, Statistics),
//   SummaryOffsets, Footer (summary CRC), magic.
// Everything before the open chunk is flushed to the kernel when a chunk closes (and synced with
// options.sync), so a crash loses at most the open chunk; McapReader reads such a file by scanning.
// Owned by one thread. Write() copies into the open chunk (amortised: no allocation once the chunk
// buffer has grown); closing a chunk compresses and does file I/O. Not for the 1 kHz loop.
// After an I/O error every call fails with that error; the file is left as a crash would leave it.
class McapWriter {
 public:
  McapWriter();
  ~McapWriter();  // finishes an open file (Close), ignoring errors
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;

  // Creates (truncates) `path` and writes the magic and Header.
  bool Open(const std::string& path, const McapWriterOptions& options, std::string* error);

  // Registers a schema or channel and writes its record at once (outside chunks, so it precedes
  // every message that refers to it). Returns its id (from 1), or 0 with *error.
  uint16_t AddSchema(std::string_view name, std::string_view encoding, std::string_view data, std::string* error);
  uint16_t AddChannel(uint16_t schema_id, std::string_view topic, std::string_view message_encoding,
                      const std::map<std::string, std::string>& metadata, std::string* error);
  // A Metadata record (name and key-value pairs, e.g. the session's scene), indexed in the summary.
  bool AddMetadata(std::string_view name, const std::map<std::string, std::string>& metadata, std::string* error);

  // Appends a message to the open chunk. Closes the chunk first if log_time_ns is
  // chunk_max_age_ns or more after the chunk's oldest message, and after appending if the chunk
  // reached chunk_bytes. Log times need not increase (the reader sorts by them).
  bool Write(uint16_t channel_id, uint64_t log_time_ns, uint64_t publish_time_ns, std::string_view data,
             std::string* error);
  // Call periodically (e.g. every 100 ms) with the current time on the log-time clock: closes the
  // open chunk if its oldest message is chunk_max_age_ns old, so a quiet session still reaches the
  // disk within about a second, and flushes the file to the kernel.
  bool Flush(uint64_t now_ns, std::string* error);
  // Closes the open chunk now (if it holds a message).
  bool CloseChunk(std::string* error);
  // Closes the open chunk and writes DataEnd, the summary and the footer; closes the file.
  bool Close(std::string* error);

  bool is_open() const;
  uint64_t num_messages() const;
  uint32_t num_chunks() const;        // closed so far
  uint64_t bytes_written() const;     // to the file so far (the open chunk not included)
  uint64_t open_chunk_bytes() const;  // uncompressed records in the open chunk

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct McapReaderOptions {
  uint64_t max_file_bytes = uint64_t{1} << 40;
  // Largest record accepted, and largest decompressed chunk and summary section: bounds what a
  // malformed file can make the reader allocate. Merging chunks that overlap in time holds at
  // most 4x this at once.
  uint64_t max_record_bytes = uint64_t{256} << 20;
  bool use_summary = true;  // false: ignore the summary and scan the data section
};

// One chunk (or, in a scanned file, one run of messages outside chunks).
struct McapChunkInfo {
  uint64_t offset = 0;  // file offset of the Chunk record (of the run's first record)
  uint64_t length = 0;  // bytes, opcode and length prefix included
  uint64_t message_start_ns = 0;
  uint64_t message_end_ns = 0;
  std::string compression;  // "zstd" or "" (none)
  uint64_t compressed_bytes = 0;
  uint64_t uncompressed_bytes = 0;
  uint64_t num_messages = 0;       // from the message indexes (scanned: counted)
  std::vector<uint16_t> channels;  // that have messages in it, ascending
  bool loose = false;              // a run of Message records outside chunks (scanned files only)
};

struct McapChannelStats {
  uint64_t num_messages = 0;
  uint64_t start_ns = 0;  // earliest and latest log time, 0 when unknown or no messages
  uint64_t end_ns = 0;
};

struct McapStatistics {
  uint64_t num_messages = 0;
  uint64_t start_ns = 0;  // earliest and latest log time of the file, 0 when empty
  uint64_t end_ns = 0;
  uint32_t num_chunks = 0;
  std::map<uint16_t, McapChannelStats> channels;  // every channel, by id
};

// Reads one MCAP file. Open() validates the structure it reads (magic, record framing and lengths,
// offsets, the summary CRC; a scan also checks chunk CRCs and the data CRC); Next() checks each
// chunk's CRC and decompressed size as it loads it. Errors name the file and the byte offset:
//   "rec.mcap: byte 1234: Chunk record: uncompressed CRC 0x1a2b3c4d, computed 0x55aa0f0f".
// A finished file is read through its summary when the summary locates every message: a chunk
// index and message indexes for every chunk, no Message record outside chunks, every channel and
// schema defined outside chunks, Statistics (if any) agreeing with the message indexes. The
// specification makes all of these optional; a finished file that lacks one is scanned (and
// index_note() says why), so that no reader ever sees fewer messages than the file holds.
// A file without footer (the writer crashed or is still writing) is scanned from the start and
// keeps every complete chunk before the first truncated or damaged record; recovery_note() says
// where reading stopped and why. Owned by one thread; reads with pread, so several readers may
// share a file.
class McapReader {
 public:
  McapReader();
  ~McapReader();
  McapReader(const McapReader&) = delete;
  McapReader& operator=(const McapReader&) = delete;

  bool Open(const std::string& path, const McapReaderOptions& options, std::string* error);
  // The same on bytes in memory (tests, fuzzing, a download); `name` stands for the file in errors.
  bool OpenBuffer(std::string bytes, std::string_view name, const McapReaderOptions& options, std::string* error);

  const std::string& profile() const;
  const std::string& library() const;
  const std::map<uint16_t, McapSchema>& schemas() const;
  const std::map<uint16_t, McapChannel>& channels() const;
  // Metadata records in file order: name, key-value pairs.
  const std::vector<std::pair<std::string, std::map<std::string, std::string>>>& metadata() const;
  const McapStatistics& statistics() const;
  // Sorted by message_start_ns, then offset.
  const std::vector<McapChunkInfo>& chunks() const;
  bool indexed() const;  // read through the summary; false = scanned
  // Non-empty for an unfinished file: where the scan stopped and why, and what was kept.
  const std::string& recovery_note() const;
  // Non-empty for a finished file scanned although use_summary was set: why its summary was not
  // used ("the chunk at byte 28 has no message index").
  const std::string& index_note() const;
  // The first channel on `topic`, or nullptr.
  const McapChannel* FindChannel(std::string_view topic) const;
  const McapSchema* FindSchema(uint16_t schema_id) const;

  // Restarts iteration at the messages with start_ns <= log time <= end_ns on `channel_ids`
  // (empty = all). Chunks outside the range, or (by their message index) without those channels,
  // are not read. Iteration starts at the beginning of the file after Open().
  void Seek(uint64_t start_ns, uint64_t end_ns = std::numeric_limits<uint64_t>::max(),
            std::span<const uint16_t> channel_ids = {});
  // The next message in log-time order (ties in file order). False at the end with *error empty,
  // or on malformed data with *error set (iteration then stays at the end until Seek).
  bool Next(McapMessage* out, std::string* error);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace idms
