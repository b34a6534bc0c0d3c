// idms-server fan-out: one real idms-agent at 1 kHz publishing a session, N viewers on loopback.
// The viewers run in a separate process of this binary (--load), so that with --pin the server
// has one core to itself and the viewers and the agent the other: what is measured is the
// server, not the load. For each N, over a window: server CPU, server memory per viewer, bytes
// and WebSocket messages per viewer per second, mesh frames per viewer per second, latency from
// the agent's sample batch (DeviceSamples.sent_unix_ns, stamped just after its last tick) to a
// viewer's receipt (p50 / p99 over the probe viewers, which decode whole messages; the others
// only walk the tags to count mesh frames), and the deltas the server skipped for slow viewers.
// With --servers K (K > 1), K servers on one NATS bus (a nats-server the bench starts): the agent
// on the first, the viewers spread evenly over all K (or, --viewers-on relays, over the K - 1 that
// relay it); the latency is then also given for the relayed viewers alone: what a second server
// adds. Prints a table; never fails on time.
//   idms-fanout-bench [--viewers 1,10,100,200] [--seconds 10] [--model hex_4x5_home]
//                     [--device scripted:palpate] [--pin] [--csv FILE] [--servers K]
//                     [--viewers-on all|relays]
#include <sched.h>
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
#include <filesystem>
#include <fstream>
#include <functional>
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

// What the viewers saw in the window (one thread: no locks).
struct Tally {
  bool counting = false;
  double slice_max_ms = 0;  // the longest latency a probe saw since the settling loop last looked
  std::vector<double> latency_ms, relayed_latency_ms;  // all probes; those on a relaying server
  uint64_t bytes = 0, probe_bytes = 0, probe_messages = 0;
  int probes = 0;
  std::vector<char> scratch = std::vector<char>(size_t{1} << 16);  // what the counting viewers read into
};

// A viewer. A probe reads WebSocket messages through Beast and decodes them (latency, mesh
// frames); the others only count the bytes the server sent them, reading the socket under the
// WebSocket directly into one shared buffer (what a byte costs the load is then one copy), and
// ping through Beast every few seconds so the server does not drop them as silent.
class Viewer : public std::enable_shared_from_this<Viewer> {
 public:
  Viewer(asio::io_context& io, Tally& tally, bool probe, bool relayed)
      : ws_(io), tally_(tally), probe_(probe), relayed_(relayed) {}
  bool Start(uint16_t port, const std::string& session, const std::string& token) {
    ws_.set_option(websocket::stream_base::decorator(
        [token](websocket::request_type& req) { req.set("Authorization", "Bearer " + token); }));
    beast::error_code ec;
    beast::get_lowest_layer(ws_).connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port), ec);
    if (!ec) ws_.handshake("127.0.0.1", "/ws/session/" + session, ec);
    if (ec) return false;
    probe_ ? Read() : Count();
    return true;
  }
  void Ping() {
    if (!probe_ && open_) ws_.async_ping({}, [self = shared_from_this()](beast::error_code) {});
  }
  uint64_t mesh_frames = 0;
  bool probe() const { return probe_; }

 private:
  void Read() {
    ws_.async_read(buffer_, [self = shared_from_this()](beast::error_code ec, size_t n) {
      if (ec) return;
      const uint64_t now = UnixNs();
      const auto data = self->buffer_.data();
      Tally& t = self->tally_;
      std::vector<idms::v1::Envelope> frames;
      std::string error;
      if (idms::ParseFrames(std::string_view(static_cast<const char*>(data.data()), data.size()), &frames, &error)) {
        if (t.counting) t.probe_bytes += n, ++t.probe_messages;
        for (const auto& e : frames) {
          if (t.counting && (e.has_mesh_keyframe() || e.has_mesh_delta())) ++self->mesh_frames;
          if (e.has_device_samples() && e.device_samples().sent_unix_ns() > 0) {
            const double ms =
                (static_cast<double>(now) - static_cast<double>(e.device_samples().sent_unix_ns())) * 1e-6;
            t.slice_max_ms = std::max(t.slice_max_ms, ms);
            if (!t.counting) continue;
            t.latency_ms.push_back(ms);
            if (self->relayed_) t.relayed_latency_ms.push_back(ms);
          }
        }
      }
      self->buffer_.consume(self->buffer_.size());
      self->Read();
    });
  }
  void Count() {
    beast::get_lowest_layer(ws_).socket().async_read_some(asio::buffer(tally_.scratch),
                                                          [self = shared_from_this()](beast::error_code ec, size_t n) {
                                                            if (ec) return void(self->open_ = false);
                                                            if (self->tally_.counting) self->tally_.bytes += n;
                                                            self->Count();
                                                          });
  }
  websocket::stream<beast::tcp_stream> ws_;
  beast::flat_buffer buffer_;
  Tally& tally_;
  bool probe_, relayed_;
  bool open_ = true;
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

