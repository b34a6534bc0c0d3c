// libFuzzer target: McapReader and RecordingReader must open or reject any input cleanly (with a
// message), never crash or over-allocate, and return messages in log-time order within the range
// and channels asked for; a file read whole both through its summary and by a scan yields as many
// messages either way. Each input is read through its summary and by a scan, then seeked to its
// middle; the seeds (tests/fuzz/corpus/mcap_fuzz) are real recordings, whole and cut short, and
// files of the MCAP conformance suite.
#include <google/protobuf/stubs/logging.h>

#include <cstddef>
#include <cstdint>
#include <string>

#include "idms/protocol/mcap.h"
#include "idms/protocol/recording.h"

namespace {

// Small enough to keep every input fast, large enough for the seeds.
idms::McapReaderOptions FuzzOptions(bool use_summary) {
  idms::McapReaderOptions options;
  options.max_file_bytes = 1 << 20;
  options.max_record_bytes = 1 << 18;
  options.use_summary = use_summary;
  return options;
}

// Reads [start, end] on `channel` (0 = all); every message must respect the order and the filter.
uint64_t ReadRange(idms::McapReader& reader, uint64_t start, uint64_t end, uint16_t channel, std::string* error) {
  const uint16_t only[] = {channel};
  reader.Seek(start, end, channel == 0 ? std::span<const uint16_t>() : std::span<const uint16_t>(only));
  idms::McapMessage m;
  uint64_t last = start, count = 0;
  while (reader.Next(&m, error)) {
    if (m.log_time_ns < last || m.log_time_ns > end) __builtin_trap();
    if (channel != 0 && m.channel_id != channel) __builtin_trap();
    if (reader.channels().count(m.channel_id) == 0) __builtin_trap();
    last = m.log_time_ns;
    ++count;
  }
  if (!error->empty() && error->find("byte ") == std::string::npos) __builtin_trap();  // errors say where
  return count;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  // Protobuf logs invalid UTF-8 in strings; that is expected here.
  google::protobuf::SetLogHandler(nullptr);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  std::string error;
  uint64_t read_whole[2] = {0, 0};  // messages of a complete, error-free read: scan, summary
  bool whole[2] = {false, false};
  for (const bool use_summary : {true, false}) {
    idms::McapReader reader;
    if (!reader.OpenBuffer(input, "fuzz", FuzzOptions(use_summary), &error)) {
      if (error.empty()) __builtin_trap();  // every rejection says why
      continue;
    }
    // Everything; a scan counted exactly what it returns.
    const uint64_t count = ReadRange(reader, 0, UINT64_MAX, 0, &error);
    if (!use_summary && error.empty() && count != reader.statistics().num_messages) __builtin_trap();
    read_whole[use_summary] = count;
    whole[use_summary] = error.empty() && reader.recovery_note().empty();
    // The second half of the time range, on one channel.
    const idms::McapStatistics& stats = reader.statistics();
    if (stats.num_messages > 0 && !reader.channels().empty()) {
      const uint64_t mid = stats.start_ns / 2 + stats.end_ns / 2;
      ReadRange(reader, mid, stats.end_ns, reader.channels().begin()->first, &error);
    }
  }
  // A finished file read whole through its summary yields what a scan yields: the index is used
  // only where it locates every message.
  if (whole[0] && whole[1] && read_whole[0] != read_whole[1]) __builtin_trap();
  // The recording on top: a seek to the middle replays the mesh from a keyframe.
  idms::RecordingReader recording;
  idms::RecordingReaderOptions options;
  options.mcap = FuzzOptions(true);
  if (recording.OpenBuffer(input, "fuzz", options, &error)) {
    const uint64_t mid = recording.start_ns() / 2 + recording.end_ns() / 2;
    if (recording.Seek(mid, &error)) {
      idms::RecordedMessage m;
      bool catching_up = true;
      while (recording.Next(&m, &error)) {
        if (m.catch_up && (!catching_up || m.log_time_ns >= mid)) __builtin_trap();
        if (!m.catch_up && m.log_time_ns < mid) __builtin_trap();
        catching_up = m.catch_up;
      }
    }
  } else if (error.empty()) {
    __builtin_trap();
  }
  return 0;
}
