// The inside of McapReader, shared by mcap_reader.cc (opening, chunks, iteration) and
// mcap_reader_summary.cc (the summary and the scan).
#pragma once

#include <zstd.h>

#include <cstdint>
#include <deque>
#include <map>
#include <queue>
#include <string>
#include <string_view>
#include <vector>

#include "idms/protocol/mcap.h"
#include "mcap_internal.h"

namespace idms {

// Where a record lies, for messages: in the file, or inside a chunk's decompressed records.
struct McapPlace {
  bool in_chunk = false;
  uint64_t chunk_offset = 0;  // file offset of the Chunk record
  std::string At(uint64_t pos) const;
};

// Where a chunk's message indexes are, from its ChunkIndex record: (channel, file offset) pairs
// and the length of all of them.
struct McapIndexLocation {
  std::vector<std::pair<uint16_t, uint64_t>> offsets;
  uint64_t length = 0;
};

struct McapReader::Impl {
  McapReaderOptions options;
  std::string name;  // the path, or the buffer's name: every error starts with it
  int fd = -1;
  std::string memory;
  bool in_memory = false;
  uint64_t size = 0;
  ZSTD_DCtx* dctx = nullptr;

  // What Open() found.
  std::string profile, library;
  uint64_t data_start = 0;  // after the Header record
  std::map<uint16_t, McapSchema> schemas;
  std::map<uint16_t, McapChannel> channels;
  std::vector<std::pair<std::string, std::map<std::string, std::string>>> metadata;
  McapStatistics stats;
  std::vector<McapChunkInfo> chunks;
  bool indexed = false;
  std::string recovery_note;

  // A chunk held while its messages are merged; slots are reused so that buffers keep their capacity.
  struct Loaded {
    std::string raw;           // the record as read (file sources)
    std::string decompressed;  // zstd chunks
    uint64_t remaining = 0;    // messages not yet returned
    uint64_t held_bytes = 0;
  };
  struct Pending {
    uint64_t chunk_offset;
    uint64_t record_offset;
    McapMessage message;
    uint32_t slot;
  };
  // Heap order: log time, then file order.
  struct Later {
    bool operator()(const Pending& a, const Pending& b) const {
      if (a.message.log_time_ns != b.message.log_time_ns) return a.message.log_time_ns > b.message.log_time_ns;
      if (a.chunk_offset != b.chunk_offset) return a.chunk_offset > b.chunk_offset;
      return a.record_offset > b.record_offset;
    }
  };

  // Iteration state.
  uint64_t range_start = 0;
  uint64_t range_end = UINT64_MAX;
  std::vector<bool> wanted;  // by channel id; empty = all
  size_t next_chunk = 0;
  std::deque<Loaded> slots;  // a deque: message views into a slot survive adding slots
  std::vector<uint32_t> free_slots;
  int64_t release_slot = -1;
  uint64_t held_bytes = 0;
  std::priority_queue<Pending, std::vector<Pending>, Later> heap;
  std::string iteration_error;
  std::string scratch;  // reads of small records

  ~Impl();

  bool Fail(const std::string& where, const std::string& what, std::string* error) const {
    if (error != nullptr) *error = name + ": " + where + ": " + what;
    return false;
  }
  // Bytes [offset, offset + length) of the file: a view into memory, or read into *buffer.
  bool Read(uint64_t offset, uint64_t length, std::string* buffer, std::string_view* out, std::string* error);

