// McapReader against the official MCAP conformance suite (tests/protocol/data/mcap-conformance,
// MIT, from github.com/foxglove/mcap): every file, through its summary and by a scan, yields the
// messages its JSON lists, record by record, and defines the schemas, channels and metadata it lists.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "idms/protocol/mcap.h"

namespace idms {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const fs::path kSuite = fs::path(IDMS_SOURCE_DIR) / "tests/protocol/data/mcap-conformance";

struct Msg {
  uint16_t channel = 0;
  std::string topic;
  uint32_t sequence = 0;
  uint64_t log_ns = 0;
  uint64_t publish_ns = 0;
  std::string data;
  bool operator==(const Msg&) const = default;
};

std::ostream& operator<<(std::ostream& os, const Msg& m) {
  return os << "{channel " << m.channel << " '" << m.topic << "', sequence " << m.sequence << ", log " << m.log_ns
            << ", publish " << m.publish_ns << ", " << m.data.size() << " bytes}";
}

// What the JSON beside a file lists: its records in file order, the definitions deduplicated (the
// summary may repeat them).
struct Expected {
  std::vector<Msg> messages;
  std::map<uint16_t, McapSchema> schemas;
  std::map<uint16_t, McapChannel> channels;
  std::vector<std::pair<std::string, std::map<std::string, std::string>>> metadata;
  std::set<std::string> features;
};

// The JSON writes integers as decimal strings and bytes as arrays of them.
uint64_t Number(const json& v) { return std::stoull(v.get<std::string>()); }

std::string Bytes(const json& v) {
  std::string out;
  for (const json& b : v) out.push_back(static_cast<char>(Number(b)));
  return out;
}

std::map<std::string, std::string> StringMap(const json& v) {
  std::map<std::string, std::string> out;
  for (const auto& [key, value] : v.items()) out[key] = value.get<std::string>();
  return out;
}

Expected ReadExpected(const fs::path& path) {
  std::ifstream in(path);
  const json doc = json::parse(in);
  Expected e;
  for (const json& f : doc["meta"]["variant"]["features"]) e.features.insert(f.get<std::string>());
  for (const json& record : doc["records"]) {
    std::map<std::string, json> fields;
    for (const json& f : record["fields"]) fields[f[0].get<std::string>()] = f[1];
    const std::string type = record["type"].get<std::string>();
    if (type == "Schema") {
      const auto id = static_cast<uint16_t>(Number(fields["id"]));
      e.schemas[id] = McapSchema{id, fields["name"].get<std::string>(), fields["encoding"].get<std::string>(),
                                 Bytes(fields["data"])};
    } else if (type == "Channel") {
      const auto id = static_cast<uint16_t>(Number(fields["id"]));
      e.channels[id] =
          McapChannel{id, static_cast<uint16_t>(Number(fields["schema_id"])), fields["topic"].get<std::string>(),
                      fields["message_encoding"].get<std::string>(), StringMap(fields["metadata"])};
    } else if (type == "Message") {
      e.messages.push_back(Msg{static_cast<uint16_t>(Number(fields["channel_id"])), "",
                               static_cast<uint32_t>(Number(fields["sequence"])), Number(fields["log_time"]),
                               Number(fields["publish_time"]), Bytes(fields["data"])});
    } else if (type == "Metadata") {
      e.metadata.emplace_back(fields["name"].get<std::string>(), StringMap(fields["metadata"]));
    }
  }
  // The reader's order: log time, ties in file order.
  for (Msg& m : e.messages) m.topic = e.channels.at(m.channel).topic;
  std::stable_sort(e.messages.begin(), e.messages.end(),
                   [](const Msg& a, const Msg& b) { return a.log_ns < b.log_ns; });
  return e;
}

std::vector<fs::path> SuiteFiles() {
  std::vector<fs::path> out;
  for (const auto& entry : fs::recursive_directory_iterator(kSuite)) {
    if (entry.path().extension() == ".mcap") out.push_back(entry.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

void ExpectSameChannel(const McapChannel& a, const McapChannel& b) {
  EXPECT_EQ(a.schema_id, b.schema_id);
  EXPECT_EQ(a.topic, b.topic);
  EXPECT_EQ(a.message_encoding, b.message_encoding);
  EXPECT_EQ(a.metadata, b.metadata);
}

// One file, one way: the definitions, the statistics and every message.
void CheckFile(const fs::path& path, const Expected& expected, bool use_summary) {
  SCOPED_TRACE(path.filename().string() + (use_summary ? " through the summary" : " by a scan"));
  McapReaderOptions options;
  options.use_summary = use_summary;
  McapReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path.string(), options, &error)) << error;
  EXPECT_EQ(reader.recovery_note(), "");
  // Messages, record by record.
  std::vector<Msg> read;
  McapMessage m;
  while (reader.Next(&m, &error)) {
    const McapChannel* channel = &reader.channels().at(m.channel_id);
    read.push_back(
        Msg{m.channel_id, channel->topic, m.sequence, m.log_time_ns, m.publish_time_ns, std::string(m.data)});
  }
  ASSERT_EQ(error, "");
  ASSERT_EQ(read.size(), expected.messages.size());
  for (size_t i = 0; i < read.size(); ++i) EXPECT_EQ(read[i], expected.messages[i]) << "message " << i;
  // Statistics as Open() found them.
  EXPECT_EQ(reader.statistics().num_messages, expected.messages.size());
  std::map<uint16_t, uint64_t> per_channel;
  for (const Msg& e : expected.messages) ++per_channel[e.channel];
  for (const auto& [id, count] : per_channel) EXPECT_EQ(reader.statistics().channels.at(id).num_messages, count);
  // Definitions and metadata.
  ASSERT_EQ(reader.schemas().size(), expected.schemas.size());
  for (const auto& [id, s] : expected.schemas) {
    const McapSchema& r = reader.schemas().at(id);
    EXPECT_EQ(r.name, s.name);
    EXPECT_EQ(r.encoding, s.encoding);
    EXPECT_EQ(r.data, s.data);
  }
  ASSERT_EQ(reader.channels().size(), expected.channels.size());
  for (const auto& [id, c] : expected.channels) ExpectSameChannel(reader.channels().at(id), c);
  EXPECT_EQ(reader.metadata(), expected.metadata);
}

TEST(McapConformance, EveryFileYieldsItsRecords) {
  const std::vector<fs::path> files = SuiteFiles();
  ASSERT_EQ(files.size(), 416u) << "the suite in " << kSuite << " is incomplete";
  for (const fs::path& path : files) {
    const Expected expected = ReadExpected(fs::path(path).replace_extension(".json"));
    CheckFile(path, expected, true);
    CheckFile(path, expected, false);
  }
}

// The index is used where it can be trusted (what the MCAP project's own indexed readers require:
// chunks, message indexes, chunk indexes, channels and schemas repeated in the summary) and
// otherwise the reader says why it scanned.
TEST(McapConformance, IndexedWhereTheSummaryLocatesEveryMessage) {
  int num_indexed = 0;
  for (const fs::path& path : SuiteFiles()) {
    const Expected expected = ReadExpected(fs::path(path).replace_extension(".json"));
    const auto has = [&](const char* f) { return expected.features.count(f) > 0; };
    McapReader reader;
    std::string error;
    ASSERT_TRUE(reader.Open(path.string(), McapReaderOptions{}, &error)) << error;
    const bool complete =
        has("ch") && has("mx") && has("chx") && has("rch") && (has("rsh") || expected.schemas.empty());
    SCOPED_TRACE(path.filename().string());
    if (complete) {
      EXPECT_TRUE(reader.indexed()) << reader.index_note();
    } else if (!expected.messages.empty()) {
      EXPECT_FALSE(reader.indexed());
    }
    if (!reader.indexed()) {
      EXPECT_NE(reader.index_note(), "");
    }
    num_indexed += reader.indexed();
  }
  EXPECT_EQ(num_indexed, 52);
}

}  // namespace
}  // namespace idms
