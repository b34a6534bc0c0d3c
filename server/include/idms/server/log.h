// One log line per event, as text ("message key=value ...") or JSON ({"time", "level", "msg",
// ...fields}), through spdlog. Never pass a token, cookie or resume token as a field.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

namespace idms::server {

enum class LogLevel { kInfo, kWarn, kError };

// "text" or "json"; text by default.
void SetLogFormat(const std::string& format);
void Log(LogLevel level, const std::string& message,
         const nlohmann::ordered_json& fields = nlohmann::ordered_json::object());

}  // namespace idms::server
