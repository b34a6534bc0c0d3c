// The model library: validated uploads, versions, deletes and the shipped-models import, over the
// BlobStore and ModelStore. Every write is validated with the sim parsers before anything is
// stored, and stores blobs (fsync'ed, renamed) before the row that names them commits.
#pragma once

#include <mutex>
#include <optional>
#include <string>
#include <string_view>

#include "idms/server/storage.h"

namespace idms::server {

// Where an upload went wrong, as the parser said it: file ("NAME.fem"), 1-based line and column
// (0 = the whole file), and what was expected.
struct UploadError {
  int status = 400;  // 400 for bad input, 500 for a storage failure
  std::string message, file;
  int line = 0, column = 0;
};

// Where an upload's time went, for the log and the bench.
struct UploadTimings {
  double parse_ms = 0;  // fem + plg through the sim parsers, the surface check, the obj
  double store_ms = 0;  // blobs hashed, written, fsync'ed, renamed; the row committed
};

// [A-Za-z0-9_.-]{1,64}, not starting with '.', without "..".
bool ValidModelName(std::string_view name);

class Library {
 public:
  Library(BlobStore* blobs, ModelStore* models) : blobs_(blobs), models_(models) {}

  // Validates the pair (fem, plg sharing the surface) and stores it as the next version of `name`,
  // with `metadata` (ModelVersion::metadata: a JSON object's text or empty, at most
  // kMaxVersionMetadataBytes).
  std::optional<ModelVersion> Upload(const std::string& name, std::string_view fem, std::string_view plg,
                                     const std::string& description, UploadError* error,
                                     UploadTimings* timings = nullptr, const std::string& metadata = {});
  // One version (version > 0) or the whole model; blobs nobody names any more are removed.
  bool Delete(const std::string& name, int64_t version);
  // `version` 0 = the latest.
  std::optional<ModelVersion> Find(const std::string& name, int64_t version);
  // Imports every PREFIX.fem + PREFIX.plg pair in `dir` as version 1 of PREFIX; returns how many.
  int ImportDirectory(const std::string& dir, std::string* error);

  BlobStore& blobs() { return *blobs_; }
  ModelStore& models() { return *models_; }

 private:
  BlobStore* blobs_;
  ModelStore* models_;
  std::mutex write_mu_;  // uploads and deletes: a delete never removes a blob an upload is about to name
};

}  // namespace idms::server
