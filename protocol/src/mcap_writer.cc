// McapWriter: chunked, indexed MCAP files written as they happen, finished with a summary.
#include <unistd.h>
#include <zstd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "idms/protocol/mcap.h"
#include "mcap_internal.h"

namespace idms {

using namespace mcap_internal;

struct McapWriter::Impl {
  McapWriterOptions options;
  std::string path;
  FILE* file = nullptr;
  std::string failure;  // the first I/O error; every later call fails with it
  ZSTD_CCtx* cctx = nullptr;

  uint64_t offset = 0;       // bytes written to the file
  uint32_t data_crc = 0;     // of every byte from the file's start to DataEnd
  bool in_summary = false;   // bytes now go to summary_crc instead
  uint32_t summary_crc = 0;  // from the summary's start to the footer's summary_crc field

  std::vector<McapSchema> schemas;    // id = index + 1
  std::vector<McapChannel> channels;  // id = index + 1
  std::vector<uint32_t> channel_sequence;
  std::vector<uint64_t> channel_count;

  // The open chunk: uncompressed Message records and, per channel, (log time, offset) pairs.
  std::string chunk;
  uint64_t chunk_messages = 0;
  uint64_t chunk_start_ns = 0;
  uint64_t chunk_end_ns = 0;
  std::vector<std::vector<std::pair<uint64_t, uint64_t>>> chunk_entries;  // by channel index

  // What the summary will hold, built as chunks close.
  std::string chunk_index_records;
  std::string metadata_index_records;
  uint32_t num_chunks = 0;
  uint32_t num_metadata = 0;
  uint64_t num_messages = 0;
  uint64_t start_ns = 0;
  uint64_t end_ns = 0;

  std::string record;      // scratch: a record being built
  std::string compressed;  // scratch: a chunk's compressed records

  bool Fail(std::string message, std::string* error) {
    if (failure.empty()) failure = path + ": " + message;
    if (error != nullptr) *error = failure;
    return false;
  }

  bool Usable(std::string* error) {
    if (!failure.empty()) {
      if (error != nullptr) *error = failure;
      return false;
    }
    if (file == nullptr) {
      if (error != nullptr) *error = "McapWriter: no file is open";
      return false;
    }
    return true;
  }

  // Appends bytes to the file, keeping the offset and the running CRCs.
  bool Emit(std::string_view bytes, std::string* error) {
    if (!bytes.empty() && std::fwrite(bytes.data(), 1, bytes.size(), file) != bytes.size()) {
      return Fail(std::string("write failed at byte ") + std::to_string(offset) + ": " + std::strerror(errno), error);
    }
    offset += bytes.size();
    if (in_summary) {
      summary_crc = Crc32(summary_crc, bytes);
    } else {
      data_crc = Crc32(data_crc, bytes);
    }
    return true;
  }

  // Hands buffered bytes to the kernel (a process crash keeps them), and to the disk with sync.
  bool FlushFile(bool sync, std::string* error) {
    if (std::fflush(file) != 0) return Fail(std::string("flush failed: ") + std::strerror(errno), error);
    if (sync && fdatasync(fileno(file)) != 0) {
      return Fail(std::string("fdatasync failed: ") + std::strerror(errno), error);
    }
    return true;
  }

