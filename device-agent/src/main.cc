// idms-agent: runs the 1 kHz DSM loop next to a haptic device and reports the session to an
// idms-server. Threads: the loop (loop.h) and this one, which runs the uplink (uplink.h).
#include <pthread.h>
#include <sched.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "idms/agent/device.h"
#include "idms/agent/loop.h"
#include "idms/agent/model_source.h"
#include "idms/agent/setup.h"
#include "idms/agent/uplink.h"
#include "idms/protocol/cli.h"
#include "idms/protocol/scene.h"
#include "idms/sim/model_io.h"
#include "idms/sim/preset.h"
#include "text_internal.h"

namespace idms::agent {
namespace {

constexpr int kExitConfig = 1;   // bad arguments, scene, model or device
constexpr int kExitRefused = 2;  // the server refused the token or the session

struct Args {
  std::string server, token, token_file, trainee, model, model_file, device, scene_file, preset, summary_json,
      dump_final, cache_dir;
  std::string rotation, offset, friction, passivity;
  double global_rate = -1;  // --global-rate; -1 = the scene's
  double duration_s = 0, rate_hz = 0, scale = 0, max_force = 0, flush_timeout_s = 5, idle_timeout_s = 2;
  int64_t backlog = 120000;
  int cpu = -1;
  int64_t spin_us = 0;
  bool no_realtime = false;
};

// What the main thread measured around the loop: hypervisor steal and where the I/O thread ran.
struct Platform {
  int64_t steal_ms = -1;           // all CPUs summed, over the run; -1 when /proc/stat was unreadable
  int64_t steal_ms_loop_cpu = -1;  // the pinned CPU's alone; -1 when not pinned or unreadable
  std::vector<int> io_cpus;        // the I/O thread's CPUs when it was moved off the loop's; else empty
};

int Fail(const std::string& message) {
  std::fprintf(stderr, "idms-agent: error: %s\n", message.c_str());
  return kExitConfig;
}

// "ws://HOST:PORT[/PATH]" or "http://HOST:PORT" -> host, port, target (default /ws/agent).
bool ParseServer(const std::string& url, UplinkOptions* o, std::string* error) {
  ServerUrl u;
  if (!ParseServerUrl(url, "--server", &u, error)) return false;
  o->host = u.host;
  o->port = u.port;
  if (!u.path.empty()) o->target = u.path;
  return true;
}

// "0-3,6": a CPU list the way the kernel writes one.
std::string CpuList(const std::vector<int>& cpus) {
  std::string out;
  for (size_t i = 0; i < cpus.size();) {
    size_t j = i;
    while (j + 1 < cpus.size() && cpus[j + 1] == cpus[j] + 1) ++j;
    if (!out.empty()) out += ",";
    out += std::to_string(cpus[i]);
    if (j > i) out += "-" + std::to_string(cpus[j]);
    i = j + 1;
  }
  return out;
}

void PrintSummary(const LatencySummary& period, const LatencySummary& wake, const LatencySummary& compute,
                  const Loop& loop, const Platform& platform, const UplinkStats& up, bool offline) {
  const LoopOptions& o = loop.options();
  const RealtimeReport rt = loop.realtime_report();
  std::string cpu = "not pinned";
  if (o.cpu >= 0) cpu = rt.pinned ? Cat({"CPU ", std::to_string(o.cpu)}) : "pinning refused";
  std::fprintf(stderr,
               "idms-agent: %llu ticks, %llu overruns, %llu wake-ups >= 1 period late, steal %lld ms (%s, %s, "
               "spin %lld us)\n"
               "  period  us: p50 %u  p99 %u  p99.9 %u  max %u\n"
               "  wake    us: p50 %u  p99 %u  p99.9 %u  max %u  (after the scheduled time)\n"
               "  compute us: p50 %u  p99 %u  p99.9 %u  max %u\n",
               static_cast<unsigned long long>(loop.counters().ticks.load()),
               static_cast<unsigned long long>(loop.counters().overruns.load()),
               static_cast<unsigned long long>(loop.counters().late_wakeups.load()),
               static_cast<long long>(platform.steal_ms), loop.realtime() ? "real-time" : "not real-time", cpu.c_str(),
               static_cast<long long>(o.spin_ns / 1000), period.p50_us, period.p99_us, period.p999_us, period.max_us,
               wake.p50_us, wake.p99_us, wake.p999_us, wake.max_us, compute.p50_us, compute.p99_us, compute.p999_us,
               compute.max_us);
  if (o.global_rate_hz > 0) {
    const LoopCounters& c = loop.counters();
    const double reachable = c.global_reachable_hz.load();
    std::fprintf(
        stderr, "  global: %lld steps at %g Hz asked, %lld exchanges found it still stepping; it reaches %.0f Hz%s\n",
        static_cast<long long>(c.global_steps.load()), o.global_rate_hz, static_cast<long long>(c.global_late.load()),
        reachable, reachable > 0 && reachable < o.global_rate_hz ? " (the model is too large for the rate asked)" : "");
  }
  if (!offline) {
    std::fprintf(stderr,
                 "  uplink: %llu samples sent (%llu resent, %llu dropped, %llu unsent), %llu mesh frames "
                 "(%llu keyframes), %llu reconnects%s\n",
                 static_cast<unsigned long long>(up.samples_sent), static_cast<unsigned long long>(up.samples_resent),
                 static_cast<unsigned long long>(up.samples_dropped),
                 static_cast<unsigned long long>(up.samples_unsent), static_cast<unsigned long long>(up.mesh_frames),
                 static_cast<unsigned long long>(up.keyframes), static_cast<unsigned long long>(up.reconnects),
                 up.ended_cleanly ? ", session closed cleanly" : "");
  }
}

nlohmann::json LatencyJson(const LatencySummary& s) {
  return {{"p50", s.p50_us}, {"p99", s.p99_us}, {"p999", s.p999_us}, {"max", s.max_us}};
}

bool WriteSummary(const std::string& path, const LatencySummary& period, const LatencySummary& wake,
                  const LatencySummary& compute, const Loop& loop, const Platform& platform, const Device& device,
                  const UplinkStats& up) {
  const LoopCounters& c = loop.counters();
  const RealtimeReport rt = loop.realtime_report();
  nlohmann::json warnings_by_kind = nlohmann::json::object();
  for (const WarningKind& k : WarningKinds(loop.state().warnings)) warnings_by_kind[k.name] = k.count;
  const nlohmann::json j = {
      {"ticks", c.ticks.load()},
      {"overruns", c.overruns.load()},
      {"period_us", LatencyJson(period)},
      {"compute_us", LatencyJson(compute)},
      {"samples_sent", up.samples_sent},
      {"samples_dropped", up.samples_dropped + c.samples_lost.load()},
      {"reconnects", up.reconnects},
      {"realtime", loop.realtime()},
      {"cpu_dma_latency", rt.dma_latency},
      {"cpu", loop.options().cpu},
      {"pinned", rt.pinned},
      {"io_cpus", platform.io_cpus},
      {"spin_us", loop.options().spin_ns / 1000},
      {"wake_latency_us", LatencyJson(wake)},
      {"late_wakeups_over_period", c.late_wakeups.load()},
      {"steal_ms", platform.steal_ms},
      {"steal_ms_loop_cpu", platform.steal_ms_loop_cpu},
      {"samples_resent", up.samples_resent},
      {"samples_unsent", up.samples_unsent},
      {"mesh_frames", up.mesh_frames},
      {"keyframes", up.keyframes},
      {"mesh_skipped", c.mesh_skipped.load()},
      {"force_faults", c.force_faults.load()},
      {"global",
       {{"rate_hz", loop.options().global_rate_hz},
        {"steps", c.global_steps.load()},
        {"late", c.global_late.load()},
        {"reachable_hz", c.global_reachable_hz.load()}}},
      {"passivity",
       {{"enabled", loop.options().passivity.enabled},
        {"ticks_acted", c.passivity_ticks.load()},
        {"dissipated", c.passivity_dissipated.load()}}},
      {"pose_faults", c.pose_faults.load()},
      {"commands", up.commands},
      {"warnings", TotalWarnings(loop.state().warnings)},
      {"warnings_by_kind", warnings_by_kind},
      {"device", device.name()},
      {"device_stats",
       {{"received", device.stats().received},
        {"lost", device.stats().lost},
        {"stale", device.stats().stale},
        {"invalid", device.stats().invalid},
        {"timeouts", device.stats().timeouts},
        {"sent", device.stats().sent}}},
      {"model", loop.model().name},
      {"atoms", loop.model().num_atoms},
      {"session_id", up.session_id},
      {"ended_cleanly", up.ended_cleanly},
      {"error", up.fatal_error},
  };
  std::ofstream out(path);
  out << j.dump(2) << "\n";
  return static_cast<bool>(out);
}

// The final surface (plg vertex order), full precision, for tests to compare with the mirror.
bool DumpFinal(const std::string& path, const Loop& loop) {
  const Model& m = loop.model();
  const State& s = loop.state();
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) return false;
  std::fprintf(f, "# idms-agent final surface: %d vertices, tick %lld, time %.17g s\n", m.num_external,
               static_cast<long long>(s.tick), s.time_s);
  for (int32_t atom : m.external_atoms) {
    const double* p = &s.atom_pos[3 * static_cast<size_t>(atom)];
    std::fprintf(f, "%.17g %.17g %.17g\n", p[0], p[1], p[2]);
  }
  return std::fclose(f) == 0;
}

// The command line into `a`.
void AddOptions(CLI::App& app, Args& a) {
  app.add_option("--server", a.server, "ws://HOST:PORT (or http://) of the idms-server, or 'none' to run offline")
      ->required();
  auto* token_opt = app.add_option("--token", a.token,
                                   "Agent token (sent as Authorization: Bearer); `ps` shows it: "
                                   "prefer IDMS_TOKEN or --token-file")
                        ->envname("IDMS_TOKEN");
  app.add_option("--token-file", a.token_file, "A file holding the agent token alone")->excludes(token_opt);
  app.set_version_flag("--version", Version());
  app.add_option("--trainee", a.trainee, "Who is at the device (the session list filters by it; up to 256 bytes)");
  auto* model_opt = app.add_option("--model", a.model, "Library model NAME[@VERSION], downloaded from the server");
  auto* file_opt = app.add_option("--model-file", a.model_file, "Local model: PREFIX of PREFIX.fem + PREFIX.plg");
  model_opt->excludes(file_opt);
  app.add_option(
         "--device", a.device,
         "scripted:palpate|stroke-slow|stroke-fast|pluck|stroke-gentle|scan[,grid=N]|pierce|stitch|suture|drag, "
         "human:SCRIPT[,mass=,k=,zeta=], udp:PORT[,bind=,timeout_ms=], replay:FILE.mcap")
      ->required();
  auto* scene_opt = app.add_option("--scene", a.scene_file,
                                   "Scene file (idms.v1.Scene text); default: the thesis's tool for the script");
  app.add_option("--preset", a.preset,
                 "Without --scene: default (symplectic Euler, r_l = 2 r) or thesis (explicit Euler, r_l = 1.5 r, "
                 "thesis 6.2); a scene file names its own (preset: PRESET_THESIS)")
      ->excludes(scene_opt);
  app.add_option("--duration", a.duration_s, "Seconds to run; 0 = until SIGINT/SIGTERM")->check(CLI::NonNegativeNumber);
  app.add_option("--rate", a.rate_hz, "Loop rate, Hz (default: the scene's device.max_rate_hz, 1000)")
      ->check(CLI::Range(1.0, 10000.0));
  app.add_option("--summary-json", a.summary_json, "Write the run's figures here at exit");
  app.add_option("--dump-final", a.dump_final, "Write the final surface positions here at exit (text)");
  app.add_option("--cache-dir", a.cache_dir, "Model cache directory (default $IDMS_CACHE_DIR, $XDG_CACHE_HOME/idms)");
  app.add_option("--backlog", a.backlog, "Samples kept for resending after a reconnect")
      ->check(CLI::Range(int64_t{1}, int64_t{100000000}));
  app.add_option("--flush-timeout", a.flush_timeout_s, "Seconds allowed at exit to deliver the rest")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--idle-timeout", a.idle_timeout_s,
                 "Seconds of silence from the server (pinged at half of it) before the link counts as dead and "
                 "the session is resumed on a new connection")
      ->check(CLI::Range(0.2, 600.0))
      ->capture_default_str();
  app.add_option("--scale", a.scale, "Registration: model units per device unit (overrides the scene)")
      ->check(CLI::PositiveNumber);
  app.add_option("--rotation", a.rotation,
                 "Registration: quat:W,X,Y,Z | axis-angle:X,Y,Z,DEG | rpy:R,P,Y (overrides the scene)");
  app.add_option("--offset", a.offset, "Registration: X,Y,Z model units (overrides the scene)");
  app.add_option("--max-force", a.max_force, "Device force clamp, device units (overrides the scene)")
      ->check(CLI::PositiveNumber);
  app.add_option("--friction", a.friction,
                 "mu_s=S[,mu_d=D,k_t=K,b_t=B]: Coulomb friction with stiction at the tool's contacts (overrides "
                 "the scene's; mu_d defaults to mu_s, k_t to the tool's k, b_t to k_t dt)");
  app.add_option("--passivity", a.passivity,
                 "on|off[,window=S,max_damping=B,quantum=Q]: the passivity observer and controller at the device "
                 "port (overrides the scene's; default on for udp: devices, off otherwise and with --preset thesis; "
                 "docs/passivity.md)");
  app.add_option("--global-rate", a.global_rate,
                 "The whole model at this rate (Hz) on a thread of its own beside the local pass (thesis 7.2.2; "
                 "overrides the scene's global_rate_hz; 0 = local only)")
      ->check(CLI::Range(0.0, 500.0));
  app.add_flag("--no-realtime", a.no_realtime, "Do not ask for SCHED_FIFO, mlockall and cpu_dma_latency 0");
  app.add_option("--cpu", a.cpu, "Pin the loop thread to this CPU; the I/O thread keeps off it (default: not pinned)")
      ->check(CLI::Range(0, CPU_SETSIZE - 1));
  app.add_option("--spin-us", a.spin_us,
                 "Sleep until this many us before each deadline, then poll the clock (costs up to that much CPU "
                 "per tick); 0 = off")
      ->check(CLI::Range(int64_t{0}, int64_t{1000000}));
}

