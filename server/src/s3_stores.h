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

}  // namespace idms::server
