// S3Client: one libcurl easy handle per call, taken from a pool so that its connection is reused;
// libcurl signs every request (SigV4) and we sign the payload's SHA-256 with it.
#include "s3_client.h"

#include <curl/curl.h>
#include <openssl/evp.h>
#include <unistd.h>

#include <array>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <mutex>

#include "idms/protocol/digest.h"
#include "idms/server/storage.h"

namespace idms::server {
namespace {

// The SHA-256 of no bytes: the payload hash of a request without a body.
constexpr const char* kEmptySha256 = "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855";
constexpr uint64_t kLargeBytes = uint64_t{1} << 20;  // beyond: a transfer is timed by its progress
constexpr size_t kMaxErrorBody = 64 << 10;           // an error reply kept to read S3's code from
constexpr uint64_t kMaxListPage = uint64_t{16} << 20;
constexpr size_t kMaxIdleHandles = 8;

// AWS's URI encoding (SigV4's canonical form): every byte but A-Z a-z 0-9 - _ . ~ as %XX, and
// '/' kept in a key. libcurl 7.88 signs the path and query as given, so they are given canonical.
std::string UriEncode(std::string_view text, bool keep_slash) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string out;
  out.reserve(text.size());
  for (const char ch : text) {
    const auto c = static_cast<unsigned char>(ch);
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == '~' || (keep_slash && c == '/')) {
      out.push_back(ch);
    } else {
      out.push_back('%');
      out.push_back(kHex[c >> 4]);
      out.push_back(kHex[c & 15]);
    }
  }
  return out;
}

// pread until `length` bytes or end of file; -1 on an error (errno set).
ssize_t PreadAll(int fd, char* buf, size_t length, uint64_t offset) {
  size_t done = 0;
  while (done < length) {
    const ssize_t n = ::pread(fd, buf + done, length - done, static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return -1;
    if (n == 0) break;
    done += static_cast<size_t>(n);
  }
  return static_cast<ssize_t>(done);
}

// The SHA-256 of `length` bytes of `fd` at `offset`, as hex. False with *error when they cannot
// all be read.
bool Sha256OfRange(int fd, uint64_t offset, uint64_t length, std::string* hex, std::string* error) {
  EVP_MD_CTX* ctx = EVP_MD_CTX_new();
  bool ok = ctx != nullptr && EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr) == 1;
  std::array<char, 64 << 10> buf;
  uint64_t done = 0;
  while (ok && done < length) {
    const size_t want = static_cast<size_t>(std::min<uint64_t>(buf.size(), length - done));
    const ssize_t n = PreadAll(fd, buf.data(), want, offset + done);
    if (n != static_cast<ssize_t>(want)) {
      *error = n < 0 ? std::string("cannot read the file: ") + std::strerror(errno)
                     : "the file ends at byte " + std::to_string(offset + done + static_cast<uint64_t>(n)) +
                           ", before the " + std::to_string(length) + " bytes to upload";
      ok = false;
      break;
    }
    ok = EVP_DigestUpdate(ctx, buf.data(), want) == 1;
    done += want;
  }
  std::array<uint8_t, 32> md;
  unsigned int md_len = 0;
  ok = ok && EVP_DigestFinal_ex(ctx, md.data(), &md_len) == 1 && md_len == md.size();
  EVP_MD_CTX_free(ctx);
  if (ok) *hex = HexEncode(md);
  if (!ok && error->empty()) *error = "SHA-256 failed";
  return ok;
}

// libcurl's global state, once per process before any handle.
void InitCurl() {
  static std::once_flag once;
  std::call_once(once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
}

}  // namespace

struct S3Client::Handle {
  CURL* curl = curl_easy_init();
  ~Handle() { curl_easy_cleanup(curl); }
};

struct S3Client::Pool {
  std::mutex mu;
  std::vector<std::unique_ptr<Handle>> idle;  // under mu
};

// One request: what to send, where the reply goes, and what came back.
struct S3Call {
  const char* method = "GET";
  std::string key;    // empty: the bucket itself
  std::string query;  // canonical (sorted, encoded)
  std::string range;  // "bytes=FIRST-LAST", or empty
  // The body: bytes in memory, or a range of a file.
  bool upload = false;
  std::string_view body;
  int in_fd = -1;
  uint64_t in_offset = 0, in_length = 0, sent = 0;
  // The reply: into a string (up to max_out bytes) or appended to a file.
  std::string* out = nullptr;
  uint64_t max_out = 0;
  int out_fd = -1;
  uint64_t received = 0;
  // What happened.
  int64_t content_length = -1;  // the reply's Content-Length (HEAD's size), -1 when none
  CURL* curl = nullptr;
  std::string error_body;
  bool too_large = false;
  int local_errno = 0;  // reading the upload or writing the download failed
};

