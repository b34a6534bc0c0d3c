// PgCluster: initdb, pg_ctl and psql run as shell commands, as the postgres user under root.
#include "pg_cluster.h"

#include <netinet/in.h>
#include <pwd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

namespace idms::test {
namespace {

namespace fs = std::filesystem;

// A port the kernel has just given out and taken back: free, barring a race with another process.
int FreePort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  int port = 0;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0)
    port = ntohs(a.sin_port);
  ::close(fd);
  return port;
}

std::string Capture(const std::string& command) {
  std::string out;
  if (FILE* p = ::popen(command.c_str(), "r")) {
    std::array<char, 4096> buf;
    size_t n;
    while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) out.append(buf.data(), n);
    ::pclose(p);
  }
  while (!out.empty() && (out.back() == '\n' || out.back() == ' ')) out.pop_back();
  return out;
}

}  // namespace

std::optional<std::string> PgCluster::BinDir() {
  std::vector<fs::path> candidates;
  if (const char* env = std::getenv("IDMS_PG_BINDIR"); env != nullptr && *env != '\0') candidates.emplace_back(env);
  if (const std::string b = Capture("pg_config --bindir 2>/dev/null"); !b.empty()) candidates.emplace_back(b);
  std::error_code ec;
  std::vector<fs::path> versions;
  for (const auto& e : fs::directory_iterator("/usr/lib/postgresql", ec)) versions.push_back(e.path() / "bin");
  std::sort(versions.rbegin(), versions.rend());
  candidates.insert(candidates.end(), versions.begin(), versions.end());
  for (const fs::path& c : candidates) {
    if (fs::exists(c / "initdb", ec) && fs::exists(c / "pg_ctl", ec) && fs::exists(c / "postgres", ec))
      return c.string();
  }
  return std::nullopt;
}

PgCluster::PgCluster() {
  const std::optional<std::string> bin = BinDir();
  if (!bin) {
    error_ = "PostgreSQL is not installed (no initdb, pg_ctl and postgres found)";
    return;
  }
  bin_ = *bin;
  // Under /tmp (short: the socket's path has a limit of 107 bytes), owned by postgres under root.
  char tmpl[] = "/tmp/idms-pg-XXXXXX";
  if (::mkdtemp(tmpl) == nullptr) {
    error_ = "mkdtemp failed";
    return;
  }
  dir_ = tmpl;
  if (::geteuid() == 0) {
    const passwd* pw = ::getpwnam("postgres");
    if (pw == nullptr || ::chown(dir_.c_str(), pw->pw_uid, pw->pw_gid) != 0) {
      error_ = "running as root, and there is no postgres user to run PostgreSQL as (initdb refuses root)";
      return;
    }
    as_user_ = "runuser -u postgres -- ";
  }
  port_ = FreePort();
  if (!Run(bin_ + "/initdb -D " + dir_ + "/data -A trust -U postgres --no-sync -E UTF8 --locale=C >" + dir_ +
           "/initdb.log 2>&1"))
    return;
  Start();
}

PgCluster::~PgCluster() {
  if (dir_.empty()) return;
  if (fs::exists(dir_ + "/data/postmaster.pid"))
    std::system((as_user_ + bin_ + "/pg_ctl -D " + dir_ + "/data -m immediate -w stop >/dev/null 2>&1").c_str());
  std::error_code ec;
  fs::remove_all(dir_, ec);
}

bool PgCluster::Run(const std::string& command, std::string* output) {
  const std::string out_file = dir_ + "/command.out";
  // From the cluster's own directory: the postgres user may not enter the caller's (a clone
  // under a mode-0700 directory), and psql says so on stderr, into the output read back.
  const int rc = std::system((as_user_ + "sh -c 'cd " + dir_ + " && " + command + "' >" + out_file + " 2>&1").c_str());
  std::ifstream in(out_file);
  std::stringstream ss;
  ss << in.rdbuf();
  if (output != nullptr) *output = ss.str();
  if (rc != 0) {
    error_ = "'" + command + "' failed (status " + std::to_string(rc) + "): " + ss.str() + Log();
    return false;
  }
  error_.clear();
  return true;
}

bool PgCluster::Start() {
  // fsync off: nothing here must survive a power cut, and the tests run faster.
  return Run(bin_ + "/pg_ctl -D " + dir_ + "/data -l " + dir_ +
             "/server.log -w -t 60 -o \"-c listen_addresses=127.0.0.1 -p " + std::to_string(port_) + " -k " + dir_ +
             " -c fsync=off -c synchronous_commit=off -c full_page_writes=off\" start");
}

bool PgCluster::Stop() { return Run(bin_ + "/pg_ctl -D " + dir_ + "/data -m fast -w -t 60 stop"); }

std::string PgCluster::Url(const std::string& db) const {
  return "postgres://postgres@127.0.0.1:" + std::to_string(port_) + "/" + db;
}

std::string PgCluster::CreateDatabase(const std::string& name) {
  if (!Psql("postgres", "CREATE DATABASE " + name)) return {};
  return Url(name);
}

std::optional<std::string> PgCluster::Psql(const std::string& db, const std::string& sql) {
  // The SQL through a file: no quoting of quotes in shell.
  const std::string file = dir_ + "/query.sql";
  std::error_code ec;
  fs::remove(file, ec);
  std::ofstream(file) << sql << ";\n";
  // Readable by the postgres user when the test runs as root.
  fs::permissions(file,
                  fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read | fs::perms::others_read);
  std::string out;
  if (!Run(bin_ + "/psql -X -q -At -v ON_ERROR_STOP=1 -h 127.0.0.1 -p " + std::to_string(port_) + " -U postgres -d " +
               db + " -f " + file,
           &out))
    return std::nullopt;
  while (!out.empty() && out.back() == '\n') out.pop_back();
  return out;
}

std::string PgCluster::Log() const {
  std::ifstream in(dir_ + "/server.log");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace idms::test