// The scene: the file, or the built-in one for the device's script (in the preset asked for);
// the command line's model and registration win. False with a message.
bool ResolveScene(const Args& a, v1::Scene* scene, StepOptions* step, ToolCommand* tool, Registration* registration,
                  std::string* error) {
  if (!a.scene_file.empty()) {
    if (!LoadScene(a.scene_file, scene, error)) return false;
  } else {
    std::string script = "palpate";
    DeviceScriptName(a.device, &script);
    Preset preset = Preset::kDefault;
    if (!a.preset.empty() && !ParsePresetName(a.preset, &preset)) {
      *error = "--preset '" + a.preset + "': expected default or thesis";
      return false;
    }
    *scene = DefaultScene(script, preset == Preset::kThesis ? v1::PRESET_THESIS : v1::PRESET_DEFAULT);
  }
  if (!a.model.empty()) scene->set_model(a.model), scene->clear_model_file();
  if (!a.model_file.empty()) scene->set_model_file(a.model_file), scene->clear_model();
  // The clamp overridden in the scene itself: the step clamps there, and the session's recorded
  // scene (and the force-limit events quoting it) say the limit in force.
  if (a.max_force > 0) scene->mutable_device()->set_max_force(a.max_force);
  if (!a.friction.empty() && !ApplyFrictionSpec(a.friction, scene, error)) return false;
  if (!ApplyPassivitySpec(a.passivity, a.device, scene, error)) return false;
  if (a.global_rate >= 0) scene->set_global_rate_hz(a.global_rate);
  if (!ValidateScene(*scene, error)) return false;
  if (!SceneToLoop(*scene, step, tool, registration, error)) return false;
  if (a.scale > 0) registration->scale = a.scale;
  if (!a.rotation.empty() && !ParseRotation(a.rotation, registration->rot, error)) {
    *error = "--rotation " + *error;
    return false;
  }
  if (!a.offset.empty() && !ParseVec3(a.offset, registration->offset, error)) {
    *error = "--offset " + *error;
    return false;
  }
  return true;
}

