// McapReader's scan: the data section record by record, for files whose summary is missing or
// cannot locate every message, and for the complete chunks of an unfinished file.
#include <algorithm>
#include <set>
#include <string>

#include "mcap_reader_internal.h"

namespace idms {

using namespace mcap_internal;

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
