// Blobs in an S3 bucket: the object blobs/<sha256> holds the bytes whose SHA-256 it names. An
// object appears whole or not at all (S3's PUT), so there is no temporary name to clean up.
#include "s3_stores.h"

namespace idms::server {
namespace {

constexpr const char* kPrefix = "blobs/";
// The largest blob read back: a model's file is at most --max-upload-mb (at most 1 TiB, 256 MiB by
// default) and its surface as .obj is smaller than its .fem; 4 GiB holds any a server accepts.
constexpr uint64_t kMaxBlobBytes = uint64_t{4} << 30;

bool IsHex64(const std::string& s) {
  return s.size() == 64 && s.find_first_not_of("0123456789abcdef") == std::string::npos;
}

class S3BlobStore final : public BlobStore {
 public:
  explicit S3BlobStore(std::unique_ptr<S3Client> s3) : s3_(std::move(s3)) {}

  bool Put(std::string_view bytes, std::string* sha, std::string* error) override {
    *sha = Sha256Hex(bytes);
    const std::string key = kPrefix + *sha;
    // Already there (another upload of the same file, or another server's): nothing to send.
    uint64_t size = 0;
    std::string why;
    if (s3_->Head(key, &size, &why) == S3Result::kOk && size == bytes.size()) return true;
    if (s3_->Put(key, bytes, error) == S3Result::kOk) return true;
    return false;
  }

  bool Get(const std::string& sha, std::string* bytes) const override {
    if (!IsHex64(sha)) return false;
    std::string error;
    return s3_->Get(kPrefix + sha, bytes, kMaxBlobBytes, &error) == S3Result::kOk;
  }

  bool Has(const std::string& sha) const override {
    uint64_t size = 0;
    std::string error;
    return IsHex64(sha) && s3_->Head(kPrefix + sha, &size, &error) == S3Result::kOk;
  }

  void Remove(const std::string& sha) override {
    std::string error;
    if (IsHex64(sha)) s3_->Delete(kPrefix + sha, &error);
  }

  std::vector<std::string> List() const override {
    std::vector<S3Object> objects;
    std::vector<std::string> out;
    std::string error;
    if (s3_->List(kPrefix, &objects, &error) != S3Result::kOk) return out;
    for (const S3Object& o : objects) {
      const std::string sha = o.key.substr(std::string_view(kPrefix).size());
      if (IsHex64(sha)) out.push_back(sha);
    }
    return out;
  }

 private:
  std::unique_ptr<S3Client> s3_;
};

}  // namespace

std::unique_ptr<BlobStore> OpenS3BlobStore(const S3Location& location, const S3Credentials& credentials,
                                           std::string* error) {
  auto s3 = std::make_unique<S3Client>(location, credentials);
  try {
    if (s3->CheckBucket(error) != S3Result::kOk) return nullptr;
  } catch (const StoreUnavailable& e) {
    *error = e.what();
    return nullptr;
  }
  return std::make_unique<S3BlobStore>(std::move(s3));
}

}  // namespace idms::server