  bool WriteChunk(std::string* error);
  bool WriteSummary(std::string* error);
};

McapWriter::McapWriter() : impl_(std::make_unique<Impl>()) {}

McapWriter::~McapWriter() {
  if (impl_->file != nullptr) Close(nullptr);
  ZSTD_freeCCtx(impl_->cctx);
}

bool McapWriter::Open(const std::string& path, const McapWriterOptions& options, std::string* error) {
  if (impl_->file != nullptr) {
    if (error != nullptr) *error = "McapWriter: " + impl_->path + " is still open";
    return false;
  }
  ZSTD_CCtx* cctx = impl_->cctx;
  impl_ = std::make_unique<Impl>();
  impl_->cctx = cctx;
  Impl& w = *impl_;
  w.options = options;
  w.path = path;
  if (w.options.chunk_bytes == 0) w.options.chunk_bytes = 1;
  if (w.options.compress && w.cctx == nullptr) w.cctx = ZSTD_createCCtx();
  w.file = std::fopen(path.c_str(), "wbe");  // e: close on exec
  if (w.file == nullptr) {
    if (error != nullptr) *error = path + ": cannot create: " + std::strerror(errno);
    return false;
  }
  // Magic and Header, on disk at once: the file is a (so far empty) recording from now on.
  w.record.assign(kMagic);
  const size_t at = BeginRecord(kHeader, &w.record);
  PutString(w.options.profile, &w.record);
  PutString(w.options.library, &w.record);
  EndRecord(at, &w.record);
  return w.Emit(w.record, error) && w.FlushFile(false, error);
}

uint16_t McapWriter::AddSchema(std::string_view name, std::string_view encoding, std::string_view data,
                               std::string* error) {
  Impl& w = *impl_;
  if (!w.Usable(error)) return 0;
  if (w.schemas.size() >= 0xFFFF) {
    if (error != nullptr) *error = w.path + ": too many schemas (65535)";
    return 0;
  }
  const uint16_t id = static_cast<uint16_t>(w.schemas.size() + 1);
  w.schemas.push_back({id, std::string(name), std::string(encoding), std::string(data)});
  w.record.clear();
  const size_t at = BeginRecord(kSchema, &w.record);
  PutU16(id, &w.record);
  PutString(name, &w.record);
  PutString(encoding, &w.record);
  PutString(data, &w.record);
  EndRecord(at, &w.record);
  return w.Emit(w.record, error) ? id : 0;
}

uint16_t McapWriter::AddChannel(uint16_t schema_id, std::string_view topic, std::string_view message_encoding,
                                const std::map<std::string, std::string>& metadata, std::string* error) {
  Impl& w = *impl_;
  if (!w.Usable(error)) return 0;
  if (schema_id > w.schemas.size()) {
    if (error != nullptr)
      *error = w.path + ": channel " + std::string(topic) + ": no schema " + std::to_string(schema_id);
    return 0;
  }
  if (w.channels.size() >= 0xFFFF) {
    if (error != nullptr) *error = w.path + ": too many channels (65535)";
    return 0;
  }
  const uint16_t id = static_cast<uint16_t>(w.channels.size() + 1);
  w.channels.push_back({id, schema_id, std::string(topic), std::string(message_encoding), metadata});
  w.channel_sequence.push_back(0);
  w.channel_count.push_back(0);
  w.chunk_entries.emplace_back();
  w.record.clear();
  const size_t at = BeginRecord(kChannel, &w.record);
  PutU16(id, &w.record);
  PutU16(schema_id, &w.record);
  PutString(topic, &w.record);
  PutString(message_encoding, &w.record);
  PutStringMap(metadata, &w.record);
  EndRecord(at, &w.record);
  return w.Emit(w.record, error) ? id : 0;
}

bool McapWriter::AddMetadata(std::string_view name, const std::map<std::string, std::string>& metadata,
                             std::string* error) {
  Impl& w = *impl_;
  if (!w.Usable(error)) return false;
  w.record.clear();
  const size_t at = BeginRecord(kMetadata, &w.record);
  PutString(name, &w.record);
  PutStringMap(metadata, &w.record);
  EndRecord(at, &w.record);
  // MetadataIndex for the summary: offset, length (prefix included), name.
  const size_t index_at = BeginRecord(kMetadataIndex, &w.metadata_index_records);
  PutU64(w.offset, &w.metadata_index_records);
  PutU64(w.record.size(), &w.metadata_index_records);
  PutString(name, &w.metadata_index_records);
  EndRecord(index_at, &w.metadata_index_records);
  ++w.num_metadata;
  return w.Emit(w.record, error);
}

bool McapWriter::Write(uint16_t channel_id, uint64_t log_time_ns, uint64_t publish_time_ns, std::string_view data,
                       std::string* error) {
  Impl& w = *impl_;
  if (!w.Usable(error)) return false;
  if (channel_id == 0 || channel_id > w.channels.size()) {
    if (error != nullptr) *error = w.path + ": no channel " + std::to_string(channel_id);
    return false;
  }
  // Age limit by log time: the new message starts the next chunk.
  if (w.chunk_messages > 0 && log_time_ns >= w.chunk_start_ns &&
      log_time_ns - w.chunk_start_ns >= w.options.chunk_max_age_ns) {
    if (!w.WriteChunk(error)) return false;
  }
  // Message record: channel_id, sequence, log_time, publish_time, data.
  const size_t index = channel_id - 1u;
  const uint64_t record_offset = w.chunk.size();
  const size_t at = BeginRecord(kMessage, &w.chunk);
  PutU16(channel_id, &w.chunk);
  PutU32(w.channel_sequence[index]++, &w.chunk);
  PutU64(log_time_ns, &w.chunk);
  PutU64(publish_time_ns, &w.chunk);
  w.chunk.append(data);
  EndRecord(at, &w.chunk);
  w.chunk_entries[index].emplace_back(log_time_ns, record_offset);
  // Times and counts for the chunk and the file.
  if (w.chunk_messages == 0 || log_time_ns < w.chunk_start_ns) w.chunk_start_ns = log_time_ns;
  if (w.chunk_messages == 0 || log_time_ns > w.chunk_end_ns) w.chunk_end_ns = log_time_ns;
  if (w.num_messages == 0 || log_time_ns < w.start_ns) w.start_ns = log_time_ns;
  if (w.num_messages == 0 || log_time_ns > w.end_ns) w.end_ns = log_time_ns;
  ++w.chunk_messages;
  ++w.num_messages;
  ++w.channel_count[index];
  // Size limit.
  if (w.chunk.size() >= w.options.chunk_bytes) return w.WriteChunk(error);
  return true;
}

bool McapWriter::Flush(uint64_t now_ns, std::string* error) {
  Impl& w = *impl_;
  if (!w.Usable(error)) return false;
  if (w.chunk_messages > 0 && now_ns >= w.chunk_start_ns && now_ns - w.chunk_start_ns >= w.options.chunk_max_age_ns) {
    return w.WriteChunk(error);  // flushes
  }
  return w.FlushFile(false, error);
}

bool McapWriter::CloseChunk(std::string* error) {
  Impl& w = *impl_;
  return w.Usable(error) && w.WriteChunk(error);
}

bool McapWriter::Impl::WriteChunk(std::string* error) {
  if (chunk_messages == 0) return true;
  // Compress; keep the raw records when zstd does not make them smaller.
  std::string_view stored = chunk;
  std::string_view compression;
  if (options.compress) {
    compressed.resize(ZSTD_compressBound(chunk.size()));
    const size_t n =
        ZSTD_compressCCtx(cctx, compressed.data(), compressed.size(), chunk.data(), chunk.size(), options.zstd_level);
    if (ZSTD_isError(n)) return Fail(std::string("zstd: ") + ZSTD_getErrorName(n), error);
    if (n < chunk.size()) {
      stored = std::string_view(compressed.data(), n);
      compression = "zstd";
    }
  }
  // Chunk record: start, end, uncompressed size and CRC, compression, records.
  const uint64_t chunk_offset = offset;
  record.clear();
  const size_t at = BeginRecord(kChunk, &record);
  PutU64(chunk_start_ns, &record);
  PutU64(chunk_end_ns, &record);
  PutU64(chunk.size(), &record);
  PutU32(Crc32(0, chunk), &record);
  PutString(compression, &record);
  PutU64(stored.size(), &record);
  record.append(stored);
  EndRecord(at, &record);
  const uint64_t chunk_length = record.size();
  if (!Emit(record, error)) return false;
  // One MessageIndex per channel with messages in the chunk, ascending channel id.
  std::vector<std::pair<uint16_t, uint64_t>> index_offsets;
  const uint64_t indexes_start = offset;
  for (size_t c = 0; c < chunk_entries.size(); ++c) {
    auto& entries = chunk_entries[c];
    if (entries.empty()) continue;
    index_offsets.emplace_back(static_cast<uint16_t>(c + 1), offset);
    record.clear();
    const size_t index_at = BeginRecord(kMessageIndex, &record);
    PutU16(static_cast<uint16_t>(c + 1), &record);
    PutU32(static_cast<uint32_t>(16 * entries.size()), &record);
    for (const auto& [log_time, record_offset] : entries) {
      PutU64(log_time, &record);
      PutU64(record_offset, &record);
    }
    EndRecord(index_at, &record);
    if (!Emit(record, error)) return false;
    entries.clear();
  }
  // ChunkIndex for the summary.
  const size_t index_at = BeginRecord(kChunkIndex, &chunk_index_records);
  PutU64(chunk_start_ns, &chunk_index_records);
  PutU64(chunk_end_ns, &chunk_index_records);
  PutU64(chunk_offset, &chunk_index_records);
  PutU64(chunk_length, &chunk_index_records);
  PutU32(static_cast<uint32_t>(10 * index_offsets.size()), &chunk_index_records);
  for (const auto& [channel, index_offset] : index_offsets) {
    PutU16(channel, &chunk_index_records);
    PutU64(index_offset, &chunk_index_records);
  }
  PutU64(offset - indexes_start, &chunk_index_records);
  PutString(compression, &chunk_index_records);
  PutU64(stored.size(), &chunk_index_records);
  PutU64(chunk.size(), &chunk_index_records);
  EndRecord(index_at, &chunk_index_records);
  ++num_chunks;
  chunk.clear();
  chunk_messages = 0;
  // The chunk is complete on disk (or in the kernel): a crash from now on keeps it.
  return FlushFile(options.sync, error);
}

bool McapWriter::Impl::WriteSummary(std::string* error) {
  // DataEnd with the CRC of every byte before it.
  record.clear();
  size_t at = BeginRecord(kDataEnd, &record);
  PutU32(data_crc, &record);
  EndRecord(at, &record);
  if (!Emit(record, error)) return false;
  // Summary: records grouped by opcode, each group located by a SummaryOffset.
  const uint64_t summary_start = offset;
  in_summary = true;
  std::vector<std::pair<uint8_t, std::pair<uint64_t, uint64_t>>> groups;
  auto emit_group = [&](uint8_t op, std::string_view records) {
    if (records.empty()) return true;
    groups.push_back({op, {offset, records.size()}});
    return Emit(records, error);
  };
  std::string schema_records, channel_records;
  for (const McapSchema& s : schemas) {
    at = BeginRecord(kSchema, &schema_records);
    PutU16(s.id, &schema_records);
    PutString(s.name, &schema_records);
    PutString(s.encoding, &schema_records);
    PutString(s.data, &schema_records);
    EndRecord(at, &schema_records);
  }
  for (const McapChannel& c : channels) {
    at = BeginRecord(kChannel, &channel_records);
    PutU16(c.id, &channel_records);
    PutU16(c.schema_id, &channel_records);
    PutString(c.topic, &channel_records);
    PutString(c.message_encoding, &channel_records);
    PutStringMap(c.metadata, &channel_records);
    EndRecord(at, &channel_records);
  }
  // Statistics last: its channel_message_counts need the Channel records before it.
  std::string statistics;
  at = BeginRecord(kStatistics, &statistics);
  PutU64(num_messages, &statistics);
  PutU16(static_cast<uint16_t>(schemas.size()), &statistics);
  PutU32(static_cast<uint32_t>(channels.size()), &statistics);
  PutU32(0, &statistics);  // attachments
  PutU32(num_metadata, &statistics);
  PutU32(num_chunks, &statistics);
  PutU64(start_ns, &statistics);
  PutU64(end_ns, &statistics);
  PutU32(static_cast<uint32_t>(10 * channels.size()), &statistics);
  for (size_t c = 0; c < channels.size(); ++c) {
    PutU16(static_cast<uint16_t>(c + 1), &statistics);
    PutU64(channel_count[c], &statistics);
  }
  EndRecord(at, &statistics);
  if (!emit_group(kSchema, schema_records) || !emit_group(kChannel, channel_records) ||
      !emit_group(kChunkIndex, chunk_index_records) || !emit_group(kMetadataIndex, metadata_index_records) ||
      !emit_group(kStatistics, statistics)) {
    return false;
  }
  const uint64_t summary_offset_start = offset;
  record.clear();
  for (const auto& [op, group] : groups) {
    at = BeginRecord(kSummaryOffset, &record);
    PutU8(op, &record);
    PutU64(group.first, &record);
    PutU64(group.second, &record);
    EndRecord(at, &record);
  }
  if (!Emit(record, error)) return false;
  // Footer: its CRC covers the summary, the summary offsets and the footer up to the CRC itself.
  record.clear();
  at = BeginRecord(kFooter, &record);
  PutU64(summary_start, &record);
  PutU64(summary_offset_start, &record);
  EndRecord(at, &record);
  PatchU64(kFooterContent, at + 1, &record);
  if (!Emit(record, error)) return false;
  record.clear();
  PutU32(summary_crc, &record);
  record.append(kMagic);
  in_summary = false;
  return Emit(record, error);
}

bool McapWriter::Close(std::string* error) {
  Impl& w = *impl_;
  if (!w.Usable(error)) {
    if (w.file != nullptr) std::fclose(w.file);
    w.file = nullptr;
    return false;
  }
  const bool ok = w.WriteChunk(error) && w.WriteSummary(error) && w.FlushFile(w.options.sync, error);
  const int closed = std::fclose(w.file);
  w.file = nullptr;
  if (ok && closed != 0) return w.Fail(std::string("close failed: ") + std::strerror(errno), error);
  return ok;
}

bool McapWriter::is_open() const { return impl_->file != nullptr; }
uint64_t McapWriter::num_messages() const { return impl_->num_messages; }
uint32_t McapWriter::num_chunks() const { return impl_->num_chunks; }
uint64_t McapWriter::bytes_written() const { return impl_->offset; }
uint64_t McapWriter::open_chunk_bytes() const { return impl_->chunk.size(); }

}  // namespace idms
