// LatencyHistogram: percentiles over 1 µs buckets, overflow kept as the exact maximum.
#include "idms/agent/histogram.h"

#include <gtest/gtest.h>

namespace idms::test {
namespace {

TEST(LatencyHistogram, PercentilesOfKnownData) {
  agent::LatencyHistogram h;
  EXPECT_EQ(h.Percentile(0.5), 0u);
  for (uint32_t v = 1; v <= 1000; ++v) h.Add(v);
  const agent::LatencySummary s = h.Summary();
  EXPECT_EQ(s.count, 1000u);
  EXPECT_EQ(s.p50_us, 500u);
  EXPECT_EQ(s.p99_us, 990u);
  EXPECT_EQ(s.p999_us, 999u);
  EXPECT_EQ(s.max_us, 1000u);
}

TEST(LatencyHistogram, OverflowReportsTheMaximum) {
  agent::LatencyHistogram h;
  for (int i = 0; i < 998; ++i) h.Add(1000);
  h.Add(50000);
  h.Add(70000);
  EXPECT_EQ(h.Percentile(0.5), 1000u);
  EXPECT_EQ(h.Percentile(0.999), 70000u);
  EXPECT_EQ(h.max_us(), 70000u);
  h.Clear();
  EXPECT_EQ(h.count(), 0u);
  EXPECT_EQ(h.max_us(), 0u);
}

}  // namespace
}  // namespace idms::test
