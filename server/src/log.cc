// Text or JSON lines through spdlog's stderr logger (thread-safe, one write per line).
#include "idms/server/log.h"

#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>

#include <atomic>

#include "idms/server/storage.h"  // UtcNowMs

namespace idms::server {
namespace {

std::atomic<bool> g_json{false};

spdlog::logger& Logger() {
  static std::shared_ptr<spdlog::logger> logger = [] {
    auto l = spdlog::stderr_logger_mt("idms-server");
    l->set_pattern("%v");
    l->flush_on(spdlog::level::info);
    return l;
  }();
  return *logger;
}

// Text fields: control characters (a decoded %0A in a path, say) escaped, so one event is one line.
std::string Escaped(const std::string& v) {
  std::string out;
  for (unsigned char c : v) {
    if (c < 0x20 || c == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
  }
  return out;
}

}  // namespace

void SetLogFormat(const std::string& format) { g_json = format == "json"; }

void Log(LogLevel level, const std::string& message, const nlohmann::ordered_json& fields) {
  const char* name = level == LogLevel::kInfo ? "info" : level == LogLevel::kWarn ? "warn" : "error";
  std::string line;
  if (g_json) {
    nlohmann::ordered_json j{{"time", UtcNowMs()}, {"level", name}, {"msg", message}};
    for (const auto& [k, v] : fields.items()) j[k] = v;
    line = j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  } else {
    line = UtcNowMs() + " " + name + " " + message;
    for (const auto& [k, v] : fields.items()) {
      line += " " + k + "=" + Escaped(v.is_string() ? v.get<std::string>() : v.dump());
    }
  }
  Logger().info(line);
}

}  // namespace idms::server
