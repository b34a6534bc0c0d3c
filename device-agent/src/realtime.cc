// The loop's platform helpers (realtime.h).
#include "idms/agent/realtime.h"

#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <fstream>
#include <sstream>

namespace idms::agent {
namespace {

timespec ToTimespec(int64_t ns) {
  timespec ts;
  ts.tv_sec = static_cast<time_t>(ns / 1000000000);
  ts.tv_nsec = static_cast<long>(ns % 1000000000);
  return ts;
}

}  // namespace

int64_t MonotonicNs() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

int64_t WaitUntil(int64_t deadline_ns, int64_t spin_ns) {
  // Sleep on the absolute deadline, or on the start of the spin before it.
  const timespec ts = ToTimespec(deadline_ns - spin_ns);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
  // Spin: poll the clock until the deadline (at once false when the sleep went all the way). No
  // PAUSE in the loop: in a KVM guest a tight PAUSE loop can trigger a pause-loop exit, which
  // hands the vCPU back to the host, the very stall the spin is there to avoid.
  int64_t now_ns = MonotonicNs();
  while (now_ns < deadline_ns) now_ns = MonotonicNs();
  return now_ns;
}

bool SetMinimalTimerSlack() { return prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL) == 0; }

RealtimeReport SetUpRealtime(int priority, int* dma_latency_fd) {
  RealtimeReport r;
  // Timer slack 1 ns: wake-ups are not coalesced with other timers.
  r.timer_slack = SetMinimalTimerSlack();
  // Lock every page now and later, so a tick never waits for a page fault.
  r.mlock = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
  if (!r.mlock) r.mlock_errno = errno;
  // First-in-first-out real-time priority for this thread only.
  sched_param param{};
  param.sched_priority = priority;
  r.fifo_errno = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
  r.fifo = r.fifo_errno == 0;
  // CPU idle states with a non-zero exit latency off while the file stays open (PM QoS).
  *dma_latency_fd = open("/dev/cpu_dma_latency", O_WRONLY | O_CLOEXEC);
  if (*dma_latency_fd >= 0) {
    const int32_t zero_us = 0;
    if (write(*dma_latency_fd, &zero_us, sizeof(zero_us)) == static_cast<ssize_t>(sizeof(zero_us))) {
      r.dma_latency = true;
    } else {
      r.dma_latency_errno = errno;
      close(*dma_latency_fd);
      *dma_latency_fd = -1;
    }
  } else {
    r.dma_latency_errno = errno;
  }
  return r;
}

std::vector<int> AllowedCpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  std::vector<int> cpus;
  if (sched_getaffinity(0, sizeof(set), &set) != 0) return cpus;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu) {
    if (CPU_ISSET(cpu, &set)) cpus.push_back(cpu);
  }
  return cpus;
}

int PinThisThread(int cpu) {
  if (cpu < 0 || cpu >= CPU_SETSIZE) return EINVAL;
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  return pthread_setaffinity_np(pthread_self(), sizeof(set), &set);
}

std::vector<int> KeepThisThreadOff(int cpu) {
  // Every allowed CPU but `cpu`; nothing to do when there is no other.
  std::vector<int> others = AllowedCpus();
  others.erase(std::remove(others.begin(), others.end(), cpu), others.end());
  if (others.empty()) return others;
  cpu_set_t set;
  CPU_ZERO(&set);
  for (int c : others) CPU_SET(c, &set);
  if (pthread_setaffinity_np(pthread_self(), sizeof(set), &set) != 0) others.clear();
  return others;
}

int64_t ParseStealMs(const std::string& proc_stat, const std::string& line, long user_hz) {
  if (user_hz <= 0) return -1;
  // The line that starts with `line` and a blank ("cpu" must not match "cpu0").
  size_t begin = 0;
  while (begin < proc_stat.size()) {
    size_t end = proc_stat.find('\n', begin);
    if (end == std::string::npos) end = proc_stat.size();
    const size_t after = begin + line.size();
    if (after < end && proc_stat.compare(begin, line.size(), line) == 0 &&
        (proc_stat[after] == ' ' || proc_stat[after] == '\t')) {
      // user nice system idle iowait irq softirq steal ...: the 8th.
      std::istringstream in(proc_stat.substr(after, end - after));
      uint64_t value = 0;
      for (int i = 0; i < 8; ++i) {
        if (!(in >> value)) return -1;
      }
      return static_cast<int64_t>(value * 1000 / static_cast<uint64_t>(user_hz));
    }
    begin = end + 1;
  }
  return -1;
}

int64_t ReadStealMs(const std::string& line) {
  std::ifstream in("/proc/stat");
  if (!in) return -1;
  std::ostringstream text;
  text << in.rdbuf();
  return ParseStealMs(text.str(), line, sysconf(_SC_CLK_TCK));
}

}  // namespace idms::agent
