// idms-server fan-out: one real idms-agent at 1 kHz publishing a session, N viewers on loopback
// (1, 10, 100, 200 by default, all in this process on one thread). For each N, over a window:
// server CPU, server memory per viewer, bytes per viewer per second, delivered mesh frames per
// viewer per second, latency from the agent's sample batch (DeviceSamples.sent_unix_ns, stamped
// just after its last tick) to a viewer's receipt (p50 / p99 over all viewers), and the deltas
// the server skipped for slow viewers. Prints a table; never fails on time.
//   idms-fanout-bench [--viewers 1,10,100,200] [--seconds 10] [--model hex_4x5_home] [--csv FILE]
#include <signal.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "child_process.h"
#include "idms/protocol/envelope.h"

namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using Clock = std::chrono::steady_clock;

uint64_t UnixNs() {
  return static_cast<uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
}

// What all viewers saw in the window (one thread: no locks).
struct Tally {
  bool counting = false;
  std::vector<double> latency_ms;
  uint64_t bytes = 0;
};

class Viewer : public std::enable_shared_from_this<Viewer> {
 public:
  Viewer(asio::io_context& io, Tally& tally) : ws_(io), tally_(tally) {}
  void Start(uint16_t port, const std::string& session, const std::string& token) {
    ws_.set_option(websocket::stream_base::decorator(
        [token](websocket::request_type& req) { req.set("Authorization", "Bearer " + token); }));
    beast::get_lowest_layer(ws_).connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
    ws_.handshake("127.0.0.1", "/ws/session/" + session);
    Read();
  }
  uint64_t mesh_frames = 0;

 private:
  void Read() {
    ws_.async_read(buffer_, [self = shared_from_this()](beast::error_code ec, size_t n) {
      if (ec) return;
      const uint64_t now = UnixNs();
      const auto data = self->buffer_.data();
      idms::v1::Envelope e;
      std::string error;
      if (self->tally_.counting &&
          idms::ParseEnvelope(std::string_view(static_cast<const char*>(data.data()), data.size()), &e, &error)) {
        self->tally_.bytes += n;
        if (e.has_mesh_delta() || e.has_mesh_keyframe()) ++self->mesh_frames;
        if (e.has_device_samples() && e.device_samples().sent_unix_ns() > 0) {
          self->tally_.latency_ms.push_back(
              (static_cast<double>(now) - static_cast<double>(e.device_samples().sent_unix_ns())) * 1e-6);
        }
      }
      self->buffer_.consume(self->buffer_.size());
      self->Read();
    });
  }
  websocket::stream<beast::tcp_stream> ws_;
  beast::flat_buffer buffer_;
  Tally& tally_;
};

std::string HttpGet(uint16_t port, const std::string& target, const std::string& token) {
  asio::io_context io;
  beast::tcp_stream s(io);
  s.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
  http::request<http::empty_body> req{http::verb::get, target, 11};
  req.set(http::field::host, "127.0.0.1");
  req.set(http::field::authorization, "Bearer " + token);
  http::write(s, req);
  beast::flat_buffer b;
  http::response<http::string_body> res;
  http::read(s, b, res);
  return res.body();
}

// utime + stime (s) and VmRSS (bytes) of a process.
double CpuSeconds(int pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string text((std::istreambuf_iterator<char>(in)), {});
  std::istringstream f(text.substr(text.rfind(')') + 2));
  std::string field;
  double ticks = 0;
  for (int i = 3; i <= 15 && f >> field; ++i) {
    if (i == 14 || i == 15) ticks += std::stod(field);
  }
  return ticks / static_cast<double>(sysconf(_SC_CLK_TCK));
}
double RssBytes(int pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) * 1024;
  }
  return 0;
}
double MetricValue(const std::string& text, const std::string& name) {
  const size_t at = text.find("\n" + name + " ");
  return at == std::string::npos ? 0 : std::stod(text.substr(at + name.size() + 2));
}
double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size())))];
}

}  // namespace