// utime + stime of this process, s.
double SelfCpuSeconds() { return CpuSeconds(static_cast<int>(getpid())); }

// The viewers, in this process (--load): one line "counting" once they are connected and settled,
// then one JSON line with what they saw in the window.
// `ports`: the servers the viewers are spread over, the session's owner first when it is one of them.
int RunLoad(const std::vector<uint16_t>& ports, uint16_t owner, const std::string& session, const std::string& token,
            int n, double seconds, int cpu) {
  if (cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cpu, &set);
    sched_setaffinity(0, sizeof set, &set);
  }
  asio::io_context io;
  Tally tally;
  std::vector<std::shared_ptr<Viewer>> viewers;
  // Up to 32 probe viewers (and at least one) decode whole messages for the latency; the rest only count.
  const int probe_every = std::max(1, n / 32);
  int connected = 0;
  for (int i = 0; i < n; ++i) {
    // Round-robin over the servers; the probes too (every probe_every-th round), so that each
    // server has its share of them.
    const size_t round = static_cast<size_t>(i) / ports.size();
    const uint16_t port = ports[static_cast<size_t>(i) % ports.size()];
    viewers.push_back(
        std::make_shared<Viewer>(io, tally, round % static_cast<size_t>(probe_every) == 0, port != owner));
    connected += viewers.back()->Start(port, session, token) ? 1 : 0;
  }
  // Pings every 5 s (the server drops a viewer silent for 15 s).
  asio::steady_timer ping(io);
  std::function<void()> keepalive = [&] {
    for (const auto& v : viewers) v->Ping();
    ping.expires_after(std::chrono::seconds(5));
    ping.async_wait([&](beast::error_code ec) {
      if (!ec) keepalive();
    });
  };
  keepalive();
  // Settle: every viewer past its keyframe, and what piled up while the others connected (they
  // connect one after another, nothing read meanwhile) drained: 2 s, then half seconds until no
  // probe saw a frame older than 100 ms in one (at most 60 s).
  const auto settle0 = Clock::now();
  io.run_for(std::chrono::seconds(2));
  for (int i = 0; i < 116; ++i) {
    tally.slice_max_ms = 0;
    io.run_for(std::chrono::milliseconds(500));
    if (tally.slice_max_ms < 100) break;
  }
  const double settle_s = std::chrono::duration<double>(Clock::now() - settle0).count();
  std::printf("counting\n");
  std::fflush(stdout);
  const double cpu0 = SelfCpuSeconds();
  const auto t0 = Clock::now();
  tally.counting = true;
  io.run_for(std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds)));
  tally.counting = false;
  const double wall = std::chrono::duration<double>(Clock::now() - t0).count();
  std::vector<double> fps;
  int probes = 0;
  for (const auto& v : viewers) {
    if (v->probe()) fps.push_back(static_cast<double>(v->mesh_frames) / wall), ++probes;
  }
  const int counters = n - probes;
  const nlohmann::json out = {
      {"connected", connected},
      {"wall_s", wall},
      {"probes", probes},
      // kB/s per counting viewer (all bytes, WebSocket framing included), and per probe
      {"kbytes_per_s", counters > 0 ? static_cast<double>(tally.bytes) / 1e3 / wall / counters : 0},
      {"probe_kbytes_per_s", static_cast<double>(tally.probe_bytes) / 1e3 / wall / probes},
      {"probe_messages_per_s", static_cast<double>(tally.probe_messages) / wall / probes},
      {"mesh_fps_median", Percentile(fps, 0.5)},
      {"mesh_fps_min", Percentile(fps, 0)},
      {"latency_p50_ms", Percentile(tally.latency_ms, 0.5)},
      {"latency_p99_ms", Percentile(tally.latency_ms, 0.99)},
      {"latency_p999_ms", Percentile(tally.latency_ms, 0.999)},
      {"settle_s", settle_s},
      {"relayed_p50_ms", Percentile(tally.relayed_latency_ms, 0.5)},
      {"relayed_p99_ms", Percentile(tally.relayed_latency_ms, 0.99)},
      {"load_cpu_percent", (SelfCpuSeconds() - cpu0) / wall * 100}};
  std::printf("%s\n", out.dump().c_str());
  std::fflush(stdout);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string viewers_list = "1,10,100,200", model = "hex_4x5_home", device = "scripted:palpate", csv;
  double seconds = 10;
  bool pin = false;
  int servers_n = 1;
  std::string viewers_on = "all";
  std::string load_ports;
  uint16_t load_owner = 0;
  std::string load_session, load_token;
  int load_viewers = 0, load_cpu = -1;
  CLI::App app{"idms-server fan-out: one agent at 1 kHz, N viewers on loopback in a separate process"};
  app.add_option("--viewers", viewers_list, "Comma-separated viewer counts")->capture_default_str();
  app.add_option("--seconds", seconds, "Measurement window per count")->capture_default_str();
  app.add_option("--model", model, "Library model the agent runs")->capture_default_str();
  app.add_option("--device", device, "The agent's device (scripted:palpate, scripted:stroke-fast, ...)")
      ->capture_default_str();
  app.add_flag("--pin", pin, "The server on CPU 0 with one I/O thread; the agent and the viewers on CPU 1");
  app.add_option("--csv", csv, "Also write the table as CSV");
  app.add_option("--servers", servers_n, "Servers on one NATS bus (the agent on the first)")
      ->check(CLI::Range(1, 8))
      ->capture_default_str();
  app.add_option("--viewers-on", viewers_on, "With --servers > 1: the viewers on all servers, or on the relays alone")
      ->check(CLI::IsMember({"all", "relays"}))
      ->capture_default_str();
  // The viewers' process (started by the bench itself).
  app.add_option("--load-ports", load_ports)->group("");
  app.add_option("--load-owner", load_owner)->group("");
  app.add_option("--load-session", load_session)->group("");
  app.add_option("--load-token", load_token)->group("");
  app.add_option("--load-viewers", load_viewers)->group("");
  app.add_option("--load-cpu", load_cpu)->group("");
  CLI11_PARSE(app, argc, argv);
  if (!load_ports.empty()) {
    std::vector<uint16_t> ports;
    for (std::stringstream ss(load_ports); ss.good();) {
      std::string item;
      std::getline(ss, item, ',');
      if (!item.empty()) ports.push_back(static_cast<uint16_t>(std::stoi(item)));
    }
    return RunLoad(ports, load_owner, load_session, load_token, load_viewers, seconds, load_cpu);
  }
  std::vector<int> counts;
  for (std::stringstream ss(viewers_list); ss.good();) {
    std::string item;
    std::getline(ss, item, ',');
    if (!item.empty()) counts.push_back(std::stoi(item));
  }
  std::printf(
      "idms-server fan-out: one agent (%s, %s at 1 kHz, 60 Hz mesh), %.0f s per row, viewers in their own process, "
      "%s\n",
      model.c_str(), device.c_str(), seconds,
      pin ? "servers pinned to CPU 0 (1 I/O thread each), agent and viewers to CPU 1" : "nothing pinned");
  if (servers_n > 1) {
    std::printf("%d servers on one NATS bus, the agent on the first, viewers on %s; server %% is all of them\n",
                servers_n, viewers_on == "all" ? "all of them" : "the relays alone");
  }
  std::printf("%8s %9s %10s %11s %10s %9s %9s %9s %10s %9s %8s %8s %8s %9s %9s %8s\n", "viewers", "server %",
              "MB/viewer", "kB/s/viewer", "msg/s/vwr", "mesh fps", "p50 ms", "p99 ms", "p99.9 ms", "skipped", "resyncs",
              "load %", "agent %", "relay p50", "relay p99", "settle s");
  std::ofstream out;
  if (!csv.empty()) {
    out.open(csv);
    out << "viewers,server_cpu_percent,server_mb_per_viewer,kbytes_per_viewer_per_s,messages_per_viewer_per_s,"
           "mesh_fps_median,latency_p50_ms,latency_p99_ms,deltas_skipped,resyncs,load_cpu_percent,agent_cpu_percent\n";
  }
  const std::string self = std::filesystem::read_symlink("/proc/self/exe").string();
  for (int n : counts) {
    const std::string dir = idms::test::TempDir("fanout-" + std::to_string(n));
    // With several servers, the bus first.
    std::unique_ptr<idms::test::ChildProcess> nats;
    std::string bus;
    if (servers_n > 1) {
      nats = std::make_unique<idms::test::ChildProcess>(
          "/usr/sbin/nats-server", std::vector<std::string>{"-a", "127.0.0.1", "-p", "-1"}, dir + "/nats.log");
      const std::string marker = "Listening for client connections on 127.0.0.1:";
      for (int i = 0; i < 1000 && bus.empty(); ++i) {
        const std::string log = idms::test::ReadText(dir + "/nats.log");
        if (const size_t at = log.find(marker); at != std::string::npos) {
          bus = "nats://127.0.0.1:" + std::to_string(std::stoi(log.substr(at + marker.size())));
        } else {
          std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
      }
      if (bus.empty()) return std::fprintf(stderr, "nats-server did not start\n"), 1;
    }
    std::string server_bin = IDMS_SERVER_BIN, agent_bin = IDMS_AGENT_BIN;
    std::vector<std::string> agent_prefix;
    if (pin) {
      agent_prefix = {"-c", "1", agent_bin};
      agent_bin = "/usr/bin/taskset";
    }
    std::vector<std::unique_ptr<idms::test::ChildProcess>> servers;
    std::vector<uint16_t> ports;
    for (int k = 0; k < servers_n; ++k) {
      std::vector<std::string> args = {"--listen",
                                       "127.0.0.1:0",
                                       "--data",
                                       dir + "/data" + std::to_string(k),
                                       "--max-connections",
                                       std::to_string(n + 64),
                                       "--max-connections-per-address",
                                       std::to_string(n + 64)};
      if (servers_n > 1) {
        args.insert(args.end(), {"--bus", bus, "--node", "s" + std::to_string(k)});
        if (k > 0) args.insert(args.end(), {"--tokens", dir + "/data0/tokens"});
      }
      std::string bin = server_bin;
      if (pin) {
        args.insert(args.begin(), {"-c", "0", bin});
        args.insert(args.end(), {"--threads", "1", "--workers", "1"});
        bin = "/usr/bin/taskset";
      }
      servers.push_back(
          std::make_unique<idms::test::ChildProcess>(bin, args, dir + "/server" + std::to_string(k) + ".log", true));
      const auto line = servers.back()->ReadLine(std::chrono::seconds(60));
      if (!line) return std::fprintf(stderr, "server did not start: %s\n", servers.back()->Log().c_str()), 1;
      ports.push_back(static_cast<uint16_t>(std::stoi(line->substr(line->rfind(':') + 1))));
    }
    idms::test::ChildProcess& server = *servers[0];
    const uint16_t port = ports[0];
    std::string agent_token, observer_token;
    {
      std::istringstream t(idms::test::ReadText(dir + "/data0/tokens"));
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
    std::vector<std::string> agent_args = agent_prefix;
    agent_args.insert(agent_args.end(),
                      {"--server", "ws://127.0.0.1:" + std::to_string(port), "--token", agent_token, "--model", model,
                       "--device", device, "--duration", "0", "--cache-dir", dir + "/cache"});
    idms::test::ChildProcess agent(agent_bin, agent_args, dir + "/agent.log");
    // The session, live.
    std::string session;
    for (int i = 0; i < 500 && session.empty(); ++i) {
      const auto j = nlohmann::json::parse(HttpGet(port, "/api/sessions", observer_token));
      if (!j["sessions"].empty()) session = j["sessions"][0]["id"];
      if (session.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    if (session.empty()) return std::fprintf(stderr, "no session\n"), 1;
    const double rss0 = RssBytes(server.pid());
    // The servers the viewers go to.
    std::string load_list;
    for (size_t k = servers_n > 1 && viewers_on == "relays" ? 1 : 0; k < ports.size(); ++k) {
      load_list += (load_list.empty() ? "" : ",") + std::to_string(ports[k]);
    }
    const auto all_cpu = [&] {
      double sum = 0;
      for (const auto& s : servers) sum += CpuSeconds(s->pid());
      return sum;
    };
    idms::test::ChildProcess load(self,
                                  {"--load-ports", load_list, "--load-owner", std::to_string(port), "--load-session",
                                   session, "--load-token", observer_token, "--load-viewers", std::to_string(n),
                                   "--load-cpu", pin ? "1" : "-1", "--seconds", std::to_string(seconds)},
                                  dir + "/load.log", true);
    const auto counting = load.ReadLine(std::chrono::seconds(120));
    if (!counting) return std::fprintf(stderr, "the viewers did not start: %s\n", load.Log().c_str()), 1;
    // A counter summed over the servers.
    const auto total = [&](const std::string& name) {
      double sum = 0;
      for (const uint16_t p : ports) sum += MetricValue(HttpGet(p, "/metrics", observer_token), name);
      return sum;
    };
    const double skipped0 = total("idms_viewer_deltas_skipped_total"), resyncs0 = total("idms_viewer_resyncs_total");
    const double cpu0 = all_cpu(), agent_cpu0 = CpuSeconds(agent.pid());
    const auto t0 = Clock::now();
    const auto result = load.ReadLine(std::chrono::seconds(static_cast<int>(seconds) + 120));
    const double wall = std::chrono::duration<double>(Clock::now() - t0).count();
    const double cpu = (all_cpu() - cpu0) / wall * 100;
    const double agent_cpu = (CpuSeconds(agent.pid()) - agent_cpu0) / wall * 100;
    const double rss1 = RssBytes(server.pid());
    if (!result) return std::fprintf(stderr, "the viewers did not report: %s\n", load.Log().c_str()), 1;
    const auto r = nlohmann::json::parse(*result);
    const double skipped = total("idms_viewer_deltas_skipped_total") - skipped0;
    const double resyncs = total("idms_viewer_resyncs_total") - resyncs0;
    const double mb_per_viewer = (rss1 - rss0) / 1e6 / n;
    const double kbps =
        r["probes"].get<int>() == n ? r["probe_kbytes_per_s"].get<double>() : r["kbytes_per_s"].get<double>();
    const double mps = r["probe_messages_per_s"].get<double>();
    if (r["connected"].get<int>() != n)
      std::printf("(only %d of %d viewers connected)\n", r["connected"].get<int>(), n);
    std::printf("%8d %9.1f %10.3f %11.1f %10.1f %9.1f %9.2f %9.2f %10.2f %9.0f %8.0f %8.1f %8.1f %9.2f %9.2f %8.1f\n",
                n, cpu, mb_per_viewer, kbps, mps, r["mesh_fps_median"].get<double>(), r["latency_p50_ms"].get<double>(),
                r["latency_p99_ms"].get<double>(), r["latency_p999_ms"].get<double>(), skipped, resyncs,
                r["load_cpu_percent"].get<double>(), agent_cpu, r["relayed_p50_ms"].get<double>(),
                r["relayed_p99_ms"].get<double>(), r["settle_s"].get<double>());
    std::fflush(stdout);
    if (out) {
      out << n << "," << cpu << "," << mb_per_viewer << "," << kbps << "," << mps << ","
          << r["mesh_fps_median"].get<double>() << "," << r["latency_p50_ms"].get<double>() << ","
          << r["latency_p99_ms"].get<double>() << "," << skipped << "," << resyncs << ","
          << r["load_cpu_percent"].get<double>() << "," << agent_cpu << "\n";
    }
    load.Wait(std::chrono::seconds(30));
    agent.Signal(SIGTERM);
    agent.Wait(std::chrono::seconds(30));
    for (const auto& s : servers) s->Signal(SIGTERM);
    for (const auto& s : servers) s->Wait(std::chrono::seconds(30));
  }
  return 0;
}
