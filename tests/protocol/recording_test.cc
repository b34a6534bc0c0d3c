// RecordingWriter and RecordingReader (protocol/src/recording.cc): a simulated session recorded
// and read back; seek-to-time rebuilding the mesh from the latest keyframe, with a device history;
// the agent's device-only reading; a crashed recording; schemas Foxglove can decode. Also keeps the seeds of
// tests/fuzz/corpus/mcap_fuzz (rewritten with IDMS_WRITE_FUZZ_SEEDS=1) and writes the recording
// tests/protocol/mcap_check.py checks.
#include "idms/protocol/recording.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "idms/protocol/envelope.h"
#include "idms/protocol/mesh_mirror.h"
#include "idms/sim/generate.h"

namespace idms {
namespace {

namespace fs = std::filesystem;

constexpr uint64_t kT0 = 1'700'000'000'000'000'000;  // Unix ns, as the server records

std::string TempPath(const std::string& name) {
  return (fs::path(testing::TempDir()) / ("idms_recording_" + std::to_string(::getpid()) + "_" + name)).string();
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string bytes(fs::file_size(path), '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return bytes;
}

struct Frame {
  RecordingTopic topic;
  uint64_t log_ns;
  std::string envelope;  // serialized
};

// A session as the server would see it: device batches every 20 ms, mesh frames at 60 Hz from the
// codec (a dent moving over a slab, keyframes every keyframe_s), events now and then.
std::vector<v1::Envelope> SessionFrames(double seconds, double keyframe_s, std::vector<uint64_t>* log_ns) {
  SlabOptions slab;
  slab.rows = 5;
  slab.cols = 4;
  const Model model = GenerateSlab(slab);
  std::vector<double> rest(3 * model.external_atoms.size());
  GatherSurface(model, model.atom_pos_eq, rest);
  EncoderOptions encoder_options;
  encoder_options.keyframe_interval_s = keyframe_s;
  MeshEncoder encoder(encoder_options);
  encoder.SetTopology(1, SurfaceTriangles(model));
  std::vector<v1::Envelope> frames;
  const int ticks = static_cast<int>(seconds * 1000);
  v1::Envelope batch;
  for (int tick = 0; tick < ticks; ++tick) {
    const double t = tick * 1e-3;
    const uint64_t now = kT0 + uint64_t(tick) * 1'000'000;
    // Device: a sample per tick, sent every 20.
    v1::DeviceSample* s = batch.mutable_device_samples()->add_samples();
    s->set_tick(static_cast<uint64_t>(tick));
    s->set_time_s(t);
    s->mutable_tool_pos()->set_x(0.5 + t);
    s->mutable_force()->set_z(-0.1 * t);
    if (tick % 20 == 19) {
      frames.push_back(batch);
      log_ns->push_back(now);
      batch.Clear();
    }
    // Mesh at 60 Hz.
    if (tick % 17 == 0) {
      std::vector<double> p = rest;
      for (size_t i = 0; i < p.size(); i += 3) {
        const double dx = p[i] - (0.5 + t), dy = p[i + 1] - 1.5;
        p[i + 2] -= 0.3 * std::exp(-(dx * dx + dy * dy) / 1.2);
      }
      v1::Envelope env;
      std::string error;
      EXPECT_TRUE(encoder.Encode(t, p, &env, &error)) << error;
      frames.push_back(env);
      log_ns->push_back(now);
    }
    // Events.
    if (tick % 250 == 0) {
      v1::Envelope env;
      env.mutable_session_event()->set_kind(tick == 0 ? v1::SessionEvent::KIND_STARTED
                                                      : v1::SessionEvent::KIND_STABILITY_FALLBACK);
      env.mutable_session_event()->set_tick(static_cast<uint64_t>(tick));
      frames.push_back(env);
      log_ns->push_back(now);
    }
    if (tick == 700) {
      v1::Envelope env;
      env.mutable_topology_event()->set_kind(v1::TopologyEvent::KIND_GRASP);
      env.mutable_topology_event()->set_tick(static_cast<uint64_t>(tick));
      frames.push_back(env);
      log_ns->push_back(now);
    }
  }
  return frames;
}

RecordingTopic TopicOf(const v1::Envelope& env) {
  if (env.has_device_samples()) return RecordingTopic::kDevice;
  if (env.has_mesh_keyframe() || env.has_mesh_delta()) return RecordingTopic::kMesh;
  return RecordingTopic::kEvents;
}

// Records a session; returns what was written, in order.
std::vector<Frame> Record(const std::string& path, double seconds, const RecordingWriterOptions& options,
                          double keyframe_s = 0.5) {
  std::vector<uint64_t> log_ns;
  const std::vector<v1::Envelope> frames = SessionFrames(seconds, keyframe_s, &log_ns);
  RecordingWriter writer;
  std::string error;
  EXPECT_TRUE(writer.Open(path, options, &error)) << error;
  std::vector<Frame> written;
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_TRUE(writer.Write(frames[i], log_ns[i], log_ns[i] + 1000, &error)) << error;
    std::string bytes;
    SerializeEnvelope(frames[i], &bytes);
    written.push_back({TopicOf(frames[i]), log_ns[i], bytes});
  }
  EXPECT_TRUE(writer.Close(&error)) << error;
  return written;
}

RecordingWriterOptions DefaultOptions() {
  RecordingWriterOptions options;
  options.session = {{"session_id", "s-42"}, {"scene", "model: \"hex_4x5_home\""}};
  return options;
}

std::vector<RecordedMessage> ReadAll(RecordingReader& reader, std::string* error) {
  std::vector<RecordedMessage> out;
  RecordedMessage m;
  while (reader.Next(&m, error)) out.push_back(m);
  return out;
}

TEST(Recording, RoundTripOfASession) {
  const std::string path = TempPath("session.mcap");
  const std::vector<Frame> written = Record(path, 3.0, DefaultOptions());
  RecordingReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, RecordingReaderOptions{}, &error)) << error;
  EXPECT_EQ(reader.session().at("session_id"), "s-42");
  EXPECT_EQ(reader.start_ns(), kT0);
  const std::vector<RecordedMessage> read = ReadAll(reader, &error);
  EXPECT_EQ(error, "");
  ASSERT_EQ(read.size(), written.size());
  for (size_t i = 0; i < read.size(); ++i) {
    std::string bytes;
    SerializeEnvelope(read[i].envelope, &bytes);
    EXPECT_EQ(read[i].topic, written[i].topic) << i;
    EXPECT_EQ(read[i].log_time_ns, written[i].log_ns) << i;
    EXPECT_EQ(read[i].publish_time_ns, written[i].log_ns + 1000) << i;
    EXPECT_FALSE(read[i].catch_up);
    EXPECT_EQ(bytes, written[i].envelope) << i;
  }
  // Channels and schemas as documented.
  const McapReader& mcap = reader.mcap();
  ASSERT_NE(mcap.FindChannel("/device"), nullptr);
  EXPECT_EQ(mcap.FindSchema(mcap.FindChannel("/device")->schema_id)->name, "idms.v1.DeviceSamples");
  EXPECT_EQ(mcap.FindSchema(mcap.FindChannel("/mesh")->schema_id)->name, "idms.v1.Envelope");
  EXPECT_EQ(mcap.FindSchema(mcap.FindChannel("/events")->schema_id)->name, "idms.v1.Envelope");
  EXPECT_EQ(mcap.FindChannel("/mesh")->message_encoding, "protobuf");
}

