// A throwaway S3 server for the tests: OpenStack Swift all-in-one (proxy with the s3api and
// tempauth middlewares, one account, container and object server, rings of one replica) on free
// loopback ports, its configuration and rings (docker/swift-config.sh, as the scale stack's) and
// its disk in a fresh directory removed at the end.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace idms::test {

class ChildProcess;

class SwiftS3 {
 public:
  // Whether Debian's swift-proxy-server, -account-, -container- and -object-server and
  // swift-ring-builder are installed (the tests skip without them).
  static bool Installed();

  // Writes the configuration and rings, starts the four servers, waits until the S3 API answers
  // and creates the bucket `bucket()`. Check ok() (and error()).
  SwiftS3();
  ~SwiftS3();  // stops the servers and removes the directory
  SwiftS3(const SwiftS3&) = delete;
  SwiftS3& operator=(const SwiftS3&) = delete;

  bool ok() const { return error_.empty(); }
  const std::string& error() const { return error_; }
  uint16_t port() const { return proxy_port_; }  // the S3 endpoint (the proxy)
  static std::string bucket() { return "idms"; }
  // tempauth's S3 credentials: ACCOUNT:USER and the user's key.
  static std::string access_key() { return "idms:tester"; }
  static std::string secret_key() { return "idms-test-secret"; }
  // s3://127.0.0.1:PORT/BUCKET, as idms-server's --blobs takes it.
  std::string Url(const std::string& bucket_name = bucket()) const;
  // Another bucket (tests sharing one Swift each take their own). False with error().
  bool CreateBucket(const std::string& name);

  // Stops every server (SIGTERM, then SIGKILL after 10 s): the store is down, connections are
  // refused. Start() brings them back on the same ports with the same data and waits until the
  // S3 API answers again. False with error() on failure.
  bool Stop();
  bool Start();

  // Runs an S3 request with curl's own SigV4 signing (the `curl` tool, independent of the
  // server's client): `method` on `/BUCKET/KEY` (KEY may hold a query, already canonical);
  // returns the HTTP status (0 when no answer) and the body in *body.
  int Curl(const std::string& method, const std::string& key, std::string* body = nullptr,
           const std::string& upload_file = "") const;

  // The keys under `prefix` in bucket(), in order (ListObjectsV2 through the curl tool; one page).
  std::vector<std::string> Keys(const std::string& prefix) const;

  std::string Log() const;  // the four servers' logs, each with its name

 private:
  bool WriteConfiguration();
  int Request(const std::string& method, const std::string& path, std::string* body,
              const std::string& upload_file) const;
  bool WaitReady();

  std::string dir_;
  uint16_t proxy_port_ = 0, account_port_ = 0, container_port_ = 0, object_port_ = 0;
  std::vector<std::unique_ptr<ChildProcess>> servers_;
  std::string error_;
};

}  // namespace idms::test