// The scene's model: from the library through the cache, or a local pair. 0, or the exit status
// after saying why.
int LoadSceneModel(const Args& a, const v1::Scene& scene, const UplinkOptions& up, bool offline, Model* model) {
  std::string fem_path, plg_path, error;
  if (!scene.model().empty()) {
    if (offline) return Fail("--model needs a server to download from; use --model-file with --server none");
    ModelFetchOptions fetch;
    fetch.host = up.host, fetch.port = up.port, fetch.token = a.token;
    fetch.cache_dir = a.cache_dir.empty() ? DefaultCacheDir() : a.cache_dir;
    bool refused = false;
    if (!FetchModel(scene.model(), fetch, &fem_path, &plg_path, &error, &refused)) {
      Fail(error);
      return refused ? kExitRefused : kExitConfig;
    }
  } else if (!scene.model_file().empty()) {
    ModelPaths(scene.model_file(), &fem_path, &plg_path);
  } else {
    return Fail("no model: give --model NAME[@VERSION] or --model-file PREFIX (or name one in the scene)");
  }
  LoadError load_error;
  if (!LoadModel(fem_path, plg_path, ReadOptions{}, model, &load_error)) return Fail(load_error.ToString());
  return 0;
}

// The loop's rate, streaming, duration and real-time options. False with a message.
bool MakeLoopOptions(const Args& a, const v1::Scene& scene, LoopOptions* lo, std::string* error) {
  lo->rate_hz = a.rate_hz > 0 ? a.rate_hz : scene.device().max_rate_hz();
  lo->mesh_rate_hz = scene.stream_rate_hz();
  lo->max_ticks = a.duration_s > 0 ? std::max<int64_t>(1, std::llround(a.duration_s * lo->rate_hz)) : 0;
  lo->realtime = !a.no_realtime;
  lo->cpu = a.cpu;
  lo->spin_ns = a.spin_us * 1000;
  if (static_cast<double>(lo->spin_ns) >= 1e9 / lo->rate_hz) {
    *error = Cat({"--spin-us ", std::to_string(a.spin_us), ": must be shorter than the period (",
                  std::to_string(std::llround(1e6 / lo->rate_hz)), " us at ", std::to_string(std::llround(lo->rate_hz)),
                  " Hz)"});
    return false;
  }
  return true;
}

