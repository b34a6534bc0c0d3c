// McapReader's two ways into a file: the summary of a finished file (chunk indexes, message
// indexes, statistics), or a scan of the data section record by record, which is also how the
// complete chunks of an unfinished file are recovered.
#include <algorithm>
#include <set>
#include <string>

#include "mcap_reader_internal.h"

namespace idms {

using namespace mcap_internal;

namespace {

// Chunk fixed fields: start, end, uncompressed size, CRC, compression length, records length.
constexpr uint64_t kChunkFixed = 8 + 8 + 8 + 4 + 4 + 8;

uint32_t GetU32(const char* p) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(p[i]);
  return v;
}

// A map<uint16, uint64> field (`map_bytes` long, just read) entry by entry into add(key, value);
// false with what is wrong when its length is not whole entries within the record.
template <class Add>
bool ReadU16U64Map(Cursor& c, uint32_t map_bytes, const char* record, const char* field, std::string* what,
                   Add add) {
  if (map_bytes % 10 != 0 || map_bytes > c.remaining()) {
    *what = std::string(record) + " record: " + field + " of " + std::to_string(map_bytes) +
            " bytes is not a whole number of entries within the record";
    return false;
  }
  for (uint32_t i = 0; i < map_bytes / 10; ++i) {
    uint16_t key = 0;
    uint64_t value = 0;
    c.U16(&key, field);
    c.U64(&value, field);
    add(key, value);
  }
  return true;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// The summary.

bool McapReader::Impl::ReadSummary(uint64_t footer_offset, bool* scan_instead, std::string* error) {
  // Footer: where the summary and the summary offsets start, and their CRC.
  std::string_view footer;
  if (!Read(footer_offset + kRecordPrefix, kFooterContent, &scratch, &footer, error)) return false;
  const uint64_t summary_start = GetU64(footer.data());
  const uint64_t summary_offset_start = GetU64(footer.data() + 8);
  const uint32_t summary_crc = GetU32(footer.data() + 16);
  const std::string at_footer = "byte " + std::to_string(footer_offset);
  if (summary_start == 0) {
    *scan_instead = true;  // no summary: the data section is all there is
    return true;
  }
  if (summary_start < data_start || summary_start > footer_offset) {
    return Fail(at_footer,
                "Footer: summary_start " + std::to_string(summary_start) + " is outside " + std::to_string(data_start) +
                    ".." + std::to_string(footer_offset),
                error);
  }
  if (summary_offset_start != 0 && (summary_offset_start < summary_start || summary_offset_start > footer_offset)) {
    return Fail(at_footer,
                "Footer: summary_offset_start " + std::to_string(summary_offset_start) + " is outside the summary " +
                    std::to_string(summary_start) + ".." + std::to_string(footer_offset),
                error);
  }
  if (footer_offset - summary_start > options.max_record_bytes) {
    return Fail(at_footer,
                "the summary of " + std::to_string(footer_offset - summary_start) + " bytes exceeds the limit of " +
                    std::to_string(options.max_record_bytes),
                error);
  }
  // The summary CRC covers the summary, the summary offsets and the footer up to the CRC itself.
  std::string buffer;
  std::string_view summary;
  if (!Read(summary_start, footer_offset - summary_start + kRecordPrefix + 16, &buffer, &summary, error)) {
    return false;
  }
  if (summary_crc != 0 && Crc32(0, summary) != summary_crc) {
    return Fail("byte " + std::to_string(summary_start),
                "summary CRC " + Hex32(summary_crc) + " (in the Footer), computed " + Hex32(Crc32(0, summary)) +
                    " (the summary is damaged)",
                error);
  }
  // Summary records, then the summary offsets (only checked to be well framed).
  const uint64_t summary_end = summary_offset_start != 0 ? summary_offset_start : footer_offset;
  std::vector<McapIndexLocation> locations;
  std::vector<std::pair<uint64_t, uint64_t>> metadata_indexes;
  std::map<uint16_t, uint64_t> channel_counts;
  bool has_statistics = false;
  const McapPlace file;
  const auto record = [&](uint8_t op, std::string_view content, uint64_t pos) {
    Cursor c(content, pos + kRecordPrefix);
    switch (op) {
      case kSchema:
        return AddSchema(content, file, pos, error);
      case kChannel:
        return AddChannel(content, file, pos, error);
      case kChunkIndex:
        return ReadChunkIndex(content, pos, summary_start, &locations, error);
      case kStatistics:
        has_statistics = true;
        return ReadStatistics(content, pos, &channel_counts, error);
      case kMetadataIndex: {
        uint64_t offset = 0, length = 0;
        std::string_view n;
        if (!c.U64(&offset, "offset") || !c.U64(&length, "length") || !c.String(&n, "name")) {
          return Fail("MetadataIndex record", c.Error(), error);
        }
        metadata_indexes.emplace_back(offset, length);
        return true;
      }
      default:
        return true;  // AttachmentIndex, future records
    }
  };
  if (!ForEachRecord(summary.substr(0, summary_end - summary_start), summary_start, file, name, error, record) ||
      !ForEachRecord(summary.substr(summary_end - summary_start, footer_offset - summary_end), summary_end, file, name,
                     error, [](uint8_t, std::string_view, uint64_t) { return true; })) {
    return false;
  }
  // Messages outside chunks cannot be indexed: a file with messages but no chunk index is scanned.
  if (chunks.empty() && (!has_statistics || stats.num_messages > 0)) {
    *scan_instead = true;
    return true;
  }
  // Per-channel figures: counts from Statistics, times (and counts) from the message indexes.
  std::map<uint16_t, McapChannelStats> per_channel;
  bool all_indexed = true;
  for (size_t i = 0; i < chunks.size(); ++i) {
    if (!ReadMessageIndexes(chunks[i], locations[i], per_channel, error)) return false;
    all_indexed = all_indexed && chunks[i].channels_known;
  }
  for (const auto& [id, channel] : channels) {
    McapChannelStats& s = stats.channels[id];
    if (all_indexed || !has_statistics) s = per_channel[id];
    if (!all_indexed && has_statistics) s.num_messages = channel_counts[id];
  }
  for (const auto& [id, count] : channel_counts) {
    if (channels.count(id) == 0) {
      return Fail("Statistics record",
                  "counts messages on channel " + std::to_string(id) + ", which the summary does not define", error);
    }
  }
  if (!has_statistics) {
    stats.num_chunks = static_cast<uint32_t>(chunks.size());
    StatsFromChannels();
  }
  // Metadata records, through their index.
  for (const auto& [offset, length] : metadata_indexes) {
    if (!ReadMetadata(offset, length, error)) return false;
  }
  return true;
}

bool McapReader::Impl::ReadChunkIndex(std::string_view content, uint64_t pos, uint64_t data_end,
                                      std::vector<McapIndexLocation>* locations, std::string* error) {
  // Fields.
  const std::string where = "byte " + std::to_string(pos);
  Cursor c(content, pos + kRecordPrefix);
  McapChunkInfo chunk;
  McapIndexLocation location;
  uint32_t map_bytes = 0;
  std::string_view compression;
  if (c.U64(&chunk.message_start_ns, "message_start_time") && c.U64(&chunk.message_end_ns, "message_end_time") &&
      c.U64(&chunk.offset, "chunk_start_offset") && c.U64(&chunk.length, "chunk_length") &&
      c.U32(&map_bytes, "message_index_offsets")) {
    std::string what;
    if (!ReadU16U64Map(c, map_bytes, "ChunkIndex", "message_index_offsets", &what,
                       [&](uint16_t channel, uint64_t offset) { location.offsets.emplace_back(channel, offset); })) {
      return Fail(where, what, error);
    }
  }
  if (!c.U64(&location.length, "message_index_length") || !c.String(&compression, "compression") ||
      !c.U64(&chunk.compressed_bytes, "compressed_size") || !c.U64(&chunk.uncompressed_bytes, "uncompressed_size")) {
    return Fail("ChunkIndex record", c.Error(), error);
  }
  chunk.compression = std::string(compression);
  // The chunk and its message indexes lie in the data section.
  if (chunk.offset < data_start || chunk.offset > data_end || chunk.length < kRecordPrefix + kChunkFixed ||
      chunk.length > data_end - chunk.offset || location.length > data_end - chunk.offset - chunk.length) {
    return Fail(where,
                "ChunkIndex record: the chunk at " + std::to_string(chunk.offset) + " of " +
                    std::to_string(chunk.length) + " bytes with " + std::to_string(location.length) +
                    " bytes of message indexes does not fit the data section " + std::to_string(data_start) + ".." +
                    std::to_string(data_end),
                error);
  }
  if (chunk.message_start_ns > chunk.message_end_ns) {
    return Fail(where, "ChunkIndex record: message_start_time is after message_end_time", error);
  }
  const uint64_t indexes_start = chunk.offset + chunk.length;
  for (const auto& [channel, offset] : location.offsets) {
    if (offset < indexes_start || offset - indexes_start >= location.length) {
      return Fail(where,
                  "ChunkIndex record: the message index of channel " + std::to_string(channel) + " at byte " +
                      std::to_string(offset) + " is not among the records after its chunk",
                  error);
    }
  }
  chunk.channels_known = !location.offsets.empty();
  chunks.push_back(std::move(chunk));
  locations->push_back(std::move(location));
  return true;
}

bool McapReader::Impl::ReadStatistics(std::string_view content, uint64_t pos,
                                      std::map<uint16_t, uint64_t>* channel_counts, std::string* error) {
  Cursor c(content, pos + kRecordPrefix);
  uint16_t schema_count = 0;
  uint32_t channel_count = 0, attachment_count = 0, metadata_count = 0, map_bytes = 0;
  if (!c.U64(&stats.num_messages, "message_count") || !c.U16(&schema_count, "schema_count") ||
      !c.U32(&channel_count, "channel_count") || !c.U32(&attachment_count, "attachment_count") ||
      !c.U32(&metadata_count, "metadata_count") || !c.U32(&stats.num_chunks, "chunk_count") ||
      !c.U64(&stats.start_ns, "message_start_time") || !c.U64(&stats.end_ns, "message_end_time") ||
      !c.U32(&map_bytes, "channel_message_counts")) {
    return Fail("Statistics record", c.Error(), error);
  }
  std::string what;
  if (!ReadU16U64Map(c, map_bytes, "Statistics", "channel_message_counts", &what,
                     [&](uint16_t channel, uint64_t count) { (*channel_counts)[channel] = count; })) {
    return Fail("byte " + std::to_string(pos), what, error);
  }
  return true;
}

bool McapReader::Impl::ReadMessageIndexes(McapChunkInfo& chunk, const McapIndexLocation& location,
                                          std::map<uint16_t, McapChannelStats>& per_channel, std::string* error) {
  if (!chunk.channels_known) return true;
  // All of a chunk's message indexes in one read.
  const uint64_t start = chunk.offset + chunk.length;
  if (location.length > options.max_record_bytes) {
    return Fail("byte " + std::to_string(start),
                "message indexes of " + std::to_string(location.length) + " bytes exceed the record limit", error);
  }
  std::string_view block;
  if (!Read(start, location.length, &scratch, &block, error)) return false;
  std::map<uint64_t, uint16_t> found;  // record offset -> channel
  const auto record = [&](uint8_t op, std::string_view content, uint64_t pos) {
    if (op != kMessageIndex) return true;
    const std::string where = "byte " + std::to_string(pos);
    Cursor c(content, pos + kRecordPrefix);
    uint16_t channel = 0;
    uint32_t bytes = 0;
    if (!c.U16(&channel, "channel_id") || !c.U32(&bytes, "records")) {
      return Fail("MessageIndex record", c.Error(), error);
    }
    if (bytes % 16 != 0 || bytes > c.remaining()) {
      return Fail(where,
                  "MessageIndex record: records of " + std::to_string(bytes) +
                      " bytes is not a whole number of entries within the record",
                  error);
    }
    if (channels.count(channel) == 0) {
      return Fail(where, "MessageIndex for channel " + std::to_string(channel) + ", which the summary does not define",
                  error);
    }
    // Each entry lies in the chunk: its time in the chunk's range, its offset in its records.
    for (uint32_t i = 0; i < bytes / 16; ++i) {
      uint64_t log_time = 0, record_offset = 0;
      c.U64(&log_time, "records");
      c.U64(&record_offset, "records");
      if (log_time < chunk.message_start_ns || log_time > chunk.message_end_ns ||
          record_offset >= chunk.uncompressed_bytes) {
        return Fail(where,
                    "MessageIndex entry (log time " + std::to_string(log_time) + ", offset " +
                        std::to_string(record_offset) + ") lies outside its chunk",
                    error);
      }
      CountMessage(log_time, per_channel[channel]);
      ++chunk.num_messages;
    }
    found[pos] = channel;
    return true;
  };
  if (!ForEachRecord(block, start, McapPlace{}, name, error, record)) return false;
  // The chunk index's offsets name those records.
  for (const auto& [channel, offset] : location.offsets) {
    const auto it = found.find(offset);
    if (it == found.end() || it->second != channel) {
      return Fail(
          "byte " + std::to_string(offset),
          "the chunk index puts the message index of channel " + std::to_string(channel) + " here, but it is not here",
          error);
    }
  }
  std::set<uint16_t> present;
  for (const auto& [offset, channel] : found) present.insert(channel);
  chunk.channels.assign(present.begin(), present.end());
  return true;
}

bool McapReader::Impl::ReadMetadata(uint64_t offset, uint64_t length, std::string* error) {
  const std::string where = "byte " + std::to_string(offset);
  if (offset < data_start || offset > size || length > size - offset || length < kRecordPrefix ||
      length > options.max_record_bytes) {
    return Fail(where, "a MetadataIndex points outside the file or at an oversize record", error);
  }
  std::string_view record;
  if (!Read(offset, length, &scratch, &record, error)) return false;
  if (static_cast<uint8_t>(record[0]) != kMetadata || GetU64(record.data() + 1) != length - kRecordPrefix) {
    return Fail(
        where,
        "a MetadataIndex points here, but no Metadata record of " + std::to_string(length) + " bytes starts here",
        error);
  }
  return ParseMetadata(record.substr(kRecordPrefix), offset, error);
}

void McapReader::Impl::StatsFromChannels() {
  stats.num_messages = 0;
  stats.start_ns = stats.end_ns = 0;
  bool any = false;
  for (const auto& [id, s] : stats.channels) {
    if (s.num_messages == 0) continue;
    stats.num_messages += s.num_messages;
    if (!any || s.start_ns < stats.start_ns) stats.start_ns = s.start_ns;
    if (!any || s.end_ns > stats.end_ns) stats.end_ns = s.end_ns;
    any = true;
  }
}

// ---------------------------------------------------------------------------------------------
// The scan.

struct McapReader::Impl::ScanState {
  std::map<uint16_t, McapChannelStats> per_channel;
  Loaded slot;
  uint32_t crc = 0;  // of every byte before the current record
  // A run of records outside chunks that holds messages: a "loose" pseudo-chunk.
  McapChunkInfo run;
  bool run_open = false;

  void CloseRun(std::vector<McapChunkInfo>& out) {
    if (run_open) out.push_back(run);
    run_open = false;
  }
};

bool McapReader::Impl::Scan(bool finished, std::string* error) {
  ScanState state;
  std::string_view head;
  if (!Read(0, data_start, &scratch, &head, error)) return false;
  state.crc = Crc32(0, head);
  // A finished file must be well formed; an unfinished one ends at its first bad record.
  const auto stop = [&](const std::string& message, bool data_complete = false) {
    if (finished) {
      if (error != nullptr) *error = message;
      return false;
    }
    uint64_t kept = 0;
    for (const McapChunkInfo& c : chunks) kept += c.num_messages;
    if (state.run_open) kept += state.run.num_messages;
    const std::string num_chunks = std::to_string(chunks.size() + (state.run_open ? 1 : 0));
    recovery_note =
        message + (data_complete ? "; kept all " + num_chunks + " chunks (" + std::to_string(kept) + " messages)"
                                 : "; kept the " + num_chunks + " complete chunks (" + std::to_string(kept) +
                                       " messages) before it");
    return true;
  };
  uint64_t pos = data_start;
  while (true) {
    // Framing: a record must fit the file and the limit.
    const std::string where = name + ": byte " + std::to_string(pos) + ": ";
    if (pos == size) {
      if (!stop(where + "the file ends without a DataEnd record (unfinished)")) return false;
      break;
    }
    if (size - pos < kRecordPrefix) {
      if (!stop(where + "a record prefix is cut short (" + std::to_string(size - pos) + " bytes)")) return false;
      break;
    }
    std::string_view prefix;
    if (!Read(pos, kRecordPrefix, &scratch, &prefix, error)) return false;
    const uint8_t op = static_cast<uint8_t>(prefix[0]);
    const uint64_t length = GetU64(prefix.data() + 1);
    if (!finished && op == 0) {
      stop(where + "opcode 0 is no MCAP record (a zero-filled tail after a crash?)");
      break;
    }
    if (length > size - pos - kRecordPrefix) {
      if (!stop(where + OpName(op) + " record (opcode " + std::to_string(op) + ") of " + std::to_string(length) +
                " bytes extends past the end of the file (" + std::to_string(size) + " bytes)")) {
        return false;
      }
      break;
    }
    if (length > options.max_record_bytes) {
      if (!stop(where + OpName(op) + " record of " + std::to_string(length) + " bytes exceeds the limit of " +
                std::to_string(options.max_record_bytes))) {
        return false;
      }
      break;
    }
    // The record.
    std::string_view record;
    if (!Read(pos, kRecordPrefix + length, &state.slot.raw, &record, error)) return false;
    bool end_of_data = false;
    std::string record_error;
    if (!ScanRecord(op, pos, record, state, &end_of_data, &record_error)) {
      if (!stop(record_error)) return false;
      break;
    }
    if (end_of_data) {
      // The data section is whole, but an unfinished file still says so.
      if (!finished) {
        stop(where + OpName(op) +
                 " ends the data section, but the file has no Footer (unfinished, or cut in its "
                 "summary)",
             true);
      }
      break;
    }
    state.crc = Crc32(state.crc, record);
    pos += kRecordPrefix + length;
  }
  state.CloseRun(chunks);
  // Statistics from what was read.
  for (const auto& [id, channel] : channels) stats.channels[id] = state.per_channel[id];
  StatsFromChannels();
  return true;
}

bool McapReader::Impl::ScanRecord(uint8_t op, uint64_t pos, std::string_view record, ScanState& state,
                                  bool* end_of_data, std::string* error) {
  const std::string_view content = record.substr(kRecordPrefix);
  const std::string where = "byte " + std::to_string(pos);
  switch (op) {
    case kHeader:
      return Fail(where, "a second Header record", error);
    case kFooter:
      *end_of_data = true;
      return true;
    case kDataEnd: {
      // The data section CRC covers every byte of the file before this record.
      *end_of_data = true;
      Cursor c(content, pos + kRecordPrefix);
      uint32_t stored = 0;
      if (!c.U32(&stored, "data_section_crc")) return Fail("DataEnd record", c.Error(), error);
      if (stored != 0 && stored != state.crc) {
        return Fail(where,
                    "DataEnd: data section CRC " + Hex32(stored) + ", computed " + Hex32(state.crc) +
                        " (the data section is damaged)",
                    error);
      }
      return true;
    }
    case kChunk:
      state.CloseRun(chunks);
      return ScanChunk(pos, content, state, error);
    case kMessageIndex:
      state.CloseRun(chunks);
      return true;
    case kSchema:
      return AddSchema(content, McapPlace{}, pos, error);
    case kChannel:
      return AddChannel(content, McapPlace{}, pos, error);
    case kMetadata:
      return ParseMetadata(content, pos, error);
    case kMessage: {
      // A message outside chunks: opens or extends the loose run.
      McapMessage m;
      if (!ParseMessage(content, McapPlace{}, pos, &m, error)) return false;
      McapChunkInfo& run = state.run;
      if (!state.run_open) {
        run = McapChunkInfo{};
        run.offset = pos;
        run.loose = true;
        run.channels_known = true;
        run.message_start_ns = run.message_end_ns = m.log_time_ns;
        state.run_open = true;
      }
      run.length = pos + record.size() - run.offset;
      run.compressed_bytes = run.uncompressed_bytes = run.length;
      run.message_start_ns = std::min(run.message_start_ns, m.log_time_ns);
      run.message_end_ns = std::max(run.message_end_ns, m.log_time_ns);
      ++run.num_messages;
      const auto at = std::lower_bound(run.channels.begin(), run.channels.end(), m.channel_id);
      if (at == run.channels.end() || *at != m.channel_id) run.channels.insert(at, m.channel_id);
      CountMessage(m.log_time_ns, state.per_channel[m.channel_id]);
      return true;
    }
    default:
      return true;  // Attachment, index records of other writers, future records
  }
}

bool McapReader::Impl::ScanChunk(uint64_t pos, std::string_view content, ScanState& state, std::string* error) {
  McapChunkInfo chunk;
  std::string_view records;
  if (!DecodeChunk(pos, content, state.slot, &chunk, &records, error)) return false;
  chunk.offset = pos;
  chunk.length = kRecordPrefix + content.size();
  chunk.channels_known = true;
  // Its records: schemas and channels register, messages count (and must lie in its range).
  std::set<uint16_t> present;
  std::map<uint16_t, McapChannelStats> counted;
  const McapPlace place{true, pos};
  const auto record = [&](uint8_t op, std::string_view inner, uint64_t inner_pos) {
    if (op == kSchema) return AddSchema(inner, place, inner_pos, error);
    if (op == kChannel) return AddChannel(inner, place, inner_pos, error);
    if (op != kMessage) return true;
    McapMessage m;
    if (!ParseMessage(inner, place, inner_pos, &m, error)) return false;
    if (m.log_time_ns < chunk.message_start_ns || m.log_time_ns > chunk.message_end_ns) {
      return Fail(place.At(inner_pos),
                  "Message log time " + std::to_string(m.log_time_ns) + " lies outside the chunk's range " +
                      std::to_string(chunk.message_start_ns) + ".." + std::to_string(chunk.message_end_ns),
                  error);
    }
    CountMessage(m.log_time_ns, counted[m.channel_id]);
    ++chunk.num_messages;
    present.insert(m.channel_id);
    return true;
  };
  if (!ForEachRecord(records, 0, place, name, error, record)) return false;
  // Only a whole chunk counts: merge its figures once it has been read without error.
  for (const auto& [id, s] : counted) {
    McapChannelStats& total = state.per_channel[id];
    if (total.num_messages == 0 || s.start_ns < total.start_ns) total.start_ns = s.start_ns;
    if (total.num_messages == 0 || s.end_ns > total.end_ns) total.end_ns = s.end_ns;
    total.num_messages += s.num_messages;
  }
  chunk.channels.assign(present.begin(), present.end());
  chunks.push_back(std::move(chunk));
  ++stats.num_chunks;
  return true;
}

}  // namespace idms
