// The real idms-agent binary, offline, with the real-time options: --cpu pins the loop and says
// so in the summary, --spin-us keeps the period, the summary carries steal time and late
// wake-ups, and a CPU or spin the machine cannot give is a clear error, not a silent fallback.
#include <gtest/gtest.h>

#include <algorithm>
#include <nlohmann/json.hpp>

#include "agent_process.h"
#include "idms/agent/loop.h"

namespace idms::test {
namespace {

using std::chrono::seconds;

const std::string kModel = std::string(IDMS_SOURCE_DIR) + "/models/hex_4x5_home";

nlohmann::json ReadJson(const std::string& path) { return nlohmann::json::parse(ReadText(path)); }

std::vector<std::string> OfflineArgs(const std::string& duration_s, const std::string& summary) {
  return {"--server",         "none",       "--model-file", kModel,           "--device",
          "scripted:palpate", "--duration", duration_s,     "--summary-json", summary};
}

TEST(AgentRt, CpuPinsTheLoopAndTheSummarySaysSo) {
  const std::vector<int> allowed = agent::AllowedCpus();
  ASSERT_FALSE(allowed.empty());
  const int cpu = allowed.front();  // CPU 0 unless this process may not use it
  const std::string dir = TempDir("pinned");
  std::vector<std::string> args = OfflineArgs("0.3", dir + "/summary.json");
  args.insert(args.end(), {"--no-realtime", "--cpu", std::to_string(cpu)});
  AgentProcess agent(args, dir + "/agent.log");
  ASSERT_EQ(agent.Wait(seconds(30)), std::optional<int>(0)) << agent.Log();
  const nlohmann::json summary = ReadJson(dir + "/summary.json");
  EXPECT_EQ(summary["ticks"], 300);
  EXPECT_EQ(summary["cpu"], cpu);
  EXPECT_EQ(summary["pinned"], true);
  EXPECT_GE(summary["steal_ms_loop_cpu"].get<int64_t>(), 0);
  EXPECT_NE(agent.Log().find("loop pinned to CPU " + std::to_string(cpu)), std::string::npos) << agent.Log();
  // The I/O thread moved to the other CPUs, when there are any.
  const std::vector<int> io_cpus = summary["io_cpus"].get<std::vector<int>>();
  EXPECT_EQ(io_cpus.size(), allowed.size() - 1);
  for (int c : io_cpus) EXPECT_NE(c, cpu);
}

// Correctness of the spin, not a speed test. With the spin, a tick starts when the clock passes its
// scheduled time, so the median wake-up lateness is the cost of one clock read (0 µs), where a
// sleep all the way pays the timer's wake-up latency (~15 µs on the VM this was written on); and
// the period's median stays one period. A busy machine delays only a minority of wake-ups of a
// SCHED_FIFO thread, so medians are checked only when SCHED_FIFO was granted; without it a loaded
// machine may hold the loop off the CPU for whole periods, and the test checks the counts alone.
TEST(AgentRt, SpinKeepsThePeriod) {
  const std::string dir = TempDir("spin");
  std::vector<std::string> args = OfflineArgs("0.5", dir + "/summary.json");
  args.insert(args.end(), {"--spin-us", "50"});
  AgentProcess agent(args, dir + "/agent.log");
  ASSERT_EQ(agent.Wait(seconds(30)), std::optional<int>(0)) << agent.Log();
  const nlohmann::json summary = ReadJson(dir + "/summary.json");
  EXPECT_EQ(summary["ticks"], 500);
  EXPECT_EQ(summary["spin_us"], 50);
  EXPECT_EQ(summary["cpu"], -1);
  EXPECT_EQ(summary["pinned"], false);
  EXPECT_NE(agent.Log().find("spinning the last 50 us before each deadline"), std::string::npos) << agent.Log();
  if (summary["realtime"] != true) GTEST_SKIP() << "SCHED_FIFO or mlockall refused: period median not checked";
  const int period_p50 = summary["period_us"]["p50"];
  EXPECT_GE(period_p50, 950);
  EXPECT_LE(period_p50, 1050);
  EXPECT_LE(summary["wake_latency_us"]["p50"].get<int>(), 5) << "the spin should end at the deadline";
}

TEST(AgentRt, SummaryHasStealAndLateWakeups) {
  const std::string dir = TempDir("steal");
  std::vector<std::string> args = OfflineArgs("0.2", dir + "/summary.json");
  args.push_back("--no-realtime");
  AgentProcess agent(args, dir + "/agent.log");
  ASSERT_EQ(agent.Wait(seconds(30)), std::optional<int>(0)) << agent.Log();
  const nlohmann::json summary = ReadJson(dir + "/summary.json");
  EXPECT_EQ(summary["ticks"], 200);
  EXPECT_GE(summary["steal_ms"].get<int64_t>(), 0);
  EXPECT_EQ(summary["steal_ms_loop_cpu"], -1) << "not pinned";
  EXPECT_EQ(summary["spin_us"], 0);
  EXPECT_EQ(summary["cpu_dma_latency"], false) << "--no-realtime leaves CPU idle states alone";
  EXPECT_LE(summary["late_wakeups_over_period"].get<uint64_t>(), summary["ticks"].get<uint64_t>());
  EXPECT_TRUE(summary["wake_latency_us"].contains("p999"));
  EXPECT_NE(agent.Log().find("wake-ups >= 1 period late, steal "), std::string::npos) << agent.Log();
}

TEST(AgentRt, CpuTheProcessMayNotUseIsAClearError) {
  const std::vector<int> allowed = agent::AllowedCpus();
  if (std::find(allowed.begin(), allowed.end(), 99) != allowed.end()) GTEST_SKIP() << "CPU 99 exists here";
  const std::string dir = TempDir("bad-cpu");
  std::vector<std::string> args = OfflineArgs("0.2", dir + "/summary.json");
  args.insert(args.end(), {"--no-realtime", "--cpu", "99"});
  AgentProcess agent(args, dir + "/agent.log");
  ASSERT_EQ(agent.Wait(seconds(30)), std::optional<int>(1)) << agent.Log();
  EXPECT_NE(agent.Log().find("error: --cpu 99: this process may run on CPUs "), std::string::npos) << agent.Log();
}

TEST(AgentRt, SpinAsLongAsThePeriodIsAClearError) {
  const std::string dir = TempDir("bad-spin");
  std::vector<std::string> args = OfflineArgs("0.2", dir + "/summary.json");
  args.insert(args.end(), {"--no-realtime", "--rate", "2000", "--spin-us", "500"});
  AgentProcess agent(args, dir + "/agent.log");
  ASSERT_EQ(agent.Wait(seconds(30)), std::optional<int>(1)) << agent.Log();
  EXPECT_NE(agent.Log().find("error: --spin-us 500: must be shorter than the period (500 us at 2000 Hz)"),
            std::string::npos)
      << agent.Log();
}

}  // namespace
}  // namespace idms::test
