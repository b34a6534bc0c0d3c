// Recordings as files in one directory: ID.live.mcap while the session is live, renamed to
// ID.mcap once the writer has closed it (the rename is atomic, so a reader sees one or the other).
#include <filesystem>

#include "idms/server/storage.h"

namespace idms::server {
namespace {

namespace fs = std::filesystem;

class FileRecordingStore : public RecordingStore {
 public:
  explicit FileRecordingStore(std::string dir) : dir_(std::move(dir)) {}
  std::string LivePath(const std::string& id) const override { return dir_ + "/" + id + ".live.mcap"; }
  std::string FinishedPath(const std::string& id) const override { return dir_ + "/" + id + ".mcap"; }
  bool Recover(const std::string& id, std::string* error) override {
    std::error_code ec;
    if (fs::exists(LivePath(id), ec)) return true;
    *error = "no live recording " + LivePath(id);
    return false;
  }
  bool Publish(const std::string& id, std::string* error) override {
    std::error_code ec;
    fs::rename(LivePath(id), FinishedPath(id), ec);
    if (ec) *error = "rename " + LivePath(id) + " -> " + FinishedPath(id) + ": " + ec.message();
    return !ec;
  }
  void Remove(const std::string& id) override {
    std::error_code ec;
    fs::remove(LivePath(id), ec);
    fs::remove(FinishedPath(id), ec);
  }

 private:
  std::string dir_;
};

}  // namespace

std::unique_ptr<RecordingStore> OpenRecordingDirectory(const std::string& dir, std::string* error) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) {
    *error = "cannot create " + dir + ": " + ec.message();
    return nullptr;
  }
  return std::make_unique<FileRecordingStore>(dir);
}

}  // namespace idms::server
