// Zigzag LEB128 varints: the integer coding of mesh payloads (the same coding protobuf uses for
// sint64). Writers append to a byte string; the reader refuses truncated and overlong varints.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace idms::internal {

inline uint64_t ZigZag(int64_t v) { return (static_cast<uint64_t>(v) << 1) ^ static_cast<uint64_t>(v >> 63); }

inline int64_t UnZigZag(uint64_t u) { return static_cast<int64_t>(u >> 1) ^ -static_cast<int64_t>(u & 1); }

// Appends v as LEB128 (1 to 10 bytes).
inline void PutVarint(uint64_t v, std::string* out) {
  while (v >= 0x80) {
    out->push_back(static_cast<char>((v & 0x7F) | 0x80));
    v >>= 7;
  }
  out->push_back(static_cast<char>(v));
}

inline void PutSigned(int64_t v, std::string* out) { PutVarint(ZigZag(v), out); }

// Reads varints from a byte range; the first failure stops reading and is remembered.
class VarintReader {
 public:
  VarintReader(const char* data, size_t size)
      : p_(reinterpret_cast<const uint8_t*>(data)), begin_(p_), end_(p_ + size) {}

  // False at the end of the data, on a truncated varint or one longer than 64 bits.
  bool Read(uint64_t* v) {
    uint64_t result = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      if (p_ == end_) {
        error_ = shift == 0 ? "payload ends early" : "truncated varint";
        return false;
      }
      const uint64_t byte = *p_++;
      // The 10th byte may only carry the top bit of a 64-bit value.
      if (shift == 63 && byte > 1) {
        error_ = "varint longer than 64 bits";
        return false;
      }
      result |= (byte & 0x7F) << shift;
      if ((byte & 0x80) == 0) {
        *v = result;
        return true;
      }
    }
    error_ = "varint longer than 64 bits";
    return false;
  }

  bool ReadSigned(int64_t* v) {
    uint64_t u = 0;
    if (!Read(&u)) return false;
    *v = UnZigZag(u);
    return true;
  }

  size_t offset() const { return static_cast<size_t>(p_ - begin_); }
  bool at_end() const { return p_ == end_; }
  const char* error() const { return error_; }

 private:
  const uint8_t* p_;
  const uint8_t* begin_;
  const uint8_t* end_;
  const char* error_ = "";
};

}  // namespace idms::internal
