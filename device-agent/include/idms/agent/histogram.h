// Fixed-bucket latency histograms for the 1 kHz loop (period and compute time): 1 µs buckets,
// allocated once, filled without allocation or locks by the one thread that owns them.
#pragma once

#include <cstdint>
#include <vector>

namespace idms::agent {

// p50 / p99 / p99.9 / max of a histogram, microseconds.
struct LatencySummary {
  uint64_t count = 0;
  uint32_t p50_us = 0;
  uint32_t p99_us = 0;
  uint32_t p999_us = 0;
  uint32_t max_us = 0;
};

// Owned by one thread. Values of kNumBuckets - 1 µs and above share the last bucket; the maximum
// is kept exactly, so a rare long stall still shows in max_us.
class LatencyHistogram {
 public:
  static constexpr uint32_t kNumBuckets = 20000;  // 0 .. 19.999 ms in 1 µs steps

  LatencyHistogram();  // allocates the buckets (160 kB)

  // Records one value, microseconds. Does not allocate.
  void Add(uint32_t us) {
    ++buckets_[us < kNumBuckets ? us : kNumBuckets - 1];
    ++count_;
    if (us > max_us_) max_us_ = us;
  }

  // The smallest v such that at least q (in [0, 1]) of the values are <= v; values in the last
  // bucket report the maximum. 0 when empty. O(kNumBuckets).
  uint32_t Percentile(double q) const;
  LatencySummary Summary() const;
  void Clear();

  uint64_t count() const { return count_; }
  uint32_t max_us() const { return max_us_; }

 private:
  std::vector<uint64_t> buckets_;  // (kNumBuckets), counts
  uint64_t count_ = 0;
  uint32_t max_us_ = 0;
};

}  // namespace idms::agent