// What Foxglove does with a protobuf schema: build the messages from the FileDescriptorSet alone.
TEST(Recording, SchemasAreSelfContainedFileDescriptorSets) {
  const std::string path = TempPath("schemas.mcap");
  Record(path, 0.1, DefaultOptions());
  McapReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, McapReaderOptions{}, &error)) << error;
  for (const auto& [id, schema] : reader.schemas()) {
    EXPECT_EQ(schema.encoding, "protobuf");
    google::protobuf::FileDescriptorSet set;
    ASSERT_TRUE(set.ParseFromString(schema.data));
    google::protobuf::DescriptorPool pool;
    for (const auto& file : set.file()) ASSERT_NE(pool.BuildFile(file), nullptr) << file.name();
    const google::protobuf::Descriptor* d = pool.FindMessageTypeByName(schema.name);
    ASSERT_NE(d, nullptr) << schema.name;
    EXPECT_NE(d->FindFieldByName(schema.name == "idms.v1.Envelope" ? "mesh_delta" : "samples"), nullptr);
  }
}

TEST(Recording, SeekRebuildsTheMeshFromTheLatestKeyframe) {
  const std::string path = TempPath("seek.mcap");
  RecordingWriterOptions options = DefaultOptions();
  options.mcap.chunk_max_age_ns = 200'000'000;  // several chunks between keyframes
  const std::vector<Frame> written = Record(path, 3.0, options, 0.7);
  RecordingReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, RecordingReaderOptions{}, &error)) << error;
  for (const double t_s : {0.0, 0.3, 0.69, 1.234, 2.5, 2.999, 4.0}) {
    const uint64_t t = kT0 + static_cast<uint64_t>(t_s * 1e9);
    ASSERT_TRUE(reader.Seek(t, &error)) << error;
    const std::vector<RecordedMessage> read = ReadAll(reader, &error);
    ASSERT_EQ(error, "");
    // Catch-up: a keyframe, then the deltas and the /device samples since it, all before t; then
    // everything from t on.
    size_t n = 0;
    std::vector<std::string> caught_samples, expected_samples;
    while (n < read.size() && read[n].catch_up) {
      EXPECT_TRUE(read[n].topic == RecordingTopic::kMesh || read[n].topic == RecordingTopic::kDevice);
      EXPECT_LT(read[n].log_time_ns, t);
      EXPECT_EQ(read[n].envelope.has_mesh_keyframe(), n == 0);
      if (read[n].topic == RecordingTopic::kDevice) SerializeEnvelope(read[n].envelope, &caught_samples.emplace_back());
      ++n;
    }
    for (const Frame& f : written) {
      if (n > 0 && f.topic == RecordingTopic::kDevice && f.log_ns >= read[0].log_time_ns && f.log_ns < t) {
        expected_samples.push_back(f.envelope);
      }
    }
    EXPECT_EQ(caught_samples, expected_samples) << "t = " << t_s;
    std::vector<std::string> after, expected_after;
    for (size_t i = n; i < read.size(); ++i) {
      EXPECT_GE(read[i].log_time_ns, t);
      SerializeEnvelope(read[i].envelope, &after.emplace_back());
    }
    for (const Frame& f : written) {
      if (f.log_ns >= t) expected_after.push_back(f.envelope);
    }
    EXPECT_EQ(after, expected_after) << "t = " << t_s;
    // The mirror after the catch-up and the frames at t equals one fed everything up to t.
    MeshMirror seeked, full;
    for (size_t i = 0; i < read.size() && (read[i].catch_up || read[i].log_time_ns == t); ++i) {
      if (read[i].topic == RecordingTopic::kMesh) {
        EXPECT_EQ(seeked.Apply(read[i].envelope, &error), MirrorStatus::kOk) << error;
      }
    }
    for (const Frame& f : written) {
      v1::Envelope env;
      ASSERT_TRUE(ParseEnvelope(f.envelope, &env, &error));
      if (f.log_ns <= t && f.topic == RecordingTopic::kMesh) {
        ASSERT_EQ(full.Apply(env, &error), MirrorStatus::kOk) << error;
      }
    }
    EXPECT_EQ(seeked.sequence(), full.sequence()) << "t = " << t_s;
    EXPECT_TRUE(std::ranges::equal(seeked.quantized(), full.quantized())) << "t = " << t_s;
  }
}

