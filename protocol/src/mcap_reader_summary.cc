// McapReader's index route: the summary of a finished file (chunk indexes, message indexes,
// statistics, metadata indexes), checked against the data section it indexes. A summary that is
// valid but does not locate every message (the MCAP specification makes most of it optional) is
// not trusted, and the file is scanned instead (mcap_reader_scan.cc).
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
bool ReadU16U64Map(Cursor& c, uint32_t map_bytes, const char* record, const char* field, std::string* what, Add add) {
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

// What the summary section holds, before it is checked against the data section.
struct McapReader::Impl::SummaryRecords {
  uint64_t summary_start = 0;
  std::vector<McapIndexLocation> locations;                     // one per chunk, in summary order
  std::vector<std::pair<uint64_t, uint64_t>> metadata_indexes;  // offset, length
  bool has_statistics = false;
  uint64_t message_count = 0;                   // Statistics.message_count
  std::map<uint16_t, uint64_t> channel_counts;  // Statistics.channel_message_counts
};

// ---------------------------------------------------------------------------------------------
// The summary, and whether it can be trusted.

bool McapReader::Impl::ReadSummary(uint64_t footer_offset, std::string* why_not, std::string* error) {
  // The summary's records: definitions, chunk indexes, statistics, metadata indexes.
  SummaryRecords summary;
  if (!ReadSummaryRecords(footer_offset, &summary, why_not, error)) return false;
  if (!why_not->empty()) return true;
  // The data section outside the indexed chunks: the definitions a scan would see, and no message
  // the index would miss.
  std::vector<std::pair<uint64_t, uint64_t>> covered;
  for (size_t i = 0; i < chunks.size(); ++i) {
    covered.emplace_back(chunks[i].offset, chunks[i].offset + chunks[i].length + summary.locations[i].length);
  }
  std::sort(covered.begin(), covered.end());
  std::map<uint64_t, uint64_t> metadata_records;
  if (!ReadUnindexed(summary.summary_start, covered, &metadata_records, why_not, error)) return false;
  if (!why_not->empty()) return true;
  // Every chunk's message indexes: which channels it holds, how many messages and when. Without
  // them a chunk's messages are known only by reading it, which is what a scan does.
  std::map<uint16_t, McapChannelStats> per_channel;
  for (size_t i = 0; i < chunks.size(); ++i) {
    if (summary.locations[i].offsets.empty()) {
      *why_not = "the chunk at byte " + std::to_string(chunks[i].offset) + " has no message index";
      return true;
    }
    if (!ReadMessageIndexes(chunks[i], summary.locations[i], per_channel, why_not, error)) return false;
    if (!why_not->empty()) return true;
  }
  // Every channel's schema is defined.
  for (const auto& [id, channel] : channels) {
    if (channel.schema_id != 0 && schemas.count(channel.schema_id) == 0) {
      *why_not = "Channel " + std::to_string(id) + " (" + channel.topic + ") refers to schema " +
                 std::to_string(channel.schema_id) + ", which no record outside chunks defines";
      return true;
    }
  }
  // Statistics, where given, agree with the message indexes.
  if (summary.has_statistics) {
    *why_not = CompareStatistics(summary, per_channel);
    if (!why_not->empty()) return true;
  }
  // The figures, from the message indexes.
  for (const auto& [id, channel] : channels) stats.channels[id] = per_channel[id];
  stats.num_chunks = static_cast<uint32_t>(chunks.size());
  StatsFromChannels();
  // Each metadata index names a Metadata record (read in file order by ReadUnindexed).
  for (const auto& [offset, length] : summary.metadata_indexes) {
    const auto it = metadata_records.find(offset);
    if (it == metadata_records.end() || it->second != length) {
      return Fail(
          "byte " + std::to_string(offset),
          "a MetadataIndex points here, but no Metadata record of " + std::to_string(length) + " bytes starts here",
          error);
    }
  }
  return true;
}

bool McapReader::Impl::ReadSummaryRecords(uint64_t footer_offset, SummaryRecords* out, std::string* why_not,
                                          std::string* error) {
  // Footer: where the summary and the summary offsets start, and their CRC.
  std::string_view footer;
  if (!Read(footer_offset + kRecordPrefix, kFooterContent, &scratch, &footer, error)) return false;
  const uint64_t summary_start = GetU64(footer.data());
  const uint64_t summary_offset_start = GetU64(footer.data() + 8);
  const uint32_t summary_crc = GetU32(footer.data() + 16);
  const std::string at_footer = "byte " + std::to_string(footer_offset);
  if (summary_start == 0) {
    *why_not = "the file has no summary";
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
  out->summary_start = summary_start;
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
  // Summary records, then the summary offsets (only checked to be well framed). A channel's schema
  // may be defined later in the summary or only in the data section: checked once all are in.
  const uint64_t summary_end = summary_offset_start != 0 ? summary_offset_start : footer_offset;
  const McapPlace file;
  const auto record = [&](uint8_t op, std::string_view content, uint64_t pos) {
    Cursor c(content, pos + kRecordPrefix);
    switch (op) {
      case kSchema:
        return AddSchema(content, file, pos, error);
      case kChannel:
        return AddChannel(content, file, pos, error, /*check_schema=*/false);
      case kChunkIndex:
        return ReadChunkIndex(content, pos, summary_start, &out->locations, error);
      case kStatistics:
        out->has_statistics = true;
        return ReadStatistics(content, pos, out, error);
      case kMetadataIndex: {
        uint64_t offset = 0, length = 0;
        std::string_view n;
        if (!c.U64(&offset, "offset") || !c.U64(&length, "length") || !c.String(&n, "name")) {
          return Fail("MetadataIndex record", c.Error(), error);
        }
        out->metadata_indexes.emplace_back(offset, length);
        return true;
      }
      default:
        return true;  // AttachmentIndex, future records
    }
  };
  return ForEachRecord(summary.substr(0, summary_end - summary_start), summary_start, file, name, error, record) &&
         ForEachRecord(summary.substr(summary_end - summary_start, footer_offset - summary_end), summary_end, file,
                       name, error, [](uint8_t, std::string_view, uint64_t) { return true; });
}

std::string McapReader::Impl::CompareStatistics(const SummaryRecords& summary,
                                                const std::map<uint16_t, McapChannelStats>& per_channel) const {
  uint64_t in_indexes = 0;
  for (const auto& [id, s] : per_channel) in_indexes += s.num_messages;
  if (summary.message_count != in_indexes) {
    return "the Statistics record counts " + std::to_string(summary.message_count) + " messages, the message indexes " +
           std::to_string(in_indexes);
  }
  for (const auto& [id, count] : summary.channel_counts) {
    if (channels.count(id) == 0) {
      return "the Statistics record counts messages on channel " + std::to_string(id) +
             ", which no record outside chunks defines";
    }
    const auto it = per_channel.find(id);
    const uint64_t found = it == per_channel.end() ? 0 : it->second.num_messages;
    if (found != count) {
      return "the Statistics record counts " + std::to_string(count) + " messages on channel " + std::to_string(id) +
             ", the message indexes " + std::to_string(found);
    }
  }
  return "";
}

bool McapReader::Impl::ReadUnindexed(uint64_t data_end, const std::vector<std::pair<uint64_t, uint64_t>>& covered,
                                     std::map<uint64_t, uint64_t>* metadata_records, std::string* why_not,
                                     std::string* error) {
  std::string buffer;
  uint64_t pos = data_start;
  size_t next = 0;  // the first indexed chunk not yet passed
  while (pos < data_end) {
    // An indexed chunk and its message indexes: read when iterated.
    if (next < covered.size() && covered[next].first == pos) {
      pos = covered[next++].second;
      continue;
    }
    // Anything else must frame up to the next indexed chunk (or the summary).
    const uint64_t limit = next < covered.size() ? covered[next].first : data_end;
    const std::string where = "byte " + std::to_string(pos);
    if (limit < pos) {
      *why_not = "the chunk index at " + std::to_string(limit) + " overlaps the record before it";
      return true;
    }
    if (limit - pos < kRecordPrefix) {
      *why_not = "the records outside chunks at " + where + " do not end at byte " + std::to_string(limit);
      return true;
    }
    std::string_view prefix;
    if (!Read(pos, kRecordPrefix, &buffer, &prefix, error)) return false;
    const uint8_t op = static_cast<uint8_t>(prefix[0]);
    const uint64_t length = GetU64(prefix.data() + 1);
    if (length > limit - pos - kRecordPrefix) {
      *why_not = std::string("the ") + OpName(op) + " record at " + where + " runs past byte " + std::to_string(limit) +
                 (next < covered.size() ? ", where an indexed chunk starts" : ", where the summary starts");
      return true;
    }
    switch (op) {
      case kMessage:
        *why_not = "a Message record at " + where + " lies outside the indexed chunks";
        return true;
      case kChunk:
        *why_not = "the Chunk record at " + where + " has no chunk index";
        return true;
      case kHeader:
      case kFooter:
        *why_not = std::string("a ") + OpName(op) + " record at " + where + " in the data section";
        return true;
      case kDataEnd:
        if (next < covered.size()) *why_not = "a chunk index points after the DataEnd record at " + where;
        return true;
      case kSchema:
      case kChannel:
      case kMetadata: {
        // Definitions and metadata, read as a scan reads them.
        if (length > options.max_record_bytes) {
          return Fail(where,
                      std::string(OpName(op)) + " record of " + std::to_string(length) +
                          " bytes exceeds the limit of " + std::to_string(options.max_record_bytes),
                      error);
        }
        std::string_view record;
        if (!Read(pos, kRecordPrefix + length, &buffer, &record, error)) return false;
        const std::string_view content = record.substr(kRecordPrefix);
        const bool ok = op == kSchema    ? AddSchema(content, McapPlace{}, pos, error)
                        : op == kChannel ? AddChannel(content, McapPlace{}, pos, error, /*check_schema=*/false)
                                         : ParseMetadata(content, pos, error);
        if (!ok) return false;
        if (op == kMetadata) (*metadata_records)[pos] = kRecordPrefix + length;
        break;
      }
      default:
        break;  // Attachment, MessageIndex, future records
    }
    pos += kRecordPrefix + length;
  }
  if (next < covered.size()) *why_not = "a chunk index points past the data section";
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
  chunks.push_back(std::move(chunk));
  locations->push_back(std::move(location));
  return true;
}

bool McapReader::Impl::ReadStatistics(std::string_view content, uint64_t pos, SummaryRecords* out, std::string* error) {
  // Only the counts are used (to check the message indexes); the rest is checked to be there.
  Cursor c(content, pos + kRecordPrefix);
  uint16_t schema_count = 0;
  uint32_t channel_count = 0, attachment_count = 0, metadata_count = 0, chunk_count = 0, map_bytes = 0;
  uint64_t start_ns = 0, end_ns = 0;
  if (!c.U64(&out->message_count, "message_count") || !c.U16(&schema_count, "schema_count") ||
      !c.U32(&channel_count, "channel_count") || !c.U32(&attachment_count, "attachment_count") ||
      !c.U32(&metadata_count, "metadata_count") || !c.U32(&chunk_count, "chunk_count") ||
      !c.U64(&start_ns, "message_start_time") || !c.U64(&end_ns, "message_end_time") ||
      !c.U32(&map_bytes, "channel_message_counts")) {
    return Fail("Statistics record", c.Error(), error);
  }
  std::string what;
  if (!ReadU16U64Map(c, map_bytes, "Statistics", "channel_message_counts", &what,
                     [&](uint16_t channel, uint64_t count) { out->channel_counts[channel] = count; })) {
    return Fail("byte " + std::to_string(pos), what, error);
  }
  return true;
}

bool McapReader::Impl::ReadMessageIndexes(McapChunkInfo& chunk, const McapIndexLocation& location,
                                          std::map<uint16_t, McapChannelStats>& per_channel, std::string* why_not,
                                          std::string* error) {
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
    if (op != kMessageIndex) {
      // Anything else here would be skipped by ReadUnindexed and never read: not indexed.
      *why_not = std::string("a ") + OpName(op) + " record at byte " + std::to_string(pos) +
                 " lies among the message indexes of the chunk at byte " + std::to_string(chunk.offset);
      return false;
    }
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
      *why_not = "the MessageIndex at " + where + " is for channel " + std::to_string(channel) +
                 ", which no record outside chunks defines";
      return false;
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
  if (!ForEachRecord(block, start, McapPlace{}, name, error, record)) return !why_not->empty();
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

}  // namespace idms
