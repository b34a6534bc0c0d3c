// What the MCAP writer and reader share: opcodes, magic, fixed sizes, little-endian field writers,
// a bounds-checked field reader and CRC-32. Facts from the specification (https://mcap.dev/spec).
#pragma once

#include <zlib.h>

#include <cstdint>
#include <cstring>
#include <map>
#include <string>
#include <string_view>

namespace idms::mcap_internal {

// 0x89 "MCAP" major version '0' "\r\n", at both ends of a file.
inline constexpr std::string_view kMagic("\x89MCAP0\r\n", 8);

enum Op : uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kAttachment = 0x09,
  kAttachmentIndex = 0x0A,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

// Every record: opcode (1) + content length (uint64).
inline constexpr uint64_t kRecordPrefix = 9;
// Footer content: summary_start, summary_offset_start, summary_crc.
inline constexpr uint64_t kFooterContent = 8 + 8 + 4;
// Message content before its data: channel_id, sequence, log_time, publish_time.
inline constexpr uint64_t kMessageFixed = 2 + 4 + 8 + 8;

const char* OpName(uint8_t op);

// CRC-32 (IEEE 802.3, reflected 0xEDB88320), as MCAP specifies; zlib's. Start from 0.
inline uint32_t Crc32(uint32_t crc, std::string_view bytes) {
  return static_cast<uint32_t>(
      crc32_z(crc, reinterpret_cast<const Bytef*>(bytes.data()), static_cast<z_size_t>(bytes.size())));
}

// Little-endian field writers (the specification's "Serialization" section).
inline void PutU8(uint8_t v, std::string* out) { out->push_back(static_cast<char>(v)); }
inline void PutU16(uint16_t v, std::string* out) {
  for (int i = 0; i < 2; ++i) out->push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
inline void PutU32(uint32_t v, std::string* out) {
  for (int i = 0; i < 4; ++i) out->push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
inline void PutU64(uint64_t v, std::string* out) {
  for (int i = 0; i < 8; ++i) out->push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
inline void PatchU64(uint64_t v, size_t at, std::string* out) {
  for (int i = 0; i < 8; ++i) (*out)[at + i] = static_cast<char>((v >> (8 * i)) & 0xFF);
}
// String and uint32-length-prefixed bytes: the same encoding.
inline void PutString(std::string_view s, std::string* out) {
  PutU32(static_cast<uint32_t>(s.size()), out);
  out->append(s);
}
void PutStringMap(const std::map<std::string, std::string>& map, std::string* out);

// Starts a record (opcode and a length to patch); EndRecord patches the length. Returns where the
// record starts in *out.
inline size_t BeginRecord(uint8_t op, std::string* out) {
  const size_t at = out->size();
  PutU8(op, out);
  PutU64(0, out);
  return at;
}
inline void EndRecord(size_t at, std::string* out) { PatchU64(out->size() - at - kRecordPrefix, at + 1, out); }

inline uint64_t GetU64(const char* p) {
  uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(p[i]);
  return v;
}

// Reads the fields of one record. The first field that does not fit in what is left fails the
// cursor and is remembered for the message; later reads fail too.
class Cursor {
 public:
  // `base` is the file offset of bytes[0] (or the offset inside a chunk's records), for messages.
  Cursor(std::string_view bytes, uint64_t base) : bytes_(bytes), base_(base) {}

  bool U8(uint8_t* v, const char* field);
  bool U16(uint16_t* v, const char* field);
  bool U32(uint32_t* v, const char* field);
  bool U64(uint64_t* v, const char* field);
  // String, or uint32-length-prefixed Bytes.
  bool String(std::string_view* v, const char* field);
  // uint64-length-prefixed Bytes.
  bool Bytes64(std::string_view* v, const char* field);
  // Map<string, string>.
  bool StringMap(std::map<std::string, std::string>* v, const char* field);
  // The rest of the record.
  std::string_view Rest() {
    const std::string_view rest = bytes_.substr(pos_);
    pos_ = bytes_.size();
    return rest;
  }

  bool ok() const { return failed_field_ == nullptr; }
  uint64_t offset() const { return base_ + pos_; }
  size_t remaining() const { return bytes_.size() - pos_; }
  // "byte N: field F needs K bytes, the record has R left" for the failed field.
  std::string Error() const;

 private:
  bool Take(size_t n, const char* field, const char** p);

  std::string_view bytes_;
  uint64_t base_;
  size_t pos_ = 0;
  const char* failed_field_ = nullptr;
  uint64_t failed_at_ = 0;
  uint64_t failed_need_ = 0;
  uint64_t failed_left_ = 0;
};

}  // namespace idms::mcap_internal