// "N frames logged from A to B ms" (after kT0): what a catch-up holds, short enough to read.
std::string Span(const std::vector<uint64_t>& log_ns) {
  if (log_ns.empty()) return "none";
  return std::to_string(log_ns.size()) + " frames logged from " + std::to_string((log_ns.front() - kT0) / 1'000'000) +
         " to " + std::to_string((log_ns.back() - kT0) / 1'000'000) + " ms";
}

// The catch-up with a device history longer than the keyframe interval (the server asks for its
// viewer's 5 s plot window): /device from t - history on, /mesh only from the keyframe at or before
// t, no events; each topic in log-time order, the keyframe before any delta.
TEST(Recording, SeekReplaysTheDeviceHistory) {
  const std::string path = TempPath("history.mcap");
  RecordingWriterOptions writer_options = DefaultOptions();
  writer_options.mcap.chunk_max_age_ns = 200'000'000;
  const std::vector<Frame> written = Record(path, 6.0, writer_options, 1.0);
  constexpr uint64_t kHistoryNs = 2'500'000'000;
  RecordingReaderOptions options;
  options.device_history_ns = kHistoryNs;
  RecordingReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, options, &error)) << error;
  for (const double t_s : {0.0, 0.4, 1.7, 3.25, 4.0, 5.999, 7.0}) {
    const uint64_t t = kT0 + static_cast<uint64_t>(t_s * 1e9);
    ASSERT_TRUE(reader.Seek(t, &error)) << error;
    const std::vector<RecordedMessage> read = ReadAll(reader, &error);
    ASSERT_EQ(error, "");
    // What it should be, from what was written: the latest keyframe at or before t, and the
    // catch-up's /device start.
    uint64_t keyframe_ns = t;
    for (const Frame& f : written) {
      v1::Envelope env;
      ASSERT_TRUE(ParseEnvelope(f.envelope, &env, &error));
      if (f.log_ns <= t && env.has_mesh_keyframe()) keyframe_ns = f.log_ns;
    }
    const uint64_t device_from = std::min(keyframe_ns, t > kT0 + kHistoryNs ? t - kHistoryNs : kT0);
    std::map<RecordingTopic, std::vector<std::string>> caught, expected_caught;
    std::map<RecordingTopic, std::vector<uint64_t>> caught_ns, expected_ns;
    for (const Frame& f : written) {
      const bool in = f.topic == RecordingTopic::kDevice ? f.log_ns >= device_from
                      : f.topic == RecordingTopic::kMesh ? f.log_ns >= keyframe_ns
                                                         : false;
      if (in && f.log_ns < t) {
        expected_caught[f.topic].push_back(f.envelope);
        expected_ns[f.topic].push_back(f.log_ns);
      }
    }
    // The catch-up: before t, in log-time order, the first /mesh frame a keyframe.
    size_t n = 0;
    for (; n < read.size() && read[n].catch_up; ++n) {
      EXPECT_LT(read[n].log_time_ns, t);
      EXPECT_GE(read[n].log_time_ns, n > 0 ? read[n - 1].log_time_ns : 0);
      std::vector<std::string>& topic = caught[read[n].topic];
      EXPECT_TRUE(read[n].topic != RecordingTopic::kMesh || read[n].envelope.has_mesh_keyframe() == topic.empty());
      SerializeEnvelope(read[n].envelope, &topic.emplace_back());
      caught_ns[read[n].topic].push_back(read[n].log_time_ns);
    }
    for (const RecordingTopic topic : {RecordingTopic::kDevice, RecordingTopic::kMesh, RecordingTopic::kEvents}) {
      EXPECT_EQ(Span(caught_ns[topic]), Span(expected_ns[topic])) << "t = " << t_s << ", topic " << int(topic);
    }
    EXPECT_TRUE(caught == expected_caught) << "t = " << t_s;
    // Past the first keyframe interval the plots' history reaches t - history, before the keyframe.
    if (t_s > 3) {
      ASSERT_FALSE(caught[RecordingTopic::kDevice].empty());
      v1::Envelope first;
      ASSERT_TRUE(ParseEnvelope(caught[RecordingTopic::kDevice][0], &first, &error));
      EXPECT_NEAR(first.device_samples().samples(0).time_s(), t_s - kHistoryNs * 1e-9, 0.021) << "t = " << t_s;
      EXPECT_GT(keyframe_ns, device_from) << "t = " << t_s;
    }
    // Then every topic from t on.
    std::vector<std::string> after, expected_after;
    for (size_t i = n; i < read.size(); ++i) {
      EXPECT_FALSE(read[i].catch_up);
      SerializeEnvelope(read[i].envelope, &after.emplace_back());
    }
    for (const Frame& f : written) {
      if (f.log_ns >= t) expected_after.push_back(f.envelope);
    }
    EXPECT_EQ(after, expected_after) << "t = " << t_s;
  }
  // Without /mesh (no keyframe to start from), the history alone.
  options.mesh = false;
  ASSERT_TRUE(reader.Open(path, options, &error)) << error;
  const uint64_t t = kT0 + 4'000'000'000;
  ASSERT_TRUE(reader.Seek(t, &error)) << error;
  const std::vector<RecordedMessage> read = ReadAll(reader, &error);
  ASSERT_FALSE(read.empty());
  EXPECT_TRUE(read[0].catch_up);
  EXPECT_EQ(read[0].topic, RecordingTopic::kDevice);
  EXPECT_GE(read[0].log_time_ns, t - kHistoryNs);
  EXPECT_LT(read[0].log_time_ns, t - kHistoryNs + 20'000'000);
}

