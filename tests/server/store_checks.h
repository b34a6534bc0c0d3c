// What the store tests (storage_test.cc, and the contract on SQLite and PostgreSQL in
// pg_store_test.cc) build their rows from.
#pragma once

#include <string>

#include "idms/server/storage.h"

namespace idms::test {

// A model version naming `fem_sha` and fixed plg and obj hashes, as an upload would store it.
inline server::ModelVersion TestModelVersion(const std::string& name, const std::string& fem_sha) {
  server::ModelVersion v;
  v.name = name;
  v.description = "d";
  v.atoms = 3;
  v.bytes = 10;
  v.fem_sha256 = fem_sha;
  v.plg_sha256 = std::string(64, 'b');
  v.obj_sha256 = std::string(64, 'c');
  return v;
}

}  // namespace idms::test
