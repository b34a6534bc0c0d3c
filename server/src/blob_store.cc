// Blobs as files named by their SHA-256 under DIR/ab/abcdef... (two hex digits of fan-out), each
// written to DIR/tmp/, fsync'ed and renamed into place, so a crash leaves a whole blob or none.
#include <fcntl.h>
#include <openssl/evp.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "idms/server/storage.h"

namespace idms::server {
namespace {

namespace fs = std::filesystem;

bool IsHex64(const std::string& s) {
  return s.size() == 64 && s.find_first_not_of("0123456789abcdef") == std::string::npos;
}

std::string Errno(const std::string& what, const std::string& path) {
  return what + " " + path + ": " + std::strerror(errno);
}

// Writes all of `bytes` to fd; false on any short write.
bool WriteAll(int fd, std::string_view bytes) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    done += static_cast<size_t>(n);
  }
  return true;
}

bool FsyncPath(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (fd < 0) return false;
  const bool ok = ::fsync(fd) == 0;
  ::close(fd);
  return ok;
}

class BlobDirectory final : public BlobStore {
 public:
  explicit BlobDirectory(fs::path root) : root_(std::move(root)) {}

  bool Init(std::string* error) {
    std::error_code ec;
    fs::create_directories(root_ / "tmp", ec);
    if (ec) {
      *error = "cannot create " + (root_ / "tmp").string() + ": " + ec.message();
      return false;
    }
    // A crash during Put leaves its temporary file; nothing else writes there.
    for (const fs::directory_entry& e : fs::directory_iterator(root_ / "tmp", ec)) fs::remove(e.path(), ec);
    return true;
  }

  bool Put(std::string_view bytes, std::string* sha, std::string* error) override {
    *sha = Sha256Hex(bytes);
    const fs::path final_path = PathOf(*sha);
    if (Has(*sha)) return true;
    std::error_code ec;
    fs::create_directories(final_path.parent_path(), ec);
    // tmp file: unique name, exclusive create.
    thread_local std::mt19937_64 rng{std::random_device{}()};
    const fs::path tmp = root_ / "tmp" / (*sha + "." + std::to_string(rng()));
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) {
      *error = Errno("cannot create", tmp.string());
      return false;
    }
    const bool written = WriteAll(fd, bytes) && ::fsync(fd) == 0;
    const int saved = errno;
    ::close(fd);
    if (!written) {
      errno = saved;
      *error = Errno("cannot write", tmp.string());
      fs::remove(tmp, ec);
      return false;
    }
    // rename + fsync of the directory: the name is durable before any row names it.
    if (::rename(tmp.c_str(), final_path.c_str()) != 0) {
      *error = Errno("cannot rename into", final_path.string());
      fs::remove(tmp, ec);
      return false;
    }
    FsyncPath(final_path.parent_path());
    return true;
  }

  bool Get(const std::string& sha, std::string* bytes) const override {
    if (!IsHex64(sha)) return false;
    std::ifstream in(PathOf(sha), std::ios::binary);
    if (!in) return false;
    std::ostringstream ss;
    ss << in.rdbuf();
    *bytes = std::move(ss).str();
    return true;
  }

  bool Has(const std::string& sha) const override {
    std::error_code ec;
    return IsHex64(sha) && fs::is_regular_file(PathOf(sha), ec);
  }

  void Remove(const std::string& sha) override {
    std::error_code ec;
    if (IsHex64(sha)) fs::remove(PathOf(sha), ec);
  }

  std::vector<std::string> List() const override {
    std::vector<std::string> out;
    std::error_code ec;
    for (const fs::directory_entry& d : fs::directory_iterator(root_, ec)) {
      if (!d.is_directory() || d.path().filename() == "tmp") continue;
      for (const fs::directory_entry& f : fs::directory_iterator(d.path(), ec)) {
        const std::string name = f.path().filename().string();
        if (IsHex64(name)) out.push_back(name);
      }
    }
    return out;
  }

 private:
  fs::path PathOf(const std::string& sha) const { return root_ / sha.substr(0, 2) / sha; }

  fs::path root_;
};

}  // namespace

std::unique_ptr<BlobStore> OpenBlobDirectory(const std::string& dir, std::string* error) {
  auto store = std::make_unique<BlobDirectory>(dir);
  if (!store->Init(error)) return nullptr;
  return store;
}

bool OpenStorage(const std::string& data_dir, Storage* storage, std::string* error, ObjectStores objects) {
  const std::string db = (fs::path(data_dir) / "idms.db").string();
  std::error_code ec;
  fs::create_directories(data_dir, ec);
  if (ec) {
    *error = "cannot create the data directory " + data_dir + ": " + ec.message();
    return false;
  }
  std::unique_ptr<ModelStore> models = OpenSqliteModelStore(db, error);
  if (!models) return false;
  std::unique_ptr<SessionIndex> sessions = OpenSqliteSessionIndex(db, error);
  if (!sessions) return false;
  const bool own_blobs = objects.blobs == nullptr;
  if (!OpenStorage(data_dir, std::move(models), std::move(sessions), storage, error, std::move(objects))) return false;
  // A crash between a blob's rename and its row's commit leaves a blob nobody names. Only here,
  // where this server is the library's only writer: with a shared database or bucket another
  // server's upload may be between the two (its blob stored, its row not yet committed).
  if (!own_blobs) return true;
  for (const std::string& sha : storage->blobs->List()) {
    if (!storage->models->BlobReferenced(sha)) storage->blobs->Remove(sha);
  }
  return true;
}

bool OpenStorage(const std::string& data_dir, std::unique_ptr<ModelStore> models,
                 std::unique_ptr<SessionIndex> sessions, Storage* storage, std::string* error, ObjectStores objects) {
  std::error_code ec;
  fs::create_directories(data_dir, ec);
  if (ec) {
    *error = "cannot create the data directory " + data_dir + ": " + ec.message();
    return false;
  }
  Storage s;
  s.models = std::move(models);
  s.sessions = std::move(sessions);
  s.blobs =
      objects.blobs ? std::move(objects.blobs) : OpenBlobDirectory((fs::path(data_dir) / "blobs").string(), error);
  if (!s.blobs) return false;
  s.recordings = objects.recordings ? std::move(objects.recordings)
                                    : OpenRecordingDirectory((fs::path(data_dir) / "recordings").string(), error);
  if (!s.recordings) return false;
  *storage = std::move(s);
  return true;
}

}  // namespace idms::server