namespace {

size_t OnWrite(char* data, size_t size, size_t n, void* user) {
  auto& c = *static_cast<S3Call*>(user);
  const size_t len = size * n;
  long status = 0;
  curl_easy_getinfo(c.curl, CURLINFO_RESPONSE_CODE, &status);
  // An error's body is S3's <Error>: kept (bounded) to say why.
  if (status < 200 || status >= 300) {
    c.error_body.append(data, std::min(len, kMaxErrorBody - std::min(kMaxErrorBody, c.error_body.size())));
    return len;
  }
  if (c.out_fd >= 0) {
    for (size_t done = 0; done < len;) {
      const ssize_t w = ::write(c.out_fd, data + done, len - done);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) {
        c.local_errno = w < 0 ? errno : EIO;
        return 0;
      }
      done += static_cast<size_t>(w);
    }
  } else if (c.out != nullptr) {
    if (c.received + len > c.max_out) {
      c.too_large = true;
      return 0;
    }
    c.out->append(data, len);
  }
  c.received += len;
  return len;
}

size_t OnRead(char* buf, size_t size, size_t n, void* user) {
  auto& c = *static_cast<S3Call*>(user);
  const size_t want = static_cast<size_t>(std::min<uint64_t>(size * n, c.in_length - c.sent));
  if (want == 0) return 0;
  if (c.in_fd < 0) {
    std::memcpy(buf, c.body.data() + c.sent, want);
  } else {
    const ssize_t got = PreadAll(c.in_fd, buf, want, c.in_offset + c.sent);
    if (got != static_cast<ssize_t>(want)) {
      c.local_errno = got < 0 ? errno : EIO;  // the file shrank under us
      return CURL_READFUNC_ABORT;
    }
  }
  c.sent += want;
  return want;
}

// libcurl rewinds the body when it resends a request (a reused connection the server had closed).
int OnSeek(void* user, curl_off_t offset, int origin) {
  auto& c = *static_cast<S3Call*>(user);
  if (origin != SEEK_SET || offset < 0 || static_cast<uint64_t>(offset) > c.in_length) return CURL_SEEKFUNC_FAIL;
  c.sent = static_cast<uint64_t>(offset);
  return CURL_SEEKFUNC_OK;
}

}  // namespace

S3Client::S3Client(S3Location location, S3Credentials credentials, S3Timeouts timeouts)
    : location_(std::move(location)),
      credentials_(std::move(credentials)),
      timeouts_(timeouts),
      pool_(std::make_unique<Pool>()) {
  InitCurl();
  base_url_ = std::string(location_.tls ? "https" : "http") + "://" + location_.host + ":" +
              std::to_string(location_.port) + "/" + location_.bucket;
}

S3Client::~S3Client() = default;

std::unique_ptr<S3Client::Handle> S3Client::Acquire() {
  {
    std::lock_guard lock(pool_->mu);
    if (!pool_->idle.empty()) {
      std::unique_ptr<Handle> h = std::move(pool_->idle.back());
      pool_->idle.pop_back();
      return h;
    }
  }
  auto h = std::make_unique<Handle>();
  if (h->curl == nullptr) throw std::bad_alloc();
  return h;
}

void S3Client::Release(std::unique_ptr<Handle> handle) {
  // A reset handle keeps its open connection (and its DNS cache) for the next call.
  curl_easy_reset(handle->curl);
  std::lock_guard lock(pool_->mu);
  if (pool_->idle.size() < kMaxIdleHandles) pool_->idle.push_back(std::move(handle));
}