  // mcap_reader.cc
  bool OpenSource(std::string* error);
  bool ReadHeader(std::string* error);
  bool AddSchema(std::string_view content, const McapPlace& place, uint64_t pos, std::string* error);
  bool AddChannel(std::string_view content, const McapPlace& place, uint64_t pos, std::string* error);
  bool ParseMessage(std::string_view content, const McapPlace& place, uint64_t pos, McapMessage* out,
                    std::string* error) const;
  bool ParseMetadata(std::string_view content, uint64_t pos, std::string* error);
  // Decompresses and checks a Chunk record's content into `slot`: *header gets its fields,
  // *records views its records.
  bool DecodeChunk(uint64_t offset, std::string_view content, Loaded& slot, McapChunkInfo* header,
                   std::string_view* records, std::string* error);
  // Calls fn(message, record_offset) for every message of one chunk (or loose run), registering
  // the Schema and Channel records on the way and checking times against the chunk's range.
  template <typename F>
  bool ForEachMessage(const McapChunkInfo& chunk, Loaded& slot, std::string* error, F fn);
  bool LoadChunk(const McapChunkInfo& chunk, std::string* error);
  uint32_t TakeSlot();
  void ReleaseSlot(uint32_t slot);
  void ResetIteration();
  void SortChunks();

  // mcap_reader_summary.cc
  // Reads the summary of a finished file. *scan_instead when it has none or it cannot locate
  // messages (no chunk index, messages outside chunks).
  bool ReadSummary(uint64_t footer_offset, bool* scan_instead, std::string* error);
  bool ReadChunkIndex(std::string_view content, uint64_t pos, uint64_t data_end,
                      std::vector<McapIndexLocation>* locations, std::string* error);
  bool ReadStatistics(std::string_view content, uint64_t pos, std::map<uint16_t, uint64_t>* channel_counts,
                      std::string* error);
  bool ReadMessageIndexes(McapChunkInfo& chunk, const McapIndexLocation& location,
                          std::map<uint16_t, McapChannelStats>& per_channel, std::string* error);
  bool ReadMetadata(uint64_t offset, uint64_t length, std::string* error);
  // Reads the data section record by record. A finished file must be well formed; an unfinished
  // one keeps what precedes its first bad record (recovery_note says which).
  bool Scan(bool finished, std::string* error);
  struct ScanState;
  // One record of the data section; *end_of_data at DataEnd (or a Footer).
  bool ScanRecord(uint8_t op, uint64_t pos, std::string_view record, ScanState& state, bool* end_of_data,
                  std::string* error);
  bool ScanChunk(uint64_t pos, std::string_view content, ScanState& state, std::string* error);
  void StatsFromChannels();
};

// Adds one message's log time to per-channel figures.
inline void CountMessage(uint64_t log_time_ns, McapChannelStats& s) {
  if (s.num_messages == 0 || log_time_ns < s.start_ns) s.start_ns = log_time_ns;
  if (s.num_messages == 0 || log_time_ns > s.end_ns) s.end_ns = log_time_ns;
  ++s.num_messages;
}

std::string Hex32(uint32_t v);

// Frames the records of `bytes` (at file or chunk offset `base`): fn(op, content, pos) for each,
// pos being the record's offset. False with a message at the first record that does not fit.
template <typename F>
bool ForEachRecord(std::string_view bytes, uint64_t base, const McapPlace& place, const std::string& name,
                   std::string* error, F fn) {
  using mcap_internal::kRecordPrefix;
  size_t pos = 0;
  while (pos < bytes.size()) {
    const uint64_t at = base + pos;
    if (bytes.size() - pos < kRecordPrefix) {
      if (error != nullptr) {
        *error = name + ": " + place.At(at) + ": record prefix needs 9 bytes, " + std::to_string(bytes.size() - pos) +
                 " left";
      }
      return false;
    }
    const uint8_t op = static_cast<uint8_t>(bytes[pos]);
    const uint64_t length = mcap_internal::GetU64(bytes.data() + pos + 1);
    if (length > bytes.size() - pos - kRecordPrefix) {
      if (error != nullptr) {
        *error = name + ": " + place.At(at) + ": " + mcap_internal::OpName(op) + " record (opcode " +
                 std::to_string(op) + ") of " + std::to_string(length) + " bytes extends past the end (" +
                 std::to_string(bytes.size() - pos - kRecordPrefix) + " bytes left)";
      }
      return false;
    }
    if (!fn(op, bytes.substr(pos + kRecordPrefix, static_cast<size_t>(length)), at)) return false;
    pos += kRecordPrefix + static_cast<size_t>(length);
  }
  return true;
}

}  // namespace idms
