// The inside of McapReader, shared by mcap_reader.cc (opening, chunks, iteration),
// mcap_reader_summary.cc (the summary and whether it can be trusted) and mcap_reader_scan.cc (the
// scan).
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
  std::string index_note;  // why a finished file was scanned rather than read through its summary

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
  // check_schema: the channel's schema must already be known (the data section's order); the
  // summary and the index route check every channel's schema once all records are in.
  bool AddChannel(std::string_view content, const McapPlace& place, uint64_t pos, std::string* error,
                  bool check_schema = true);
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
  // The file's totals from stats.channels.
  void StatsFromChannels();
  // Forgets what the summary gave, before a scan finds it again.
  void ClearFound();

  // mcap_reader_summary.cc
  // Reads the summary of a finished file and decides whether it can be trusted to locate every
  // message. Returns false on a malformed or damaged summary (with *error); true with *why_not set
  // when the file is valid but its summary does not index it completely (no summary, no message
  // indexes, messages outside chunks, channels the summary does not define, statistics that
  // disagree with the indexes): the caller then scans.
  bool ReadSummary(uint64_t footer_offset, std::string* why_not, std::string* error);
  struct SummaryRecords;
  // The footer and the summary's records (*why_not when the file has no summary).
  bool ReadSummaryRecords(uint64_t footer_offset, SummaryRecords* out, std::string* why_not, std::string* error);
  bool ReadChunkIndex(std::string_view content, uint64_t pos, uint64_t data_end,
                      std::vector<McapIndexLocation>* locations, std::string* error);
  bool ReadStatistics(std::string_view content, uint64_t pos, SummaryRecords* out, std::string* error);
  // "" when the Statistics record's counts equal the message indexes', else how they differ.
  std::string CompareStatistics(const SummaryRecords& summary,
                                const std::map<uint16_t, McapChannelStats>& per_channel) const;
  // Reads the records of the data section that no chunk index covers (Schema, Channel, Metadata;
  // others only framed), so that the index route sees the definitions a scan would. *why_not
  // when one of them holds messages the index cannot locate (a Message record, an unindexed
  // Chunk) or the records do not frame between the indexed chunks. *metadata_records gets the
  // offset and length of each Metadata record.
  bool ReadUnindexed(uint64_t data_end, const std::vector<std::pair<uint64_t, uint64_t>>& covered,
                     std::map<uint64_t, uint64_t>* metadata_records, std::string* why_not, std::string* error);
  // A chunk's message indexes: its channels and message count, and per-channel figures. *why_not
  // when one is for a channel no record outside chunks defines, or a record other than a
  // MessageIndex lies among them.
  bool ReadMessageIndexes(McapChunkInfo& chunk, const McapIndexLocation& location,
                          std::map<uint16_t, McapChannelStats>& per_channel, std::string* why_not, std::string* error);

  // mcap_reader_scan.cc
  // Reads the data section record by record. A finished file must be well formed; an unfinished
  // one keeps what precedes its first bad record (recovery_note says which).
  bool Scan(bool finished, std::string* error);
  struct ScanState;
  // One record of the data section; *end_of_data at DataEnd (or a Footer).
  bool ScanRecord(uint8_t op, uint64_t pos, std::string_view record, ScanState& state, bool* end_of_data,
                  std::string* error);
  bool ScanChunk(uint64_t pos, std::string_view content, ScanState& state, std::string* error);
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
