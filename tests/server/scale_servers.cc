// The real servers the several-servers tests start on loopback (scale_servers.h).
#include "scale_servers.h"

#include <signal.h>

#include <boost/asio/ip/tcp.hpp>
#include <fstream>
#include <regex>

namespace idms::test {

using std::chrono::seconds;

NatsServer::NatsServer(const std::string& dir, int port, const std::vector<std::string>& extra) {
  static int n = 0;
  log_ = dir + "/nats-" + std::to_string(++n) + ".log";
  std::vector<std::string> args = {"-a", "127.0.0.1", "-p", std::to_string(port)};
  args.insert(args.end(), extra.begin(), extra.end());
  process_ = std::make_unique<ChildProcess>("/usr/sbin/nats-server", args, log_);
  const std::regex listening("Listening for client connections on 127\\.0\\.0\\.1:([0-9]+)");
  Eventually(
      [&] {
        std::smatch m;
        const std::string text = ReadText(log_);
        if (!std::regex_search(text, m, listening)) return false;
        port_ = std::stoi(m[1]);
        return true;
      },
      seconds(20));
}

void NatsServer::Kill() { process_->Signal(SIGKILL), process_->Wait(seconds(10)); }
std::string NatsServer::Log() const { return ReadText(log_); }

bool HaveNats() { return std::ifstream("/usr/sbin/nats-server").good(); }
bool HaveHaproxy() { return std::ifstream("/usr/sbin/haproxy").good(); }

uint16_t FreePort() {
  boost::asio::io_context io;
  boost::asio::ip::tcp::acceptor a(io, {boost::asio::ip::make_address("127.0.0.1"), 0});
  return a.local_endpoint().port();
}

std::string CreateToken(const std::string& file, const std::string& role) {
  ChildProcess p(IDMS_SERVER_BIN, {"token", "create", role, "--tokens", file}, file + "." + role + ".log", true);
  const auto line = p.ReadLine(seconds(20));
  p.Wait(seconds(20));
  return line.value_or("");
}

Haproxy::Haproxy(const std::string& dir, const std::vector<uint16_t>& agents, const std::vector<uint16_t>& viewers)
    : port_(FreePort()) {
  // The configuration the scale stack's container runs (docker/haproxy-config.sh).
  const auto list = [](const std::vector<uint16_t>& ports) {
    std::string s;
    for (const uint16_t p : ports) s += (s.empty() ? "127.0.0.1:" : " 127.0.0.1:") + std::to_string(p);
    return s;
  };
  ChildProcess config("/bin/sh",
                      {IDMS_SOURCE_DIR "/docker/haproxy-config.sh", std::to_string(port_), list(agents), list(viewers)},
                      dir + "/haproxy.cfg");
  config.Wait(seconds(20));
  process_ = std::make_unique<ChildProcess>(
      "/usr/sbin/haproxy", std::vector<std::string>{"-db", "-f", dir + "/haproxy.cfg"}, dir + "/haproxy.log");
  // Ready once it accepts.
  Eventually(
      [&] {
        boost::asio::io_context io;
        boost::asio::ip::tcp::socket socket(io);
        boost::system::error_code ec;
        socket.connect({boost::asio::ip::make_address("127.0.0.1"), port_}, ec);
        return !ec;
      },
      seconds(20));
}

std::vector<uint64_t> Ticks(TestViewer& v) {
  std::vector<uint64_t> ticks;
  for (const v1::Envelope& e : v.Frames()) {
    if (!e.has_device_samples()) continue;
    for (const auto& s : e.device_samples().samples()) ticks.push_back(s.tick());
  }
  return ticks;
}

}  // namespace idms::test
