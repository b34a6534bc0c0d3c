// Percentiles over the fixed 1 µs buckets of LatencyHistogram.
#include "idms/agent/histogram.h"

#include <algorithm>
#include <cmath>

namespace idms::agent {

LatencyHistogram::LatencyHistogram() : buckets_(kNumBuckets, 0) {}

uint32_t LatencyHistogram::Percentile(double q) const {
  if (count_ == 0) return 0;
  // Rank of the value asked for, 1-based, at least 1.
  const double clamped = std::clamp(q, 0.0, 1.0);
  const uint64_t rank = std::max<uint64_t>(1, static_cast<uint64_t>(std::ceil(clamped * static_cast<double>(count_))));
  // Walk the buckets until the running count reaches the rank.
  uint64_t seen = 0;
  for (uint32_t i = 0; i + 1 < kNumBuckets; ++i) {
    seen += buckets_[i];
    if (seen >= rank) return i;
  }
  return max_us_;
}

LatencySummary LatencyHistogram::Summary() const {
  LatencySummary s;
  s.count = count_;
  s.p50_us = Percentile(0.50);
  s.p99_us = Percentile(0.99);
  s.p999_us = Percentile(0.999);
  s.max_us = max_us_;
  return s;
}

void LatencyHistogram::Clear() {
  std::fill(buckets_.begin(), buckets_.end(), 0);
  count_ = 0;
  max_us_ = 0;
}

}  // namespace idms::agent
