// The loop's real-time helpers (loop.h): the wait never returns before its deadline and allocates
// nothing with or without a spin, late wake-ups are counted against the schedule, CPU pinning
// and keeping off a CPU, and the steal time parsed from /proc/stat.
#include <gtest/gtest.h>
#include <sched.h>

#include <algorithm>
#include <cerrno>
#include <memory>
#include <thread>

#include "alloc_counter.h"
#include "hex_loop.h"
#include "idms/agent/device.h"
#include "idms/agent/loop.h"
#include "idms/agent/setup.h"
#include "idms/sim/model_io.h"

namespace idms::test {
namespace {

using agent::Loop;
using agent::MonotonicNs;

constexpr int64_t kPeriodNs = 1000000;

TEST(LoopRt, WaitUntilNeverReturnsEarlyAndAllocatesNothing) {
  for (const int64_t spin_ns : {int64_t{0}, int64_t{50000}, int64_t{300000}}) {
    agent::WaitUntil(MonotonicNs() + 100000, spin_ns);  // warm-up
    const int64_t before = AllocationCount();
    int64_t deadline_ns = MonotonicNs();
    for (int i = 0; i < 100; ++i) {
      deadline_ns += kPeriodNs / 4;
      const int64_t woke_ns = agent::WaitUntil(deadline_ns, spin_ns);
      ASSERT_GE(woke_ns, deadline_ns) << "spin " << spin_ns << " ns, wait " << i;
      ASSERT_LE(woke_ns, MonotonicNs()) << "the wake time is a clock reading, not the deadline";
    }
    EXPECT_EQ(AllocationCount() - before, 0) << "spin " << spin_ns << " ns";
  }
  // A deadline already gone returns at once with the current time.
  const int64_t past_ns = MonotonicNs() - kPeriodNs;
  EXPECT_GE(agent::WaitUntil(past_ns, 50000), past_ns + kPeriodNs);
}

using test::HexLoop;

TEST(LoopRt, WakeUpsAPeriodLateAreCountedAgainstTheSchedule) {
  Model model;
  std::unique_ptr<agent::Device> device;
  std::unique_ptr<Loop> loop = HexLoop(&model, &device);
  ASSERT_TRUE(device);
  // Scheduled wake-ups 1 ms apart; the deadline of each is the next one.
  const int64_t t0 = MonotonicNs();
  loop->Tick(t0 + 20000, t0 + kPeriodNs);                        // 20 µs late
  loop->Tick(t0 + kPeriodNs + 999000, t0 + 2 * kPeriodNs);       // 999 µs late: not a period
  loop->Tick(t0 + 3 * kPeriodNs, t0 + 3 * kPeriodNs);            // exactly one period late
  loop->Tick(t0 + 3 * kPeriodNs + 5000000, t0 + 4 * kPeriodNs);  // 5 ms late
  loop->samples().consume_all([](const agent::TickSample&) {});
  EXPECT_EQ(loop->counters().late_wakeups.load(), 2u);
  const agent::LatencySummary wake = loop->wake_histogram().Summary();
  EXPECT_EQ(wake.count, 4u);
  EXPECT_EQ(wake.max_us, 5000u);
  EXPECT_EQ(loop->wake_histogram().Percentile(0.25), 20u);
  EXPECT_EQ(loop->wake_histogram().Percentile(0.5), 999u);
  EXPECT_EQ(loop->wake_histogram().Percentile(0.75), 1000u);
}

TEST(LoopRt, PinThisThreadRunsOnThatCpuOnly) {
  const std::vector<int> allowed = agent::AllowedCpus();
  ASSERT_FALSE(allowed.empty());
  const int cpu = allowed.back();
  int pin = -1, ran_on = -1;
  std::vector<int> after;
  std::thread([&] {
    pin = agent::PinThisThread(cpu);
    ran_on = sched_getcpu();
    after = agent::AllowedCpus();
  }).join();
  EXPECT_EQ(pin, 0);
  EXPECT_EQ(ran_on, cpu);
  EXPECT_EQ(after, std::vector<int>{cpu});
  EXPECT_EQ(agent::PinThisThread(CPU_SETSIZE), EINVAL);
  EXPECT_EQ(agent::PinThisThread(-1), EINVAL);
}

TEST(LoopRt, KeepThisThreadOffLeavesTheCpuToTheLoop) {
  const std::vector<int> allowed = agent::AllowedCpus();
  ASSERT_FALSE(allowed.empty());
  const int cpu = allowed.front();
  std::vector<int> kept, after, child;
  std::thread([&] {
    kept = agent::KeepThisThreadOff(cpu);
    after = agent::AllowedCpus();
    // Threads started later inherit the mask.
    std::thread([&] { child = agent::AllowedCpus(); }).join();
  }).join();
  if (allowed.size() == 1) {
    EXPECT_TRUE(kept.empty()) << "no other CPU: nothing to move to";
    EXPECT_EQ(after, allowed);
    return;
  }
  std::vector<int> others = allowed;
  others.erase(others.begin());
  EXPECT_EQ(kept, others);
  EXPECT_EQ(after, others);
  EXPECT_EQ(child, others);
}

TEST(LoopRt, StealIsTheEighthValueOfTheCpuLineInUserHz) {
  const std::string stat =
      "cpu  1411474 351313 112681 299682 926 0 342 1445 0 0\n"
      "cpu0 711889 165990 56280 153599 221 0 67 727 0 0\n"
      "cpu1 699585 185323 56401 146083 705 0 274 717 0 0\n"
      "cpu12 1 2 3 4 5 6 7\n"
      "intr 123 4 5\n";
  EXPECT_EQ(agent::ParseStealMs(stat, "cpu", 100), 14450);
  EXPECT_EQ(agent::ParseStealMs(stat, "cpu0", 100), 7270);
  EXPECT_EQ(agent::ParseStealMs(stat, "cpu1", 100), 7170) << "cpu1 must not match cpu12";
  EXPECT_EQ(agent::ParseStealMs(stat, "cpu1", 250), 2868);
  EXPECT_EQ(agent::ParseStealMs(stat, "cpu12", 100), -1) << "7 values: no steal column";
  EXPECT_EQ(agent::ParseStealMs(stat, "cpu3", 100), -1);
  EXPECT_EQ(agent::ParseStealMs(stat, "cpu", 0), -1);
  EXPECT_EQ(agent::ParseStealMs("", "cpu", 100), -1);
  // This machine's, and it never goes backwards.
  const int64_t first = agent::ReadStealMs("cpu");
  EXPECT_GE(first, 0);
  EXPECT_GE(agent::ReadStealMs("cpu"), first);
}

}  // namespace
}  // namespace idms::test