int main(int argc, char** argv) {
  std::string viewers_list = "1,10,100,200", model = "hex_4x5_home", csv;
  double seconds = 10;
  CLI::App app{"idms-server fan-out: one agent at 1 kHz, N viewers on loopback"};
  app.add_option("--viewers", viewers_list, "Comma-separated viewer counts")->capture_default_str();
  app.add_option("--seconds", seconds, "Measurement window per count")->capture_default_str();
  app.add_option("--model", model, "Library model the agent runs")->capture_default_str();
  app.add_option("--csv", csv, "Also write the table as CSV");
  CLI11_PARSE(app, argc, argv);
  std::vector<int> counts;
  for (std::stringstream ss(viewers_list); ss.good();) {
    std::string item;
    std::getline(ss, item, ',');
    if (!item.empty()) counts.push_back(std::stoi(item));
  }
  std::printf(
      "idms-server fan-out: one agent (%s, scripted palpation at 1 kHz, 60 Hz mesh), %.0f s per row, "
      "%u cores shared by server, agent and viewers\n",
      model.c_str(), seconds, std::thread::hardware_concurrency());
  std::printf("%8s %10s %12s %14s %12s %10s %10s %10s %8s\n", "viewers", "server %", "MB/viewer", "kB/s/viewer",
              "mesh fps", "p50 ms", "p99 ms", "skipped", "resyncs");
  std::ofstream out;
  if (!csv.empty()) {
    out.open(csv);
    out << "viewers,server_cpu_percent,server_mb_per_viewer,kbytes_per_viewer_per_s,mesh_fps_median,latency_p50_ms,"
           "latency_p99_ms,deltas_skipped,resyncs\n";
  }
  for (int n : counts) {
    const std::string dir = idms::test::TempDir("fanout-" + std::to_string(n));
    idms::test::ChildProcess server(IDMS_SERVER_BIN, {"--listen", "127.0.0.1:0", "--data", dir + "/data"},
                                    dir + "/server.log", true);
    const auto line = server.ReadLine(std::chrono::seconds(60));
    if (!line) return std::fprintf(stderr, "server did not start: %s\n", server.Log().c_str()), 1;
    const uint16_t port = static_cast<uint16_t>(std::stoi(line->substr(line->rfind(':') + 1)));
    std::string agent_token, observer_token;
    {
      std::istringstream t(idms::test::ReadText(dir + "/data/tokens"));
      std::string role, token;
      while (t >> role) {
        if (role[0] == '#') {
          std::getline(t, token);
          continue;
        }
        t >> token;
        if (role == "agent") agent_token = token;
        if (role == "observer") observer_token = token;
      }
    }
    idms::test::ChildProcess agent(
        IDMS_AGENT_BIN,
        {"--server", "ws://127.0.0.1:" + std::to_string(port), "--token", agent_token, "--model", model, "--device",
         "scripted:palpate", "--duration", "0", "--cache-dir", dir + "/cache"},
        dir + "/agent.log");
    // The session, live.
    std::string session;
    for (int i = 0; i < 500 && session.empty(); ++i) {
      const auto j = nlohmann::json::parse(HttpGet(port, "/api/sessions", observer_token));
      if (!j["sessions"].empty()) session = j["sessions"][0]["id"];
      if (session.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    if (session.empty()) return std::fprintf(stderr, "no session\n"), 1;
    const double rss0 = RssBytes(server.pid());
    asio::io_context io;
    Tally tally;
    std::vector<std::shared_ptr<Viewer>> viewers;
    for (int i = 0; i < n; ++i) {
      viewers.push_back(std::make_shared<Viewer>(io, tally));
      viewers.back()->Start(port, session, observer_token);
    }
    // One second to settle, then the window.
    io.run_for(std::chrono::seconds(1));
    const std::string m0 = HttpGet(port, "/metrics", observer_token);
    const double cpu0 = CpuSeconds(server.pid());
    const auto t0 = Clock::now();
    tally.counting = true;
    io.run_for(std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds)));
    tally.counting = false;
    const double wall = std::chrono::duration<double>(Clock::now() - t0).count();
    const double cpu = (CpuSeconds(server.pid()) - cpu0) / wall * 100;
    const double rss1 = RssBytes(server.pid());
    const std::string m1 = HttpGet(port, "/metrics", observer_token);
    std::vector<double> fps;
    for (const auto& v : viewers) fps.push_back(static_cast<double>(v->mesh_frames) / wall);
    const double skipped =
        MetricValue(m1, "idms_viewer_deltas_skipped_total") - MetricValue(m0, "idms_viewer_deltas_skipped_total");
    const double resyncs = MetricValue(m1, "idms_viewer_resyncs_total") - MetricValue(m0, "idms_viewer_resyncs_total");
    const double p50 = Percentile(tally.latency_ms, 0.5), p99 = Percentile(tally.latency_ms, 0.99);
    const double mb_per_viewer = (rss1 - rss0) / 1e6 / n;
    const double kbps = static_cast<double>(tally.bytes) / 1e3 / wall / n;
    std::printf("%8d %10.1f %12.3f %14.1f %12.1f %10.2f %10.2f %10.0f %8.0f\n", n, cpu, mb_per_viewer, kbps,
                Percentile(fps, 0.5), p50, p99, skipped, resyncs);
    std::fflush(stdout);
    if (out) {
      out << n << "," << cpu << "," << mb_per_viewer << "," << kbps << "," << Percentile(fps, 0.5) << "," << p50 << ","
          << p99 << "," << skipped << "," << resyncs << "\n";
    }
    viewers.clear();
    agent.Signal(SIGTERM);
    agent.Wait(std::chrono::seconds(30));
    server.Signal(SIGTERM);
    server.Wait(std::chrono::seconds(30));
  }
  return 0;
}