// Runs the loop on its own thread and the uplink on this one until both end; what the platform
// did meanwhile (this thread kept off a pinned loop's CPU, steal time over the run).
Platform RunLoopAndUplink(Loop& loop, Uplink& uplink, int cpu, bool* ok) {
  Platform platform;
  if (cpu >= 0) {
    platform.io_cpus = KeepThisThreadOff(cpu);
    if (platform.io_cpus.empty()) {
      std::fprintf(stderr, "idms-agent: note: the I/O thread shares CPU %d with the loop (no other CPU allowed)\n",
                   cpu);
    } else {
      std::fprintf(stderr, "idms-agent: I/O thread on CPUs %s\n", CpuList(platform.io_cpus).c_str());
    }
  }
  // Steal before and after the run, read here: never on the loop thread. {all CPUs, the loop's
  // CPU}, -1 where unreadable (or not pinned).
  const std::string loop_cpu_line = Cat({"cpu", std::to_string(cpu)});
  auto read_steal = [&] {
    return std::array<int64_t, 2>{ReadStealMs("cpu"), cpu >= 0 ? ReadStealMs(loop_cpu_line) : -1};
  };
  const std::array<int64_t, 2> steal_start = read_steal();

  // The loop thread starts with SIGINT/SIGTERM blocked: they are this thread's to handle.
  sigset_t block, old;
  sigemptyset(&block);
  sigaddset(&block, SIGINT);
  sigaddset(&block, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &block, &old);
  std::thread loop_thread([&loop] { loop.Run(); });
  pthread_sigmask(SIG_SETMASK, &old, nullptr);
  *ok = uplink.Run();
  loop_thread.join();
  const std::array<int64_t, 2> steal_end = read_steal();
  auto delta = [](int64_t start, int64_t end) { return start >= 0 && end >= 0 ? end - start : int64_t{-1}; };
  platform.steal_ms = delta(steal_start[0], steal_end[0]);
  platform.steal_ms_loop_cpu = delta(steal_start[1], steal_end[1]);
  return platform;
}