TEST(Recording, DeviceOnlyForTheAgentsReplay) {
  const std::string path = TempPath("device.mcap");
  const std::vector<Frame> written = Record(path, 1.0, DefaultOptions());
  RecordingReaderOptions options;
  options.mesh = options.events = false;
  RecordingReader reader;
  std::string error;
  ASSERT_TRUE(reader.Open(path, options, &error)) << error;
  const size_t batches =
      std::count_if(written.begin(), written.end(), [](const Frame& f) { return f.topic == RecordingTopic::kDevice; });
  std::vector<RecordedMessage> read = ReadAll(reader, &error);
  ASSERT_EQ(read.size(), batches);
  uint64_t tick = 0;
  for (const RecordedMessage& m : read) {
    ASSERT_EQ(m.topic, RecordingTopic::kDevice);
    for (const v1::DeviceSample& s : m.envelope.device_samples().samples()) EXPECT_EQ(s.tick(), tick++);
  }
  // From the middle: the first batch at or after t, no catch-up.
  ASSERT_TRUE(reader.Seek(kT0 + 500'000'000, &error));
  read = ReadAll(reader, &error);
  ASSERT_FALSE(read.empty());
  EXPECT_EQ(read[0].log_time_ns, kT0 + 519'000'000);
  EXPECT_FALSE(read[0].catch_up);
}

