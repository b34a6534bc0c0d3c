// The object stores behind idms-server's --blobs and --recordings s3://HOST:PORT/BUCKET: the
// library's blobs and the sessions' recordings as objects in an S3 bucket (server/README.md,
// "Object storage").
#pragma once

#include <memory>
#include <string>

#include "idms/server/storage.h"
#include "s3_client.h"

namespace idms::server {

// Blobs as objects `blobs/<sha256>` (content-addressed: a Put of bytes already stored is a HEAD,
// no upload). Checks at once that the store answers, the bucket exists and the credentials are
// accepted: null with *error naming the problem otherwise. Every method throws StoreUnavailable
// while the store cannot be reached (the HTTP layer answers 503 with Retry-After).
std::unique_ptr<BlobStore> OpenS3BlobStore(const S3Location& location, const S3Credentials& credentials,
                                           std::string* error);

// Recordings as objects (--recordings): a live recording's file stays in `cache_dir`; Persist
// uploads what was flushed since the last upload as the next segment recordings/ID/GGGGGG-OFFSET
// (on the store's own threads, retried while the store is down, the newest request per session
// kept); Publish uploads the finished file as recordings/ID.mcap and then deletes the segments;
// Fetch brings a finished recording into the cache (bounded, least recently used first); Recover
// rebuilds a live file from its segments. Checks the bucket at once, as OpenS3BlobStore does.
struct S3RecordingOptions {
  uint64_t cache_bytes = uint64_t{1} << 30;       // finished recordings kept in the cache
  int upload_threads = 4;                         // recordings uploading at once
  std::chrono::milliseconds max_retry{1000};      // while the store is down, it is tried this often
  std::chrono::milliseconds drain_timeout{5000};  // at destruction, for what is queued
};
std::unique_ptr<RecordingStore> OpenS3RecordingStore(const S3Location& location, const S3Credentials& credentials,
                                                     const std::string& cache_dir, std::string* error,
                                                     S3RecordingOptions options = S3RecordingOptions());

}  // namespace idms::server
