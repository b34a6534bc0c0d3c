// The inside of CodecContext: zstd contexts kept for the session and the scratch buffers the
// codec reuses, so that a warm encoder or mirror allocates nothing per frame.
#pragma once

#include <zstd.h>

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "idms/protocol/mesh_codec.h"

namespace idms {

struct CodecContext::Impl {
  ZSTD_CCtx* cctx = nullptr;
  ZSTD_DCtx* dctx = nullptr;
  std::string raw;           // an uncompressed payload being built or decoded
  std::string compressed;    // a compressed payload being built
  std::vector<int32_t> ids;  // delta scratch: vertex ids
  std::vector<int32_t> dq;   // delta scratch: (3 x n) changes, planar
};

namespace internal {

// Compresses ctx.raw into *out with zstd (content size declared) when that makes it smaller, else
// copies it. Returns the compression used.
v1::Compression CompressPayload(CodecContext::Impl& ctx, std::string* out);

// Makes the uncompressed payload available in *raw: the bytes themselves for COMPRESSION_NONE,
// else ctx.raw after checking that the payload is one zstd frame whose declared content size is
// present and <= max_bytes and equals what it decompresses to. False with a message otherwise.
bool DecompressPayload(CodecContext::Impl& ctx, v1::Compression compression, std::string_view payload,
                       int64_t max_bytes, std::string_view* raw, std::string* error);

}  // namespace internal
}  // namespace idms