TEST(Recording, CrashedRecordingIsReadable) {
  const std::string path = TempPath("crashed.mcap");
  std::vector<uint64_t> log_ns;
  const std::vector<v1::Envelope> frames = SessionFrames(2.5, 0.5, &log_ns);
  RecordingWriter writer;
  std::string error;
  ASSERT_TRUE(writer.Open(path, DefaultOptions(), &error)) << error;
  for (size_t i = 0; i < frames.size(); ++i) ASSERT_TRUE(writer.Write(frames[i], log_ns[i], log_ns[i], &error));
  ASSERT_TRUE(writer.Flush(log_ns.back(), &error));
  // Read while the writer is open, as after a crash: the two closed seconds.
  RecordingReader reader;
  ASSERT_TRUE(reader.Open(path, RecordingReaderOptions{}, &error)) << error;
  EXPECT_FALSE(reader.mcap().indexed());
  EXPECT_EQ(reader.session().at("session_id"), "s-42");
  const std::vector<RecordedMessage> read = ReadAll(reader, &error);
  EXPECT_EQ(error, "");
  EXPECT_GT(read.size(), frames.size() * 3 / 4);
  EXPECT_LT(read.size(), frames.size());
  for (size_t i = 0; i < read.size(); ++i) EXPECT_EQ(read[i].log_time_ns, log_ns[i]);
  EXPECT_TRUE(writer.Close(&error)) << error;
}

