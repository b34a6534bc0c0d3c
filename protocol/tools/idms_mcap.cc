// idms-mcap: what is in an MCAP file (a session recording or any other): channels, message counts,
// time range, chunks, metadata; and whether it was finished or had to be recovered by a scan.
#include <CLI/CLI.hpp>
#include <cinttypes>
#include <cstdio>
#include <iostream>
#include <string>

#include "idms/protocol/cli.h"
#include "idms/protocol/mcap.h"

namespace {

// Log times as seconds.nanoseconds (Unix time for idms recordings).
std::string Time(uint64_t ns) {
  char buffer[48];
  std::snprintf(buffer, sizeof buffer, "%" PRIu64 ".%09" PRIu64, ns / 1'000'000'000, ns % 1'000'000'000);
  return buffer;
}

std::string Bytes(uint64_t n) {
  char buffer[32];
  if (n < 10'000) {
    std::snprintf(buffer, sizeof buffer, "%" PRIu64 " B", n);
  } else if (n < 10'000'000) {
    std::snprintf(buffer, sizeof buffer, "%.1f kB", n / 1e3);
  } else {
    std::snprintf(buffer, sizeof buffer, "%.1f MB", n / 1e6);
  }
  return buffer;
}

std::string Shorten(const std::string& s, size_t max) {
  std::string one_line = s.substr(0, s.find('\n'));
  if (one_line.size() > max || one_line.size() < s.size()) {
    return one_line.substr(0, max) + "... (" + std::to_string(s.size()) + " bytes)";
  }
  return one_line;
}

int Info(const std::string& path, uint64_t max_bytes, bool scan) {
  idms::McapReaderOptions options;
  options.max_file_bytes = max_bytes;
  options.use_summary = !scan;
  idms::McapReader reader;
  std::string error;
  if (!reader.Open(path, options, &error)) {
    std::cerr << "idms-mcap info: " << error << "\n";
    return 1;
  }
  // File, index, totals.
  const idms::McapStatistics& stats = reader.statistics();
  std::printf("file       %s\n", path.c_str());
  std::printf("library    %s\n", reader.library().c_str());
  std::printf("profile    %s\n", reader.profile().empty() ? "(none)" : reader.profile().c_str());
  if (reader.indexed()) {
    std::printf("index      summary (finished file)\n");
  } else if (!reader.index_note().empty()) {
    std::printf("index      summary not used (%s): scanned\n", reader.index_note().c_str());
  } else if (reader.recovery_note().empty()) {
    std::printf("index      none: scanned\n");
  } else {
    std::printf("index      none: unfinished file, recovered by a scan\n");
    std::printf("recovery   %s\n", reader.recovery_note().c_str());
  }
  std::printf("messages   %" PRIu64 "\n", stats.num_messages);
  if (stats.num_messages > 0) {
    std::printf("start      %s\n", Time(stats.start_ns).c_str());
    std::printf("end        %s\n", Time(stats.end_ns).c_str());
    std::printf("duration   %.3f s\n", (stats.end_ns - stats.start_ns) * 1e-9);
  }
  // Chunks.
  uint64_t compressed = 0, uncompressed = 0, zstd = 0, loose = 0;
  for (const idms::McapChunkInfo& chunk : reader.chunks()) {
    if (chunk.loose) {
      ++loose;
      continue;
    }
    compressed += chunk.compressed_bytes;
    uncompressed += chunk.uncompressed_bytes;
    zstd += chunk.compression == "zstd";
  }
  const uint64_t num_chunks = reader.chunks().size() - loose;
  std::printf("chunks     %" PRIu64 " (zstd %" PRIu64 ", uncompressed %" PRIu64 "), %s stored, %s of records\n",
              num_chunks, zstd, num_chunks - zstd, Bytes(compressed).c_str(), Bytes(uncompressed).c_str());
  if (loose > 0) std::printf("loose      %" PRIu64 " runs of messages outside chunks\n", loose);
  // Channels.
  std::printf("channels   %zu\n", reader.channels().size());
  for (const auto& [id, channel] : reader.channels()) {
    const idms::McapSchema* schema = reader.FindSchema(channel.schema_id);
    const auto it = stats.channels.find(id);
    const idms::McapChannelStats s = it == stats.channels.end() ? idms::McapChannelStats{} : it->second;
    std::printf("  %-3u %-12s %-24s %-9s %8" PRIu64 " msgs", id, channel.topic.c_str(),
                schema == nullptr ? "(no schema)" : schema->name.c_str(), channel.message_encoding.c_str(),
                s.num_messages);
    if (s.num_messages > 0 && s.end_ns > 0) {
      std::printf("  %s .. %s", Time(s.start_ns).c_str(), Time(s.end_ns).c_str());
    }
    std::printf("\n");
  }
  // Metadata.
  for (const auto& [name, map] : reader.metadata()) {
    std::printf("metadata   %s\n", name.c_str());
    for (const auto& [key, value] : map) std::printf("  %-16s %s\n", key.c_str(), Shorten(value, 60).c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"idms-mcap: inspect MCAP files (idms session recordings or any other)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", idms::Version());
  std::string path;
  uint64_t max_bytes = uint64_t{1} << 40;
  bool scan = false;
  CLI::App* info = app.add_subcommand("info", "channels, message counts, time range, chunks and metadata of FILE");
  info->add_option("FILE", path, "an .mcap file")->required();
  info->add_option("--max-bytes", max_bytes, "refuse files larger than this")->capture_default_str();
  info->add_flag("--scan", scan, "ignore the summary and read every chunk (checks all CRCs)");
  int status = 0;
  info->callback([&]() { status = Info(path, max_bytes, scan); });
  CLI11_PARSE(app, argc, argv);
  return status;
}
