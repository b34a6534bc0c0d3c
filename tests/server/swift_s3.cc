// SwiftS3: the scale stack's configuration and rings (docker/swift-config.sh) and four Swift servers
// as child processes; the S3 API checked and the bucket made with the curl tool's own SigV4 signing.
#include "swift_s3.h"

#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/xattr.h>
#include <unistd.h>

#include <array>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <thread>

#include "child_process.h"

namespace idms::test {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using std::chrono::seconds;

constexpr const char* kBin = "/usr/bin/";
constexpr std::array<const char*, 4> kServers = {"account", "container", "object", "proxy"};

// A free loopback port outside the kernel's ephemeral range. While the servers are stopped their
// ports are free, and an ephemeral one could be handed to an outgoing connection (the idms-server's
// retries to this very port connect to themselves), so that the restarted server cannot bind it.
uint16_t FreePort() {
  int low = 32768, high = 60999;
  std::ifstream("/proc/sys/net/ipv4/ip_local_port_range") >> low >> high;
  const bool below = low > 12000;
  std::random_device rd;
  std::uniform_int_distribution<int> pick(below ? 10000 : high + 1, below ? low - 1 : 65535);
  for (int attempt = 0; attempt < 200; ++attempt) {
    const uint16_t port = static_cast<uint16_t>(pick(rd));
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(port);
    const bool free = ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
    ::close(fd);
    if (free) return port;
  }
  return 0;
}

// Whether `dir` takes user extended attributes (the object server keeps its metadata in them).
bool TakesUserXattrs(const std::string& dir) {
  const std::string probe = dir + "/.xattr-probe";
  std::ofstream(probe) << "x";
  const bool ok = ::setxattr(probe.c_str(), "user.idms", "1", 1, 0) == 0;
  std::error_code ec;
  fs::remove(probe, ec);
  return ok;
}

bool Accepts(uint16_t port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(port);
  const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  ::close(fd);
  return ok;
}

}  // namespace

bool SwiftS3::Installed() {
  std::error_code ec;
  for (const char* s : kServers) {
    if (!fs::exists(std::string(kBin) + "swift-" + s + "-server", ec)) return false;
  }
  return fs::exists(std::string(kBin) + "swift-ring-builder", ec) && fs::exists(std::string(kBin) + "curl", ec);
}

SwiftS3::SwiftS3() {
  if (!Installed()) {
    error_ = "Swift is not installed (swift-proxy, swift-account, swift-container, swift-object, curl)";
    return;
  }
  // A directory whose file system keeps user xattrs: the temporary directory, else the current one.
  for (const std::string& base : {fs::temp_directory_path().string(), fs::current_path().string()}) {
    std::string tmpl = base + "/idms-swift-XXXXXX";
    if (::mkdtemp(tmpl.data()) == nullptr) continue;
    if (TakesUserXattrs(tmpl)) {
      dir_ = tmpl;
      break;
    }
    std::error_code ec;
    fs::remove_all(tmpl, ec);
  }
  if (dir_.empty()) {
    error_ = "no directory that takes user extended attributes (Swift's object server needs them)";
    return;
  }
  proxy_port_ = FreePort();
  account_port_ = FreePort();
  container_port_ = FreePort();
  object_port_ = FreePort();
  const std::set<uint16_t> ports = {proxy_port_, account_port_, container_port_, object_port_};
  if (ports.size() != 4 || ports.count(0) != 0) {
    error_ = "no four free loopback ports outside the ephemeral range";
    return;
  }
  if (!WriteConfiguration() || !Start()) return;
  // The default bucket (PUT Bucket; Swift's account is created on first use).
  if (!CreateBucket(bucket())) error_ += Log();
}

SwiftS3::~SwiftS3() {
  Stop();
  std::error_code ec;
  if (!dir_.empty()) fs::remove_all(dir_, ec);
}

bool SwiftS3::WriteConfiguration() {
  // The configuration, rings and curl's netrc the scale stack's container runs
  // (docker/swift-config.sh), the device under the directory.
  const std::string log = dir_ + "/swift-config.log";
  ChildProcess config("/bin/sh",
                      {IDMS_SOURCE_DIR "/docker/swift-config.sh", dir_, dir_ + "/devices", std::to_string(proxy_port_),
                       std::to_string(account_port_), std::to_string(container_port_), std::to_string(object_port_),
                       access_key(), secret_key()},
                      log);
  if (const auto status = config.Wait(seconds(60)); status != 0) {
    error_ = "docker/swift-config.sh failed (" + (status ? "status " + std::to_string(*status) : "timed out") + "):\n" +
             ReadText(log);
    return false;
  }
  return true;
}

