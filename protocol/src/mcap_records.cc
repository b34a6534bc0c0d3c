// MCAP record helpers shared by the writer and the reader: opcode names, the string map encoding
// and the bounds-checked field cursor.
#include <string>

#include "mcap_internal.h"

namespace idms::mcap_internal {

const char* OpName(uint8_t op) {
  switch (op) {
    case kHeader:
      return "Header";
    case kFooter:
      return "Footer";
    case kSchema:
      return "Schema";
    case kChannel:
      return "Channel";
    case kMessage:
      return "Message";
    case kChunk:
      return "Chunk";
    case kMessageIndex:
      return "MessageIndex";
    case kChunkIndex:
      return "ChunkIndex";
    case kAttachment:
      return "Attachment";
    case kAttachmentIndex:
      return "AttachmentIndex";
    case kStatistics:
      return "Statistics";
    case kMetadata:
      return "Metadata";
    case kMetadataIndex:
      return "MetadataIndex";
    case kSummaryOffset:
      return "SummaryOffset";
    case kDataEnd:
      return "DataEnd";
    default:
      return "unknown";
  }
}

void PutStringMap(const std::map<std::string, std::string>& map, std::string* out) {
  // Map: uint32 byte length of the entries, then key and value strings (std::map: sorted, unique).
  const size_t at = out->size();
  PutU32(0, out);
  for (const auto& [key, value] : map) {
    PutString(key, out);
    PutString(value, out);
  }
  const uint32_t length = static_cast<uint32_t>(out->size() - at - 4);
  for (int i = 0; i < 4; ++i) (*out)[at + i] = static_cast<char>((length >> (8 * i)) & 0xFF);
}

bool Cursor::Take(size_t n, const char* field, const char** p) {
  if (failed_field_ != nullptr) return false;
  if (n > bytes_.size() - pos_) {
    failed_field_ = field;
    failed_at_ = base_ + pos_;
    failed_need_ = n;
    failed_left_ = bytes_.size() - pos_;
    return false;
  }
  *p = bytes_.data() + pos_;
  pos_ += n;
  return true;
}

bool Cursor::U8(uint8_t* v, const char* field) {
  const char* p = nullptr;
  if (!Take(1, field, &p)) return false;
  *v = static_cast<uint8_t>(p[0]);
  return true;
}

bool Cursor::U16(uint16_t* v, const char* field) {
  const char* p = nullptr;
  if (!Take(2, field, &p)) return false;
  *v = static_cast<uint16_t>(static_cast<uint8_t>(p[0]) | (static_cast<uint8_t>(p[1]) << 8));
  return true;
}

bool Cursor::U32(uint32_t* v, const char* field) {
  const char* p = nullptr;
  if (!Take(4, field, &p)) return false;
  uint32_t x = 0;
  for (int i = 3; i >= 0; --i) x = (x << 8) | static_cast<uint8_t>(p[i]);
  *v = x;
  return true;
}

bool Cursor::U64(uint64_t* v, const char* field) {
  const char* p = nullptr;
  if (!Take(8, field, &p)) return false;
  *v = GetU64(p);
  return true;
}

bool Cursor::String(std::string_view* v, const char* field) {
  uint32_t n = 0;
  const char* p = nullptr;
  if (!U32(&n, field) || !Take(n, field, &p)) return false;
  *v = std::string_view(p, n);
  return true;
}

bool Cursor::Bytes64(std::string_view* v, const char* field) {
  uint64_t n = 0;
  const char* p = nullptr;
  if (!U64(&n, field)) return false;
  if (n > bytes_.size() - pos_) {
    // Report the declared length, which may not fit in size_t.
    failed_field_ = field;
    failed_at_ = base_ + pos_;
    failed_need_ = n;
    failed_left_ = bytes_.size() - pos_;
    return false;
  }
  if (!Take(static_cast<size_t>(n), field, &p)) return false;
  *v = std::string_view(p, static_cast<size_t>(n));
  return true;
}

bool Cursor::StringMap(std::map<std::string, std::string>* v, const char* field) {
  std::string_view entries;
  if (!String(&entries, field)) return false;
  Cursor inner(entries, base_ + pos_ - entries.size());
  while (inner.remaining() > 0) {
    std::string_view key, value;
    if (!inner.String(&key, field) || !inner.String(&value, field)) {
      failed_field_ = field;
      failed_at_ = inner.failed_at_;
      failed_need_ = inner.failed_need_;
      failed_left_ = inner.failed_left_;
      return false;
    }
    // Duplicate keys are "indeterminate" in the specification; the first one wins.
    v->emplace(std::string(key), std::string(value));
  }
  return true;
}

std::string Cursor::Error() const {
  if (failed_field_ == nullptr) return "no error";
  return "byte " + std::to_string(failed_at_) + ": field " + failed_field_ + " needs " + std::to_string(failed_need_) +
         " bytes, the record has " + std::to_string(failed_left_) + " left";
}

}  // namespace idms::mcap_internal
