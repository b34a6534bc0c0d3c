// The server's Prometheus metrics: requests by route and status, a request-duration histogram,
// bytes in and out, open connections and WebSockets; library figures are read at scrape time.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>

namespace idms::server {

class Metrics {
 public:
  // One finished HTTP request. `method` and `route` are bounded labels (MethodLabel, the route's
  // pattern or "(none)"), never the client's spelling or path: every label set is kept forever.
  void CountRequest(const std::string& method, const std::string& route, int status, double seconds, uint64_t bytes_in,
                    uint64_t bytes_out);
  void AddBytesOut(uint64_t n) { bytes_out_ += n; }
  void AddBytesIn(uint64_t n) { bytes_in_ += n; }

  std::atomic<int64_t> open_connections{0};
  std::atomic<int64_t> open_websockets{0};
  std::atomic<int64_t> rejected_connections{0};  // at --max-connections
  std::atomic<int64_t> rejected_per_address{0};  // at --max-connections-per-address
  std::atomic<int64_t> accept_paused{0};         // accepts that failed for want of descriptors or memory

  // Prometheus text exposition format 0.0.4.
  std::string Render(int64_t models, int64_t library_bytes, double uptime_s) const;

 private:
  static constexpr std::array<double, 12> kBuckets = {0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025,
                                                      0.05,   0.1,   0.25,   0.5,   1.0,  5.0};
  struct Histogram {
    std::array<uint64_t, kBuckets.size()> counts{};
    uint64_t count = 0;
    double sum = 0;
  };
  mutable std::mutex mu_;
  std::map<std::tuple<std::string, std::string, int>, uint64_t> requests_;  // method, route, status
  std::map<std::string, Histogram> durations_;                              // by route
  std::atomic<uint64_t> bytes_in_{0}, bytes_out_{0};
};

}  // namespace idms::server