S3Result S3Client::Run(S3Call& c, std::string* error) {
  std::unique_ptr<Handle> handle = Acquire();
  CURL* curl = handle->curl;
  c.curl = curl;
  const std::string what = std::string("S3 ") + c.method + " " + (c.key.empty() ? location_.bucket : c.key);
  // The payload's hash, signed: the store checks the bytes it got against it.
  std::string payload_sha = kEmptySha256;
  if (c.upload) {
    if (c.in_fd < 0) {
      payload_sha = Sha256Hex(c.body);
    } else if (std::string why; !Sha256OfRange(c.in_fd, c.in_offset, c.in_length, &payload_sha, &why)) {
      Release(std::move(handle));
      *error = what + ": " + why;
      return S3Result::kRefused;
    }
  }
  std::string url = base_url_;
  if (!c.key.empty()) url.append("/").append(UriEncode(c.key, true));
  if (!c.query.empty()) url.append("?").append(c.query);
  const std::string sigv4 = "aws:amz:" + location_.region + ":s3";
  curl_slist* headers = nullptr;
  headers = curl_slist_append(headers, ("x-amz-content-sha256: " + payload_sha).c_str());
  // Not "Expect:" to drop libcurl's 100-continue on large uploads: libcurl 7.88 signs the
  // removed header as if it were sent, and the store refuses the signature.
  if (!c.range.empty()) headers = curl_slist_append(headers, ("Range: " + c.range).c_str());
  std::array<char, CURL_ERROR_SIZE> curl_error{};
  curl_easy_setopt(curl, CURLOPT_URL, url.c_str());
  curl_easy_setopt(curl, CURLOPT_AWS_SIGV4, sigv4.c_str());
  curl_easy_setopt(curl, CURLOPT_USERNAME, credentials_.access_key.c_str());
  curl_easy_setopt(curl, CURLOPT_PASSWORD, credentials_.secret_key.c_str());
  curl_easy_setopt(curl, CURLOPT_HTTPHEADER, headers);
  curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(curl, CURLOPT_TCP_KEEPALIVE, 1L);
  curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, curl_error.data());
  curl_easy_setopt(curl, CURLOPT_CONNECTTIMEOUT_MS, static_cast<long>(timeouts_.connect.count()));
  // Small requests have a deadline; large transfers must keep moving instead.
  const bool large = c.in_length > kLargeBytes || c.out_fd >= 0 || c.max_out > kLargeBytes;
  if (large) {
    curl_easy_setopt(curl, CURLOPT_LOW_SPEED_LIMIT, 1024L);
    curl_easy_setopt(
        curl, CURLOPT_LOW_SPEED_TIME,
        static_cast<long>(std::max<int64_t>(1, std::chrono::ceil<std::chrono::seconds>(timeouts_.request).count())));
  } else {
    curl_easy_setopt(curl, CURLOPT_TIMEOUT_MS, static_cast<long>(timeouts_.request.count()));
  }
  curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, OnWrite);
  curl_easy_setopt(curl, CURLOPT_WRITEDATA, &c);
  if (std::strcmp(c.method, "HEAD") == 0) {
    curl_easy_setopt(curl, CURLOPT_NOBODY, 1L);
  } else if (std::strcmp(c.method, "DELETE") == 0) {
    curl_easy_setopt(curl, CURLOPT_CUSTOMREQUEST, "DELETE");
  } else if (c.upload) {
    curl_easy_setopt(curl, CURLOPT_UPLOAD, 1L);
    curl_easy_setopt(curl, CURLOPT_INFILESIZE_LARGE, static_cast<curl_off_t>(c.in_length));
    curl_easy_setopt(curl, CURLOPT_READFUNCTION, OnRead);
    curl_easy_setopt(curl, CURLOPT_READDATA, &c);
    curl_easy_setopt(curl, CURLOPT_SEEKFUNCTION, OnSeek);
    curl_easy_setopt(curl, CURLOPT_SEEKDATA, &c);
  }
  const CURLcode rc = curl_easy_perform(curl);
  long status = 0;
  curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &status);
  curl_off_t content_length = -1;
  curl_easy_getinfo(curl, CURLINFO_CONTENT_LENGTH_DOWNLOAD_T, &content_length);
  c.content_length = content_length;
  curl_slist_free_all(headers);
  Release(std::move(handle));

  // Our side: a reply too large, or a file that could not be read or written.
  if (c.too_large) {
    *error = what + ": the object is larger than " + std::to_string(c.max_out) + " bytes";
    return S3Result::kRefused;
  }
  if (c.local_errno != 0) {
    *error = what + ": " + std::strerror(c.local_errno);
    return S3Result::kRefused;
  }
  // The store's side: unreachable, silent, cut off, or failing (5xx) is "unavailable".
  if (rc != CURLE_OK) {
    throw StoreUnavailable(what + ": " + location_.Describe() +
                           " unreachable: " + (curl_error[0] != '\0' ? curl_error.data() : curl_easy_strerror(rc)));
  }
  if (status >= 200 && status < 300) return S3Result::kOk;
  const std::string s3 = ParseS3Error(c.error_body);
  const std::string why = what + ": " + std::to_string(status) + (s3.empty() ? "" : " " + s3);
  if (status >= 500) throw StoreUnavailable(why);
  *error = why;
  if (status == 404 && (s3.empty() || s3.rfind("NoSuchKey", 0) == 0) && !c.key.empty()) return S3Result::kNotFound;
  if (status == 403 && s3.empty()) *error += " Forbidden (are AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY right?)";
  return S3Result::kRefused;
}