int Main(int argc, char** argv) {
  Args a;
  CLI::App app{"idms-agent: the 1 kHz DSM loop next to a haptic device, reporting to an idms-server"};
  AddOptions(app, a);
  CLI11_PARSE(app, argc, argv);

  // A CPU this process may not use is an error, not a silently unpinned loop.
  if (a.cpu >= 0) {
    const std::vector<int> allowed = AllowedCpus();
    if (std::find(allowed.begin(), allowed.end(), a.cpu) == allowed.end()) {
      return Fail(Cat({"--cpu ", std::to_string(a.cpu), ": this process may run on CPUs ", CpuList(allowed),
                       " only (sched_getaffinity); pick one of them or leave --cpu out"}));
    }
  }
  const bool offline = a.server == "none";
  UplinkOptions up;
  std::string error;
  if (!offline && !ParseServer(a.server, &up, &error)) return Fail(error);
  if (!a.token_file.empty() && !ReadTokenFile(a.token_file, &a.token, &error)) return Fail(error);
  if (!offline && a.token.empty()) {
    return Fail("a token is required with a server: --token-file FILE, IDMS_TOKEN or --token (or use --server none)");
  }

  // Scene, model, device.
  v1::Scene scene;
  StepOptions step;
  ToolCommand tool;
  Registration registration;
  if (!ResolveScene(a, &scene, &step, &tool, &registration, &error)) return Fail(error);
  Model model;
  if (const int status = LoadSceneModel(a, scene, up, offline, &model); status != 0) return status;
  LoopOptions lo;
  if (!MakeLoopOptions(a, scene, &lo, &error)) return Fail(error);
  if (!SceneTools(scene, &lo.tools, &lo.num_tools, &error)) return Fail(error);
  lo.passivity = PassivityFromScene(scene, registration, step.dt_s);
  lo.global_rate_hz = scene.global_rate_hz();
  // The cores the loop does not use (sections of a renumbered model; one otherwise).
  lo.global_threads = std::max(1, static_cast<int>(std::thread::hardware_concurrency()) - 1);
  if (lo.global_rate_hz > 0) {
    std::fprintf(stderr, "idms-agent: global pass at %g Hz beside the local one (its own thread)\n", lo.global_rate_hz);
  }
  if (lo.passivity.enabled) {
    std::fprintf(stderr, "idms-agent: passivity controller on (window %g s, damping up to %g, encoder %g)\n",
                 scene.device().passivity().window_s(), scene.device().passivity().max_damping(),
                 scene.device().passivity().encoder_quantum());
  }
  DeviceContext dc;
  dc.model = &model;
  dc.registration = registration;
  dc.mio_radius = tool.radius;
  dc.mu_s = tool.mu_s;
  dc.dt_s = step.dt_s;
  dc.num_tools = lo.num_tools;
  for (int32_t i = 0; i < lo.num_tools; ++i) dc.tool_kinds[i] = lo.tools[i].kind;
  std::unique_ptr<Device> device = MakeDevice(a.device, dc, &error);
  if (!device) return Fail(error);
  if (std::abs(lo.rate_hz * step.dt_s - 1) > 1e-9) {
    std::fprintf(stderr, "idms-agent: note: %.0f Hz with dt %.6g s runs the simulation at %.3gx real time\n",
                 lo.rate_hz, step.dt_s, lo.rate_hz * step.dt_s);
  }

  // The loop and the uplink (the uplink's signal handlers exist before the loop starts).
  Loop loop(std::move(model), step, tool, registration, *device, lo);
  up.offline = offline;
  up.token = a.token;
  char host[256] = "?";
  gethostname(host, sizeof(host) - 1);
  up.identity = Cat({"idms-agent ", host}) + " pid " + std::to_string(getpid());
  up.trainee = a.trainee;
  up.device = device->name();
  up.scene = scene;
  up.backlog_samples = a.backlog;
  up.flush_timeout_s = a.flush_timeout_s;
  up.idle_timeout_s = a.idle_timeout_s;
  Uplink uplink(loop, up);
  std::signal(SIGPIPE, SIG_IGN);
  bool ok = false;
  const Platform platform = RunLoopAndUplink(loop, uplink, lo.cpu, &ok);

  // Figures, files, exit status.
  const LatencySummary period = loop.period_histogram().Summary();
  const LatencySummary wake = loop.wake_histogram().Summary();
  const LatencySummary compute = loop.compute_histogram().Summary();
  PrintSummary(period, wake, compute, loop, platform, uplink.stats(), offline);
  if (!a.summary_json.empty() &&
      !WriteSummary(a.summary_json, period, wake, compute, loop, platform, *device, uplink.stats())) {
    std::fprintf(stderr, "idms-agent: error: cannot write %s\n", a.summary_json.c_str());
  }
  if (!a.dump_final.empty() && !DumpFinal(a.dump_final, loop)) {
    std::fprintf(stderr, "idms-agent: error: cannot write %s\n", a.dump_final.c_str());
  }
  return ok ? 0 : kExitRefused;
}

}  // namespace
}  // namespace idms::agent

int main(int argc, char** argv) { return idms::agent::Main(argc, argv); }
