// McapReader: opens and validates an MCAP file, decodes its chunks, and merges them into one
// log-time-ordered stream of messages. The summary and the scan are in mcap_reader_summary.cc.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include "mcap_reader_internal.h"

namespace idms {

using namespace mcap_internal;

std::string McapPlace::At(uint64_t pos) const {
  if (!in_chunk) return "byte " + std::to_string(pos);
  return "byte " + std::to_string(chunk_offset) + ": Chunk records offset " + std::to_string(pos);
}

std::string Hex32(uint32_t v) {
  char buffer[16];
  std::snprintf(buffer, sizeof buffer, "0x%08x", v);
  return buffer;
}

McapReader::Impl::~Impl() {
  if (fd >= 0) ::close(fd);
  ZSTD_freeDCtx(dctx);
}

bool McapReader::Impl::Read(uint64_t offset, uint64_t length, std::string* buffer, std::string_view* out,
                            std::string* error) {
  if (offset > size || length > size - offset) {
    return Fail(
        "byte " + std::to_string(offset),
        "reading " + std::to_string(length) + " bytes past the end of the file (" + std::to_string(size) + " bytes)",
        error);
  }
  if (in_memory) {
    *out = std::string_view(memory).substr(static_cast<size_t>(offset), static_cast<size_t>(length));
    return true;
  }
  buffer->resize(static_cast<size_t>(length));
  uint64_t done = 0;
  while (done < length) {
    const ssize_t n = ::pread(fd, buffer->data() + done, length - done, static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      return Fail("byte " + std::to_string(offset + done),
                  std::string("read failed: ") + (n < 0 ? std::strerror(errno) : "the file shrank"), error);
    }
    done += static_cast<uint64_t>(n);
  }
  *out = *buffer;
  return true;
}

McapReader::McapReader() : impl_(std::make_unique<Impl>()) {}
McapReader::~McapReader() = default;

bool McapReader::Open(const std::string& path, const McapReaderOptions& options, std::string* error) {
  impl_ = std::make_unique<Impl>();
  Impl& r = *impl_;
  r.options = options;
  r.name = path;
  r.fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (r.fd < 0) {
    if (error != nullptr) *error = path + ": cannot open: " + std::strerror(errno);
    return false;
  }
  struct stat st {};
  if (::fstat(r.fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    if (error != nullptr) *error = path + ": not a regular file";
    return false;
  }
  r.size = static_cast<uint64_t>(st.st_size);
  return r.OpenSource(error);
}

bool McapReader::OpenBuffer(std::string bytes, std::string_view name, const McapReaderOptions& options,
                            std::string* error) {
  impl_ = std::make_unique<Impl>();
  Impl& r = *impl_;
  r.options = options;
  r.name = std::string(name);
  r.memory = std::move(bytes);
  r.in_memory = true;
  r.size = r.memory.size();
  return r.OpenSource(error);
}

bool McapReader::Impl::OpenSource(std::string* error) {
  // Size, magic and Header.
  if (size > options.max_file_bytes) {
    return Fail(
        "byte 0",
        "the file is " + std::to_string(size) + " bytes, the limit is " + std::to_string(options.max_file_bytes),
        error);
  }
  dctx = ZSTD_createDCtx();
  if (!ReadHeader(error)) return false;
  // A finished file ends with a Footer and the magic; anything else is unfinished (the writer
  // crashed, or is still writing) and is scanned.
  const uint64_t tail = kRecordPrefix + kFooterContent + kMagic.size();
  bool finished = false;
  uint64_t footer_offset = 0;
  if (size >= data_start + tail) {
    std::string_view end;
    if (!Read(size - tail, tail, &scratch, &end, error)) return false;
    finished = end.substr(kRecordPrefix + kFooterContent) == kMagic;
    footer_offset = size - tail;
    if (finished && (static_cast<uint8_t>(end[0]) != kFooter || GetU64(end.data() + 1) != kFooterContent)) {
      return Fail("byte " + std::to_string(footer_offset),
                  "the file ends with the MCAP magic but no 20-byte Footer record precedes it", error);
    }
  }
  // The summary when it locates every message; else the scan.
  if (finished && options.use_summary) {
    std::string why_not;
    if (!ReadSummary(footer_offset, &why_not, error)) return false;
    if (why_not.empty()) {
      indexed = true;
      SortChunks();
      ResetIteration();
      return true;
    }
    ClearFound();
    index_note = why_not;
  }
  if (!Scan(finished, error)) return false;
  SortChunks();
  ResetIteration();
  return true;
}

bool McapReader::Impl::ReadHeader(std::string* error) {
  std::string_view head;
  if (size < kMagic.size() || !Read(0, kMagic.size(), &scratch, &head, error) || head != kMagic) {
    return Fail("byte 0", "not an MCAP file (it does not start with the magic 89 4D 43 41 50 30 0D 0A)", error);
  }
  if (size - kMagic.size() < kRecordPrefix) return Fail("byte 8", "the Header record is missing or cut short", error);
  std::string_view prefix;
  if (!Read(kMagic.size(), kRecordPrefix, &scratch, &prefix, error)) return false;
  const uint8_t op = static_cast<uint8_t>(prefix[0]);
  const uint64_t length = GetU64(prefix.data() + 1);
  if (op != kHeader) {
    return Fail("byte 8",
                std::string("expected the Header record (opcode 1), found ") + OpName(op) + " (opcode " +
                    std::to_string(op) + ")",
                error);
  }
  if (length > size - kMagic.size() - kRecordPrefix || length > options.max_record_bytes) {
    return Fail("byte 8",
                "Header record of " + std::to_string(length) + " bytes does not fit the file (" + std::to_string(size) +
                    " bytes) or the record limit",
                error);
  }
  std::string_view content;
  if (!Read(kMagic.size() + kRecordPrefix, length, &scratch, &content, error)) return false;
  Cursor c(content, kMagic.size() + kRecordPrefix);
  std::string_view p, l;
  if (!c.String(&p, "profile") || !c.String(&l, "library")) return Fail("Header record", c.Error(), error);
  profile = std::string(p);
  library = std::string(l);
  data_start = kMagic.size() + kRecordPrefix + length;
  return true;
}

// ---------------------------------------------------------------------------------------------
// Records.

bool McapReader::Impl::AddSchema(std::string_view content, const McapPlace& place, uint64_t pos, std::string* error) {
  Cursor c(content, pos + kRecordPrefix);
  McapSchema s;
  std::string_view n, e, d;
  if (!c.U16(&s.id, "id") || !c.String(&n, "name") || !c.String(&e, "encoding") || !c.String(&d, "data")) {
    return Fail(place.At(pos), "Schema record: " + c.Error(), error);
  }
  if (s.id == 0) return true;  // invalid, and to be ignored, says the specification
  s.name = std::string(n);
  s.encoding = std::string(e);
  s.data = std::string(d);
  const auto [it, added] = schemas.emplace(s.id, s);
  if (!added && (it->second.name != s.name || it->second.encoding != s.encoding || it->second.data != s.data)) {
    return Fail(place.At(pos), "Schema " + std::to_string(s.id) + " differs from an earlier record with that id",
                error);
  }
  return true;
}

bool McapReader::Impl::AddChannel(std::string_view content, const McapPlace& place, uint64_t pos, std::string* error,
                                  bool check_schema) {
  Cursor c(content, pos + kRecordPrefix);
  McapChannel ch;
  std::string_view t, e;
  if (!c.U16(&ch.id, "id") || !c.U16(&ch.schema_id, "schema_id") || !c.String(&t, "topic") ||
      !c.String(&e, "message_encoding") || !c.StringMap(&ch.metadata, "metadata")) {
    return Fail(place.At(pos), "Channel record: " + c.Error(), error);
  }
  ch.topic = std::string(t);
  ch.message_encoding = std::string(e);
  if (check_schema && ch.schema_id != 0 && schemas.count(ch.schema_id) == 0) {
    return Fail(place.At(pos),
                "Channel " + std::to_string(ch.id) + " (" + ch.topic + ") refers to schema " +
                    std::to_string(ch.schema_id) + ", which no earlier Schema record defines",
                error);
  }
  const auto [it, added] = channels.emplace(ch.id, ch);
  if (!added && (it->second.schema_id != ch.schema_id || it->second.topic != ch.topic ||
                 it->second.message_encoding != ch.message_encoding || it->second.metadata != ch.metadata)) {
    return Fail(place.At(pos), "Channel " + std::to_string(ch.id) + " differs from an earlier record with that id",
                error);
  }
  return true;
}

bool McapReader::Impl::ParseMessage(std::string_view content, const McapPlace& place, uint64_t pos, McapMessage* out,
                                    std::string* error) const {
  Cursor c(content, pos + kRecordPrefix);
  if (!c.U16(&out->channel_id, "channel_id") || !c.U32(&out->sequence, "sequence") ||
      !c.U64(&out->log_time_ns, "log_time") || !c.U64(&out->publish_time_ns, "publish_time")) {
    return Fail(place.At(pos), "Message record: " + c.Error(), error);
  }
  out->data = c.Rest();
  if (channels.count(out->channel_id) == 0) {
    return Fail(place.At(pos),
                "Message on channel " + std::to_string(out->channel_id) + ", which no earlier Channel record defines",
                error);
  }
  return true;
}

bool McapReader::Impl::ParseMetadata(std::string_view content, uint64_t pos, std::string* error) {
  Cursor c(content, pos + kRecordPrefix);
  std::string_view n;
  std::map<std::string, std::string> map;
  if (!c.String(&n, "name") || !c.StringMap(&map, "metadata")) {
    return Fail("byte " + std::to_string(pos), "Metadata record: " + c.Error(), error);
  }
  metadata.emplace_back(std::string(n), std::move(map));
  return true;
}

bool McapReader::Impl::DecodeChunk(uint64_t offset, std::string_view content, Loaded& slot, McapChunkInfo* header,
                                   std::string_view* records, std::string* error) {
  // Header fields, then the records, compressed or not.
  const std::string where = "byte " + std::to_string(offset);
  Cursor c(content, offset + kRecordPrefix);
  uint64_t uncompressed_size = 0;
  uint32_t crc = 0;
  std::string_view compression, stored;
  if (!c.U64(&header->message_start_ns, "message_start_time") || !c.U64(&header->message_end_ns, "message_end_time") ||
      !c.U64(&uncompressed_size, "uncompressed_size") || !c.U32(&crc, "uncompressed_crc") ||
      !c.String(&compression, "compression") || !c.Bytes64(&stored, "records")) {
    return Fail("Chunk record", c.Error(), error);
  }
  header->compression = std::string(compression);
  header->compressed_bytes = stored.size();
  header->uncompressed_bytes = uncompressed_size;
  if (uncompressed_size > options.max_record_bytes) {
    return Fail(where,
                "Chunk record: uncompressed size " + std::to_string(uncompressed_size) +
                    " bytes exceeds the limit of " + std::to_string(options.max_record_bytes),
                error);
  }
  if (compression.empty()) {
    if (stored.size() != uncompressed_size) {
      return Fail(where,
                  "uncompressed Chunk record holds " + std::to_string(stored.size()) +
                      " bytes of records but declares " + std::to_string(uncompressed_size),
                  error);
    }
    *records = stored;
  } else if (compression == "zstd") {
    slot.decompressed.resize(static_cast<size_t>(uncompressed_size));
    const size_t n =
        ZSTD_decompressDCtx(dctx, slot.decompressed.data(), slot.decompressed.size(), stored.data(), stored.size());
    if (ZSTD_isError(n)) {
      return Fail(where,
                  std::string("Chunk record: zstd: ") + ZSTD_getErrorName(n) + " (declared size " +
                      std::to_string(uncompressed_size) + " bytes)",
                  error);
    }
    if (n != uncompressed_size) {
      return Fail(where,
                  "Chunk record: decompressed to " + std::to_string(n) + " bytes, declared " +
                      std::to_string(uncompressed_size),
                  error);
    }
    *records = slot.decompressed;
  } else {
    return Fail(where,
                "Chunk record: compression '" + std::string(compression) +
                    "' is not supported (idms reads zstd and uncompressed chunks)",
                error);
  }
  // CRC of the uncompressed records; 0 means the writer did not compute one.
  if (crc != 0) {
    const uint32_t computed = Crc32(0, *records);
    if (computed != crc) {
      return Fail(
          where,
          "Chunk record: uncompressed CRC " + Hex32(crc) + ", computed " + Hex32(computed) + " (the chunk is damaged)",
          error);
    }
  }
  return true;
}

template <typename F>
bool McapReader::Impl::ForEachMessage(const McapChunkInfo& chunk, Loaded& slot, std::string* error, F fn) {
  // The bytes: a Chunk record (decoded), or a loose run of records in the file itself.
  std::string_view bytes;
  if (!Read(chunk.offset, chunk.length, &slot.raw, &bytes, error)) return false;
  std::string_view records = bytes;
  McapPlace place;
  uint64_t base = chunk.offset;
  if (!chunk.loose) {
    if (chunk.length < kRecordPrefix || static_cast<uint8_t>(bytes[0]) != kChunk ||
        GetU64(bytes.data() + 1) != chunk.length - kRecordPrefix) {
      return Fail(
          "byte " + std::to_string(chunk.offset),
          "the chunk index points here, but no Chunk record of " + std::to_string(chunk.length) + " bytes starts here",
          error);
    }
    McapChunkInfo header;
    if (!DecodeChunk(chunk.offset, bytes.substr(kRecordPrefix), slot, &header, &records, error)) return false;
    if (header.message_start_ns != chunk.message_start_ns || header.message_end_ns != chunk.message_end_ns ||
        header.uncompressed_bytes != chunk.uncompressed_bytes) {
      return Fail("byte " + std::to_string(chunk.offset),
                  "the Chunk record's time range or size differs from its chunk index", error);
    }
    place = {true, chunk.offset};
    base = 0;
  }
  // Schema and Channel records register; Message records must lie in the chunk's time range.
  return ForEachRecord(records, base, place, name, error, [&](uint8_t op, std::string_view content, uint64_t pos) {
    if (op == kSchema) return AddSchema(content, place, pos, error);
    if (op == kChannel) return AddChannel(content, place, pos, error);
    if (op != kMessage) return true;
    McapMessage m;
    if (!ParseMessage(content, place, pos, &m, error)) return false;
    if (m.log_time_ns < chunk.message_start_ns || m.log_time_ns > chunk.message_end_ns) {
      return Fail(place.At(pos),
                  "Message log time " + std::to_string(m.log_time_ns) + " lies outside its chunk's range " +
                      std::to_string(chunk.message_start_ns) + ".." + std::to_string(chunk.message_end_ns),
                  error);
    }
    return fn(m, pos);
  });
}

// ---------------------------------------------------------------------------------------------
// Iteration: chunks are loaded in order of their start time while they may hold the next message,
// and their messages merged through a heap. Every message of a chunk lies in its stated range
// (checked), so a chunk not yet loaded cannot hold anything earlier than the heap's top.

void McapReader::Impl::SortChunks() {
  std::stable_sort(chunks.begin(), chunks.end(), [](const McapChunkInfo& a, const McapChunkInfo& b) {
    return a.message_start_ns != b.message_start_ns ? a.message_start_ns < b.message_start_ns : a.offset < b.offset;
  });
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
void McapReader::Impl::ClearFound() {
  schemas.clear();
  channels.clear();
  chunks.clear();
  metadata.clear();
  stats = {};
}

uint32_t McapReader::Impl::TakeSlot() {
  if (!free_slots.empty()) {
    const uint32_t slot = free_slots.back();
    free_slots.pop_back();
    return slot;
  }
  slots.emplace_back();
  return static_cast<uint32_t>(slots.size() - 1);
}

void McapReader::Impl::ReleaseSlot(uint32_t slot) {
  held_bytes -= slots[slot].held_bytes;
  slots[slot].held_bytes = 0;
  slots[slot].remaining = 0;
  free_slots.push_back(slot);
}

void McapReader::Impl::ResetIteration() {
  heap = {};
  free_slots.clear();
  for (uint32_t i = 0; i < slots.size(); ++i) {
    slots[i].remaining = 0;
    slots[i].held_bytes = 0;
    free_slots.push_back(i);
  }
  held_bytes = 0;
  release_slot = -1;
  next_chunk = 0;
  iteration_error.clear();
}

bool McapReader::Impl::LoadChunk(const McapChunkInfo& chunk, std::string* error) {
  const uint32_t index = TakeSlot();
  Loaded& slot = slots[index];
  // Bound what chunks overlapping in time can make the merge hold at once.
  slot.held_bytes = chunk.length + (chunk.compression.empty() ? 0 : chunk.uncompressed_bytes);
  held_bytes += slot.held_bytes;
  const uint64_t limit = 4 * options.max_record_bytes;
  if (held_bytes > limit && !heap.empty()) {
    ReleaseSlot(index);
    return Fail("byte " + std::to_string(chunk.offset),
                "too many chunks overlap in time to merge them within " + std::to_string(limit) + " bytes", error);
  }
  uint64_t count = 0;
  const bool ok = ForEachMessage(chunk, slot, error, [&](const McapMessage& m, uint64_t record_offset) {
    if (m.log_time_ns < range_start || m.log_time_ns > range_end) return true;
    if (!wanted.empty() && !wanted[m.channel_id]) return true;
    heap.push(Pending{chunk.offset, record_offset, m, index});
    ++count;
    return true;
  });
  if (!ok) {
    ReleaseSlot(index);
    return false;
  }
  slot.remaining = count;
  if (count == 0) ReleaseSlot(index);
  return true;
}

void McapReader::Seek(uint64_t start_ns, uint64_t end_ns, std::span<const uint16_t> channel_ids) {
  Impl& r = *impl_;
  r.ResetIteration();
  r.range_start = start_ns;
  r.range_end = end_ns;
  r.wanted.clear();
  if (!channel_ids.empty()) {
    r.wanted.assign(65536, false);
    for (uint16_t id : channel_ids) r.wanted[id] = true;
  }
}

bool McapReader::Next(McapMessage* out, std::string* error) {
  Impl& r = *impl_;
  if (error != nullptr) error->clear();
  // The previous message's chunk, if that was its last, is free now that its view has expired.
  if (r.release_slot >= 0) {
    r.ReleaseSlot(static_cast<uint32_t>(r.release_slot));
    r.release_slot = -1;
  }
  if (!r.iteration_error.empty()) {
    if (error != nullptr) *error = r.iteration_error;
    return false;
  }
  // Load every chunk that may hold a message before the earliest pending one.
  while (r.next_chunk < r.chunks.size()) {
    const McapChunkInfo& chunk = r.chunks[r.next_chunk];
    if (!r.heap.empty() && chunk.message_start_ns > r.heap.top().message.log_time_ns) break;
    ++r.next_chunk;
    // Skipped by time, and by channel when asked for some; never by count: a message index that
    // under-counts must not lose the chunk's messages.
    if (chunk.message_end_ns < r.range_start || chunk.message_start_ns > r.range_end) continue;
    if (!r.wanted.empty() &&
        std::none_of(chunk.channels.begin(), chunk.channels.end(), [&](uint16_t id) { return r.wanted[id]; })) {
      continue;
    }
    if (!r.LoadChunk(chunk, &r.iteration_error)) {
      r.heap = {};
      if (error != nullptr) *error = r.iteration_error;
      return false;
    }
  }
  // The earliest.
  if (r.heap.empty()) return false;
  const Impl::Pending top = r.heap.top();
  r.heap.pop();
  *out = top.message;
  if (--r.slots[top.slot].remaining == 0) r.release_slot = top.slot;
  return true;
}

const std::string& McapReader::profile() const { return impl_->profile; }
const std::string& McapReader::library() const { return impl_->library; }
const std::map<uint16_t, McapSchema>& McapReader::schemas() const { return impl_->schemas; }
const std::map<uint16_t, McapChannel>& McapReader::channels() const { return impl_->channels; }
const std::vector<std::pair<std::string, std::map<std::string, std::string>>>& McapReader::metadata() const {
  return impl_->metadata;
}
const McapStatistics& McapReader::statistics() const { return impl_->stats; }
const std::vector<McapChunkInfo>& McapReader::chunks() const { return impl_->chunks; }
bool McapReader::indexed() const { return impl_->indexed; }
const std::string& McapReader::recovery_note() const { return impl_->recovery_note; }
const std::string& McapReader::index_note() const { return impl_->index_note; }

const McapChannel* McapReader::FindChannel(std::string_view topic) const {
  for (const auto& [id, channel] : impl_->channels) {
    if (channel.topic == topic) return &channel;
  }
  return nullptr;
}

const McapSchema* McapReader::FindSchema(uint16_t schema_id) const {
  const auto it = impl_->schemas.find(schema_id);
  return it == impl_->schemas.end() ? nullptr : &it->second;
}

}  // namespace idms
