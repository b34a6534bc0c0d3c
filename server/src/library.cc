// Uploads validated by the sim parsers, blob-then-row writes, deletes that collect their blobs.
#include "idms/server/library.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <set>

#include "idms/sim/model.h"
#include "idms/sim/model_io.h"

namespace idms::server {

bool ValidModelName(std::string_view name) {
  return !name.empty() && name.size() <= 64 && name.front() != '.' && name.find("..") == std::string_view::npos &&
         name.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_.-") ==
             std::string_view::npos;
}

std::optional<ModelVersion> Library::Upload(const std::string& name, std::string_view fem, std::string_view plg,
                                            const std::string& description, UploadError* error, UploadTimings* timings,
                                            const std::string& metadata) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point t0 = Clock::now();
  if (!ValidModelName(name)) {
    *error = {400, "model name '" + name + "': expected 1-64 of [A-Za-z0-9_.-], not starting with '.', no '..'", "", 0,
              0};
    return std::nullopt;
  }
  if (metadata.size() > kMaxVersionMetadataBytes) {
    *error = {400,
              "model " + name + ": metadata of " + std::to_string(metadata.size()) + " bytes, at most " +
                  std::to_string(kMaxVersionMetadataBytes),
              "", 0, 0};
    return std::nullopt;
  }
  // Both files through the sim parsers, then the surface against the model.
  Model model;
  LoadError le;
  if (!ParseModelText(fem, plg, name, &model, &le)) {
    *error = {400, le.ToString(), le.file, le.line, le.col};
    return std::nullopt;
  }
  ModelVersion v;
  v.name = name;
  v.description = description;
  v.metadata = metadata;
  v.atoms = model.num_atoms;
  v.elements = model.num_elems;
  v.triangles = model.num_tris;
  v.bytes = static_cast<int64_t>(fem.size() + plg.size());
  const std::string obj = WriteObj(model);
  const Clock::time_point t1 = Clock::now();
  // Blobs durable first, then the row (under the write lock, so no delete collects them between).
  std::lock_guard lock(write_mu_);
  std::string storage_error;
  if (!blobs_->Put(fem, &v.fem_sha256, &storage_error) || !blobs_->Put(plg, &v.plg_sha256, &storage_error) ||
      !blobs_->Put(obj, &v.obj_sha256, &storage_error) || !models_->AddVersion(&v, &storage_error)) {
    *error = {500, "storing " + name + ": " + storage_error, "", 0, 0};
    return std::nullopt;
  }
  if (timings != nullptr) {
    timings->parse_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
    timings->store_ms = std::chrono::duration<double, std::milli>(Clock::now() - t1).count();
  }
  return v;
}

bool Library::Delete(const std::string& name, int64_t version) {
  std::lock_guard lock(write_mu_);
  const std::optional<ModelRecord> rec = models_->Get(name);
  if (!rec) return false;
  std::set<std::string> shas;
  for (const ModelVersion& v : rec->versions) {
    if (version == 0 || v.version == version) shas.insert({v.fem_sha256, v.plg_sha256, v.obj_sha256});
  }
  if (shas.empty() || !models_->Delete(name, version)) return false;
  // Row first, then the blobs no other version names: a crash in between leaves only garbage
  // that the next start-up collects.
  for (const std::string& sha : shas) {
    if (!models_->BlobReferenced(sha)) blobs_->Remove(sha);
  }
  return true;
}

std::optional<ModelVersion> Library::Find(const std::string& name, int64_t version) {
  std::optional<ModelRecord> rec = models_->Get(name);
  if (!rec) return std::nullopt;
  if (version == 0) return rec->latest();
  for (const ModelVersion& v : rec->versions) {
    if (v.version == version) return v;
  }
  return std::nullopt;
}

int Library::ImportDirectory(const std::string& dir, std::string* error) {
  namespace fs = std::filesystem;
  std::vector<fs::path> fems;
  std::error_code ec;
  for (const fs::directory_entry& e : fs::directory_iterator(dir, ec)) {
    if (e.path().extension() == ".fem") fems.push_back(e.path());
  }
  if (ec) {
    *error = "cannot list " + dir + ": " + ec.message();
    return -1;
  }
  std::sort(fems.begin(), fems.end());
  int imported = 0;
  for (const fs::path& fem_path : fems) {
    const fs::path plg_path = fs::path(fem_path).replace_extension(".plg");
    std::string fem, plg;
    LoadError le;
    if (!fs::exists(plg_path) || !ReadTextFile(fem_path.string(), ReadOptions{}.max_bytes, &fem, &le) ||
        !ReadTextFile(plg_path.string(), ReadOptions{}.max_bytes, &plg, &le)) {
      continue;  // not a pair
    }
    UploadError ue;
    const std::string name = fem_path.stem().string();
    if (!Upload(name, fem, plg, "shipped with idms (models/" + name + ")", &ue)) {
      *error = "importing " + fem_path.string() + ": " + ue.message;
      return -1;
    }
    ++imported;
  }
  return imported;
}

}  // namespace idms::server
