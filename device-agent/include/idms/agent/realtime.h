// The loop's platform helpers: the clock and absolute-deadline waits, real-time scheduling,
// memory locking and CPU idle latency, CPU pinning, and hypervisor steal time. Each says which
// thread may call it; only MonotonicNs and WaitUntil belong in a tick.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace idms::agent {

// What the real-time setup achieved, reported before the first tick.
struct RealtimeReport {
  bool fifo = false, mlock = false, timer_slack = false;
  bool dma_latency = false;  // /dev/cpu_dma_latency held at 0 µs (CPU idle states with no exit latency)
  bool pinned = false;       // the loop thread runs on LoopOptions::cpu only
  int fifo_errno = 0, mlock_errno = 0, dma_latency_errno = 0, pin_errno = 0;
};

// CLOCK_MONOTONIC now, ns (clock_gettime through the vDSO: no system call with the tsc or
// kvm-clock clocksource).
int64_t MonotonicNs();

// Returns at CLOCK_MONOTONIC deadline_ns or later, with the time it saw then, ns: clock_nanosleep
// (TIMER_ABSTIME) until deadline_ns - spin_ns, then MonotonicNs in a busy loop until deadline_ns.
// spin_ns 0 = sleep all the way. The spin trades up to spin_ns of CPU per call for a wake-up that
// does not depend on the timer interrupt's latency. Loop thread; no allocation, and no system
// call but the sleep.
int64_t WaitUntil(int64_t deadline_ns, int64_t spin_ns);

// A 1 ns timer slack for the calling thread (wake-ups not coalesced with other timers); false
// when refused. A system call: not in the tick.
bool SetMinimalTimerSlack();

// Tries SCHED_FIFO at `priority` for the calling thread, mlockall(MCL_CURRENT | MCL_FUTURE), a
// 1 ns timer slack and a 0 µs CPU idle exit latency (writes 0 to /dev/cpu_dma_latency, as
// cyclictest does; the request holds while *dma_latency_fd stays open, -1 when refused); reports
// what worked. Not for the tick itself (it makes system calls).
RealtimeReport SetUpRealtime(int priority, int* dma_latency_fd);

// The CPUs this process may run on (sched_getaffinity), ascending. Allocates; not in the tick.
std::vector<int> AllowedCpus();

// Restricts the calling thread to `cpu` alone; 0 or the errno.
int PinThisThread(int cpu);

// Restricts the calling thread to the allowed CPUs other than `cpu`, so that it and the threads it
// starts later leave `cpu` to the loop; the CPUs it kept, empty when `cpu` is the only one (the
// thread is then left as it was).
std::vector<int> KeepThisThreadOff(int cpu);

// Hypervisor steal time since boot, ms: the 8th value of `line` ("cpu" = all CPUs summed,
// "cpu1" = CPU 1) in /proc/stat, in USER_HZ (sysconf(_SC_CLK_TCK)); -1 when unreadable. USER_HZ
// is usually 100, so the figure moves in 10 ms steps. Reads a file and allocates: not in the loop.
int64_t ReadStealMs(const std::string& line);
// The same from /proc/stat's text (for tests).
int64_t ParseStealMs(const std::string& proc_stat, const std::string& line, long user_hz);

}  // namespace idms::agent
