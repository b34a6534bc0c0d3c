// Prometheus text format, written by hand: it is a few lines of text, and no Debian package
// offers a C++ client.
#include "idms/server/metrics.h"

#include <cstdio>
#include <sstream>

namespace idms::server {

void Metrics::CountRequest(const std::string& method, const std::string& route, int status, double seconds,
                           uint64_t bytes_in, uint64_t bytes_out) {
  bytes_in_ += bytes_in;
  bytes_out_ += bytes_out;
  std::lock_guard lock(mu_);
  ++requests_[{method, route, status}];
  Histogram& h = durations_[route];
  for (size_t i = 0; i < kBuckets.size(); ++i) {
    if (seconds <= kBuckets[i]) ++h.counts[i];
  }
  ++h.count;
  h.sum += seconds;
}

std::string Metrics::Render(int64_t models, int64_t library_bytes, double uptime_s) const {
  std::ostringstream out;
  out << "# HELP idms_http_requests_total HTTP requests by method, route and status.\n"
         "# TYPE idms_http_requests_total counter\n";
  std::lock_guard lock(mu_);
  for (const auto& [key, n] : requests_) {
    const auto& [method, route, status] = key;
    out << "idms_http_requests_total{method=\"" << method << "\",route=\"" << route << "\",status=\"" << status
        << "\"} " << n << "\n";
  }
  out << "# HELP idms_http_request_duration_seconds Time from a request's last byte read to its response "
         "written.\n# TYPE idms_http_request_duration_seconds histogram\n";
  for (const auto& [route, h] : durations_) {
    for (size_t i = 0; i < kBuckets.size(); ++i) {
      char le[32];
      std::snprintf(le, sizeof le, "%g", kBuckets[i]);
      out << "idms_http_request_duration_seconds_bucket{route=\"" << route << "\",le=\"" << le << "\"} " << h.counts[i]
          << "\n";
    }
    out << "idms_http_request_duration_seconds_bucket{route=\"" << route << "\",le=\"+Inf\"} " << h.count << "\n"
        << "idms_http_request_duration_seconds_sum{route=\"" << route << "\"} " << h.sum << "\n"
        << "idms_http_request_duration_seconds_count{route=\"" << route << "\"} " << h.count << "\n";
  }
  out << "# HELP idms_http_bytes_received_total Request bytes (headers and bodies).\n"
         "# TYPE idms_http_bytes_received_total counter\nidms_http_bytes_received_total "
      << bytes_in_.load() << "\n"
      << "# HELP idms_http_bytes_sent_total Response bytes (headers and bodies) and WebSocket frames.\n"
         "# TYPE idms_http_bytes_sent_total counter\nidms_http_bytes_sent_total "
      << bytes_out_.load() << "\n"
      << "# HELP idms_open_connections Open connections, HTTP and WebSocket.\n# TYPE idms_open_connections gauge\n"
         "idms_open_connections "
      << open_connections.load() << "\n"
      << "# HELP idms_open_websockets Open WebSocket connections.\n# TYPE idms_open_websockets gauge\n"
         "idms_open_websockets "
      << open_websockets.load() << "\n"
      << "# HELP idms_rejected_connections_total Connections refused with 503 at a connection limit: the "
         "server's (total) or one address's (address).\n"
         "# TYPE idms_rejected_connections_total counter\nidms_rejected_connections_total{limit=\"total\"} "
      << rejected_connections.load() << "\nidms_rejected_connections_total{limit=\"address\"} "
      << rejected_per_address.load() << "\n"
      << "# HELP idms_accept_paused_total Accepts that failed for want of descriptors or memory (EMFILE, ENFILE, "
         "ENOBUFS, ENOMEM), each followed by a 100 ms pause.\n"
         "# TYPE idms_accept_paused_total counter\nidms_accept_paused_total "
      << accept_paused.load() << "\n"
      << "# HELP idms_models Models in the library.\n# TYPE idms_models gauge\nidms_models " << models << "\n"
      << "# HELP idms_library_bytes Bytes of .fem and .plg files over all stored versions.\n"
         "# TYPE idms_library_bytes gauge\nidms_library_bytes "
      << library_bytes << "\n"
      << "# HELP idms_uptime_seconds Seconds since the server started.\n# TYPE idms_uptime_seconds gauge\n"
         "idms_uptime_seconds "
      << uptime_s << "\n";
  return out.str();
}

}  // namespace idms::server