bool SwiftS3::Start() {
  if (!servers_.empty()) return true;
  for (const char* s : kServers) {
    // -v: the log on the console (stderr), into the server's log file; no syslog needed.
    servers_.push_back(std::make_unique<ChildProcess>(std::string(kBin) + "swift-" + s + "-server",
                                                      std::vector<std::string>{dir_ + "/" + s + "-server.conf", "-v"},
                                                      dir_ + "/" + s + ".log"));
  }
  return WaitReady();
}

bool SwiftS3::WaitReady() {
  const auto deadline = std::chrono::steady_clock::now() + seconds(60);
  while (std::chrono::steady_clock::now() < deadline) {
    for (size_t i = 0; i < servers_.size(); ++i) {
      if (servers_[i]->Wait(milliseconds(0))) {
        error_ = std::string("swift-") + kServers[i] + "-server exited at start-up:\n" + Log();
        return false;
      }
    }
    // Every server accepts, and the proxy authenticates an S3 request (404: no bucket yet).
    bool listening = true;
    for (const uint16_t port : {account_port_, container_port_, object_port_, proxy_port_}) {
      listening = listening && Accepts(port);
    }
    if (const int status = listening ? Curl("GET", "") : 0; status == 200 || status == 404) {
      error_.clear();
      return true;
    }
    std::this_thread::sleep_for(milliseconds(50));
  }
  error_ = "Swift's S3 API did not answer within 60 s:\n" + Log();
  return false;
}

bool SwiftS3::Stop() {
  for (auto& s : servers_) s->Signal(SIGTERM);
  bool ok = true;
  for (auto& s : servers_) {
    if (!s->Wait(seconds(10))) {
      s->Signal(SIGKILL);
      ok = s->Wait(seconds(10)).has_value() && ok;
    }
  }
  servers_.clear();
  return ok;
}

int SwiftS3::Curl(const std::string& method, const std::string& key, std::string* body,
                  const std::string& upload_file) const {
  return Request(method, "/" + bucket() + (key.empty() ? "" : "/" + key), body, upload_file);
}

bool SwiftS3::CreateBucket(const std::string& name) {
  std::string body;
  const int status = Request("PUT", "/" + name, &body, "");
  if (status != 200) error_ = "creating bucket " + name + ": HTTP " + std::to_string(status) + " " + body;
  return status == 200;
}

std::string SwiftS3::Url(const std::string& bucket_name) const {
  return "s3://127.0.0.1:" + std::to_string(proxy_port_) + "/" + bucket_name;
}

int SwiftS3::Request(const std::string& method, const std::string& path, std::string* body,
                     const std::string& upload_file) const {
  const std::string out = dir_ + "/curl.out." + std::to_string(::gettid());
  std::string command = "curl -s -o " + out + " -w '%{http_code}' --max-time 10 --aws-sigv4 aws:amz:us-east-1:s3" +
                        " --netrc-file " + dir_ + "/netrc -H 'x-amz-content-sha256: UNSIGNED-PAYLOAD' -X " + method;
  if (!upload_file.empty()) command += " -T " + upload_file;
  command += " 'http://127.0.0.1:" + std::to_string(proxy_port_) + path + "' 2>/dev/null";
  std::string status;
  if (FILE* p = ::popen(command.c_str(), "r")) {
    std::array<char, 64> buf;
    size_t n;
    while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) status.append(buf.data(), n);
    ::pclose(p);
  }
  if (body != nullptr) *body = ReadText(out);
  std::error_code ec;
  fs::remove(out, ec);
  return std::atoi(status.c_str());
}

std::vector<std::string> SwiftS3::Keys(const std::string& prefix) const {
  // The query as SigV4 signs it (curl 7.88 signs it as given): the prefix percent-encoded.
  std::string encoded;
  for (const char ch : prefix) {
    const auto c = static_cast<unsigned char>(ch);
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == '~') {
      encoded.push_back(ch);
    } else {
      char hex[4];
      std::snprintf(hex, sizeof hex, "%%%02X", c);
      encoded += hex;
    }
  }
  std::string body;
  std::vector<std::string> keys;
  if (Request("GET", "/" + bucket() + "?list-type=2&prefix=" + encoded, &body, "") != 200) return keys;
  for (size_t at = body.find("<Key>"); at != std::string::npos; at = body.find("<Key>", at + 5)) {
    keys.push_back(body.substr(at + 5, body.find("</Key>", at) - at - 5));
  }
  return keys;
}

std::string SwiftS3::Log() const {
  std::string text;
  for (const char* s : kServers)
    text += std::string("--- swift-") + s + "-server\n" + ReadText(dir_ + "/" + s + ".log");
  return text;
}

}  // namespace idms::test
