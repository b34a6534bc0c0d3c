// An S3 client over libcurl for the object stores (blobs, recordings): path-style requests to
// http://HOST:PORT/BUCKET/KEY signed with AWS Signature V4 by libcurl itself (CURLOPT_AWS_SIGV4),
// connections kept and reused, and the replies' XML (errors, object listings) parsed here.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace idms::server {

// Where the objects live: `s3://HOST:PORT/BUCKET[?region=R][&tls=1]` (the region the signatures
// are scoped to, us-east-1 unless named; tls=1: HTTPS, the certificate checked against the
// system's CAs).
struct S3Location {
  std::string host;
  uint16_t port = 0;
  std::string bucket;
  std::string region = "us-east-1";
  bool tls = false;
  std::string Describe() const;  // "s3://HOST:PORT/BUCKET" (no credentials are ever part of it)
};
// False with *error saying what is wrong with `url`.
bool ParseS3Url(const std::string& url, S3Location* location, std::string* error);
// Whether `text` is meant as an S3 URL (starts with s3://).
bool IsS3Url(const std::string& text);

struct S3Credentials {
  std::string access_key, secret_key;
};
// AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY from the environment (never the command line: `ps`
// would show them). False with *error naming the missing variable.
bool S3CredentialsFromEnvironment(S3Credentials* credentials, std::string* error);

struct S3Timeouts {
  std::chrono::milliseconds connect{3000};  // TCP connect (and TLS handshake)
  // A request without a large body, whole (HEAD, DELETE, a listing page, a PUT or GET under 1 MiB);
  // a larger transfer instead fails once it moves under 1 KiB/s for this long.
  std::chrono::milliseconds request{30000};
};

// One object of a listing.
struct S3Object {
  std::string key;
  uint64_t size = 0;
};
// One page of ListObjectsV2.
struct S3ListPage {
  std::vector<S3Object> objects;
  bool truncated = false;
  std::string next_token;  // NextContinuationToken, when truncated
};
// Parses a ListObjectsV2 reply (untrusted bytes: bounded, never trusted for more than it says).
// False with *error when it is not one.
bool ParseListObjectsV2(std::string_view xml, S3ListPage* page, std::string* error);
// "Code: Message" from an S3 <Error> reply; empty when the body is not one.
std::string ParseS3Error(std::string_view xml);

// What a call found. Unreachable stores are not a result: they throw StoreUnavailable.
enum class S3Result {
  kOk,
  kNotFound,  // 404 NoSuchKey (any 404 for HEAD, which has no body to say more)
  kRefused,   // any other refusal (403, 400, a missing bucket, ...): *error says which
};

struct S3Call;  // one request, as the client runs it (s3_client.cc)

// Thread-safe: each call takes an idle connection (a curl handle) from a small pool, or makes one.
// Every call throws StoreUnavailable (storage.h) when the store cannot be reached, stops
// answering, or answers 5xx (including 503 SlowDown), so that the HTTP layer answers 503 with
// Retry-After; the next call tries again. Errors read "S3 PUT blobs/ab12...: 403
// SignatureDoesNotMatch: ..." (the method, the key, S3's status, code and message).
class S3Client {
 public:
  S3Client(S3Location location, S3Credentials credentials, S3Timeouts timeouts = S3Timeouts());
  ~S3Client();
  S3Client(const S3Client&) = delete;
  S3Client& operator=(const S3Client&) = delete;

  const S3Location& location() const { return location_; }

  // PUT from memory, or from `length` bytes of `fd` at `offset` (read with pread: the caller's
  // file position is untouched). The payload's SHA-256 is signed, so the store refuses bytes
  // changed on the way.
  S3Result Put(const std::string& key, std::string_view bytes, std::string* error);
  S3Result PutFile(const std::string& key, int fd, uint64_t offset, uint64_t length, std::string* error);
  // GET into *bytes (replaced), refused beyond `max_bytes`.
  S3Result Get(const std::string& key, std::string* bytes, uint64_t max_bytes, std::string* error);
  // GET of bytes [first, first + length) (Range), into *bytes.
  S3Result GetRange(const std::string& key, uint64_t first, uint64_t length, std::string* bytes, std::string* error);
  // GET written to `fd` at its current position; *size: the bytes written.
  S3Result GetToFile(const std::string& key, int fd, uint64_t* size, std::string* error);
  // HEAD: the object's size.
  S3Result Head(const std::string& key, uint64_t* size, std::string* error);
  // DELETE (an absent key is kOk, as S3 answers 204 for it).
  S3Result Delete(const std::string& key, std::string* error);
  // Every object whose key starts with `prefix`, in key order, over as many pages as it takes.
  S3Result List(const std::string& prefix, std::vector<S3Object>* objects, std::string* error);
  // HEAD of the bucket: the start-up check that the store answers, the bucket exists and the
  // credentials are accepted.
  S3Result CheckBucket(std::string* error);
  // Keys per listing page (S3's default and most: 1000). Tests page over a few objects with less.
  void set_list_page_keys(int keys) { list_page_keys_ = keys; }

 private:
  struct Handle;
  S3Result Run(S3Call& call, std::string* error);
  std::unique_ptr<Handle> Acquire();
  void Release(std::unique_ptr<Handle> handle);

  S3Location location_;
  S3Credentials credentials_;
  S3Timeouts timeouts_;
  std::string base_url_;  // http(s)://HOST:PORT/BUCKET
  int list_page_keys_ = 1000;
  struct Pool;
  std::unique_ptr<Pool> pool_;
};

}  // namespace idms::server