S3Result S3Client::Put(const std::string& key, std::string_view bytes, std::string* error) {
  S3Call c;
  c.method = "PUT";
  c.key = key;
  c.upload = true;
  c.body = bytes;
  c.in_length = bytes.size();
  return Run(c, error);
}

S3Result S3Client::PutFile(const std::string& key, int fd, uint64_t offset, uint64_t length, std::string* error) {
  S3Call c;
  c.method = "PUT";
  c.key = key;
  c.upload = true;
  c.in_fd = fd;
  c.in_offset = offset;
  c.in_length = length;
  return Run(c, error);
}

S3Result S3Client::Get(const std::string& key, std::string* bytes, uint64_t max_bytes, std::string* error) {
  bytes->clear();
  S3Call c;
  c.key = key;
  c.out = bytes;
  c.max_out = max_bytes;
  return Run(c, error);
}

S3Result S3Client::GetRange(const std::string& key, uint64_t first, uint64_t length, std::string* bytes,
                            std::string* error) {
  bytes->clear();
  if (length == 0) return S3Result::kOk;
  S3Call c;
  c.key = key;
  c.range = "bytes=" + std::to_string(first) + "-" + std::to_string(first + length - 1);
  c.out = bytes;
  c.max_out = length;
  // A store that ignored the range and sent the whole object is refused as too large.
  return Run(c, error);
}

S3Result S3Client::GetToFile(const std::string& key, int fd, uint64_t* size, std::string* error) {
  S3Call c;
  c.key = key;
  c.out_fd = fd;
  const S3Result r = Run(c, error);
  *size = c.received;
  return r;
}

S3Result S3Client::Head(const std::string& key, uint64_t* size, std::string* error) {
  S3Call c;
  c.method = "HEAD";
  c.key = key;
  const S3Result r = Run(c, error);
  if (r == S3Result::kOk && c.content_length < 0) {
    *error = "S3 HEAD " + key + ": no Content-Length in the reply";
    return S3Result::kRefused;
  }
  if (r == S3Result::kOk) *size = static_cast<uint64_t>(c.content_length);
  return r;
}

S3Result S3Client::Delete(const std::string& key, std::string* error) {
  S3Call c;
  c.method = "DELETE";
  c.key = key;
  const S3Result r = Run(c, error);
  return r == S3Result::kNotFound ? S3Result::kOk : r;
}

S3Result S3Client::List(const std::string& prefix, std::vector<S3Object>* objects, std::string* error) {
  objects->clear();
  std::string token;
  // Pages of up to 1000 keys (S3's default), each a request; the keys come in order. The query's
  // parameters in the order SigV4 signs them (by name).
  while (true) {
    S3Call c;
    std::string page_xml;
    c.query = (token.empty() ? "" : "continuation-token=" + UriEncode(token, false) + "&") + "list-type=2&" +
              (list_page_keys_ == 1000 ? "" : "max-keys=" + std::to_string(list_page_keys_) + "&") +
              "prefix=" + UriEncode(prefix, false);
    c.out = &page_xml;
    c.max_out = kMaxListPage;
    if (const S3Result r = Run(c, error); r != S3Result::kOk) return r;
    S3ListPage page;
    if (!ParseListObjectsV2(page_xml, &page, error)) {
      *error = "S3 GET " + location_.bucket + "?list-type=2&prefix=" + prefix + ": " + *error;
      return S3Result::kRefused;
    }
    for (S3Object& o : page.objects) objects->push_back(std::move(o));
    if (!page.truncated) return S3Result::kOk;
    if (page.next_token == token) {
      *error = "S3 listing of " + prefix + ": the store repeated its continuation token";
      return S3Result::kRefused;
    }
    token = page.next_token;
  }
}

S3Result S3Client::CheckBucket(std::string* error) {
  // A listing of one key rather than HEAD: its refusal carries S3's code (NoSuchBucket,
  // InvalidAccessKeyId, SignatureDoesNotMatch).
  S3Call c;
  std::string page_xml;
  c.query = "list-type=2&max-keys=1";
  c.out = &page_xml;
  c.max_out = kMaxListPage;
  return Run(c, error);
}

}  // namespace idms::server