TEST(Recording, RefusesWhatItDoesNotRecordAndForeignChannels) {
  RecordingWriter writer;
  std::string error;
  ASSERT_TRUE(writer.Open(TempPath("refuse.mcap"), RecordingWriterOptions{}, &error)) << error;
  v1::Envelope hello;
  hello.mutable_hello()->set_protocol_version(kProtocolVersion);
  EXPECT_FALSE(writer.Write(hello, 1, 1, &error));
  EXPECT_NE(error.find("body hello is not recorded"), std::string::npos) << error;
  // An MCAP file whose /mesh carries something else.
  const std::string path = TempPath("foreign.mcap");
  McapWriter mcap;
  ASSERT_TRUE(mcap.Open(path, McapWriterOptions{}, &error));
  const uint16_t schema = mcap.AddSchema("foo.Bar", "protobuf", "", &error);
  mcap.AddChannel(schema, "/mesh", "protobuf", {}, &error);
  ASSERT_TRUE(mcap.Close(&error));
  RecordingReader reader;
  EXPECT_FALSE(reader.Open(path, RecordingReaderOptions{}, &error));
  EXPECT_EQ(error, path +
                       ": channel /mesh: message encoding protobuf, schema foo.Bar (protobuf); expected protobuf, "
                       "schema idms.v1.Envelope (protobuf)");
}

// ---------------------------------------------------------------------------------------------
// Files for other checks.

// The seeds of tests/fuzz/corpus/mcap_fuzz: small real recordings, zstd and not, and one cut short.
std::map<std::string, std::string> Seeds() {
  std::map<std::string, std::string> seeds;
  for (const bool compress : {false, true}) {
    RecordingWriterOptions options = DefaultOptions();
    options.mcap.compress = compress;
    options.mcap.chunk_max_age_ns = 100'000'000;
    const std::string path = TempPath("seed.mcap");
    Record(path, 0.35, options, 0.15);
    seeds[compress ? "recording_zstd" : "recording"] = ReadFile(path);
  }
  // Cut in the middle of its third chunk, as a crash would leave it.
  const std::string& zstd = seeds["recording_zstd"];
  McapReader reader;
  std::string error;
  EXPECT_TRUE(reader.OpenBuffer(zstd, "seed", McapReaderOptions{}, &error)) << error;
  std::vector<McapChunkInfo> chunks = reader.chunks();
  std::sort(chunks.begin(), chunks.end(), [](const auto& a, const auto& b) { return a.offset < b.offset; });
  EXPECT_GE(chunks.size(), 3u);
  if (chunks.size() >= 3) seeds["recording_cut"] = zstd.substr(0, chunks[2].offset + chunks[2].length / 2);
  return seeds;
}

TEST(Recording, FuzzSeedsMatchTheCurrentFormat) {
  const fs::path dir = fs::path(IDMS_SOURCE_DIR) / "tests/fuzz/corpus/mcap_fuzz";
  const std::map<std::string, std::string> seeds = Seeds();
  if (std::getenv("IDMS_WRITE_FUZZ_SEEDS") != nullptr) {
    fs::create_directories(dir);
    for (const auto& [name, bytes] : seeds) std::ofstream(dir / (name + ".mcap"), std::ios::binary) << bytes;
  }
  for (const auto& [name, bytes] : seeds) {
    ASSERT_LT(bytes.size(), 65536u) << name << ": beyond the fuzzer's -max_len";
    const fs::path seed = dir / (name + ".mcap");
    ASSERT_TRUE(fs::exists(seed)) << seed << " missing; run with IDMS_WRITE_FUZZ_SEEDS=1";
    RecordingReader reader;
    std::string error;
    ASSERT_TRUE(reader.Open(seed.string(), RecordingReaderOptions{}, &error)) << error;
    EXPECT_EQ(reader.mcap().indexed(), name != "recording_cut") << name;
    EXPECT_GT(ReadAll(reader, &error).size(), 10u) << name;
    EXPECT_EQ(error, "") << name;
  }
}

// For tests/protocol/mcap_check.py (CTest fixture mcap.write_check_files).
TEST(RecordingCheck, WriteFiles) {
  const char* dir = std::getenv("IDMS_MCAP_CHECK_DIR");
  if (dir == nullptr) GTEST_SKIP() << "IDMS_MCAP_CHECK_DIR not set";
  fs::create_directories(dir);
  RecordingWriterOptions options = DefaultOptions();
  options.mcap.compress = false;
  Record((fs::path(dir) / "recording.mcap").string(), 2.0, options);
  options.mcap.compress = true;
  Record((fs::path(dir) / "recording_zstd.mcap").string(), 2.0, options);
}

}  // namespace
}  // namespace idms
