// Session recordings: idms's channels on MCAP, and reading them back with seek-to-time that
// rebuilds the mesh from the latest keyframe and replays the device samples that led there.
#include "idms/protocol/recording.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>

#include <algorithm>
#include <limits>
#include <set>
#include <string>

#include "idms/protocol/envelope.h"

namespace idms {

namespace {

constexpr std::string_view kProtobuf = "protobuf";

void AddFile(const google::protobuf::FileDescriptor& file, std::set<std::string>& added,
             google::protobuf::FileDescriptorSet& set) {
  if (!added.insert(file.name()).second) return;
  for (int i = 0; i < file.dependency_count(); ++i) AddFile(*file.dependency(i), added, set);
  file.CopyTo(set.add_file());
}

}  // namespace

std::string FileDescriptorSetFor(const google::protobuf::Descriptor& message) {
  google::protobuf::FileDescriptorSet set;
  std::set<std::string> added;
  AddFile(*message.file(), added, set);
  return set.SerializeAsString();
}

// ---------------------------------------------------------------------------------------------
// RecordingWriter.

bool RecordingWriter::Open(const std::string& path, const RecordingWriterOptions& options, std::string* error) {
  if (!mcap_.Open(path, options.mcap, error)) return false;
  // Two schemas from the same file: DeviceSamples for /device, Envelope for /mesh and /events.
  const std::string descriptors = FileDescriptorSetFor(*v1::Envelope::descriptor());
  const uint16_t device_schema =
      mcap_.AddSchema(v1::DeviceSamples::descriptor()->full_name(), kProtobuf, descriptors, error);
  const uint16_t envelope_schema =
      device_schema == 0 ? 0 : mcap_.AddSchema(v1::Envelope::descriptor()->full_name(), kProtobuf, descriptors, error);
  if (envelope_schema == 0) return false;
  device_channel_ = mcap_.AddChannel(device_schema, kDeviceTopic, kProtobuf, {}, error);
  mesh_channel_ = mcap_.AddChannel(envelope_schema, kMeshTopic, kProtobuf, {}, error);
  events_channel_ = mcap_.AddChannel(envelope_schema, kEventsTopic, kProtobuf, {}, error);
  annotations_channel_ = mcap_.AddChannel(envelope_schema, kAnnotationsTopic, kProtobuf, {}, error);
  if (device_channel_ == 0 || mesh_channel_ == 0 || events_channel_ == 0 || annotations_channel_ == 0) return false;
  if (!options.session.empty() && !mcap_.AddMetadata(kSessionMetadataName, options.session, error)) return false;
  return mcap_.Flush(0, error);
}

bool RecordingWriter::Write(const v1::Envelope& envelope, uint64_t log_time_ns, uint64_t publish_time_ns,
                            std::string* error) {
  // The channel by body; /device stores the DeviceSamples itself, the others the whole frame.
  uint16_t channel = 0;
  bytes_.clear();
  switch (envelope.body_case()) {
    case v1::Envelope::kDeviceSamples:
      channel = device_channel_;
      envelope.device_samples().AppendToString(&bytes_);
      break;
    case v1::Envelope::kMeshKeyframe:
    case v1::Envelope::kMeshDelta:
      channel = mesh_channel_;
      envelope.AppendToString(&bytes_);
      break;
    case v1::Envelope::kSessionEvent:
    case v1::Envelope::kTopologyEvent:
      channel = events_channel_;
      envelope.AppendToString(&bytes_);
      break;
    case v1::Envelope::kAnnotation:
      channel = annotations_channel_;
      envelope.AppendToString(&bytes_);
      break;
    default:
      if (error != nullptr) {
        *error = std::string("recording: a frame with body ") + EnvelopeBodyName(envelope) +
                 " is not recorded (only device_samples, mesh_keyframe, mesh_delta, session_event, topology_event, "
                 "annotation)";
      }
      return false;
  }
  return mcap_.Write(channel, log_time_ns, publish_time_ns, bytes_, error);
}

// ---------------------------------------------------------------------------------------------
// RecordingReader.

bool RecordingReader::Open(const std::string& path, const RecordingReaderOptions& options, std::string* error) {
  name_ = path;
  return mcap_.Open(path, options.mcap, error) && Setup(options, error);
}

bool RecordingReader::OpenBuffer(std::string bytes, std::string_view name, const RecordingReaderOptions& options,
                                 std::string* error) {
  name_ = std::string(name);
  return mcap_.OpenBuffer(std::move(bytes), name, options.mcap, error) && Setup(options, error);
}

bool RecordingReader::Setup(const RecordingReaderOptions& options, std::string* error) {
  options_ = options;
  // Each channel present must carry the schema this file format gives it.
  const auto find = [&](std::string_view topic, std::string_view schema_name, uint16_t* id) {
    *id = 0;
    const McapChannel* channel = mcap_.FindChannel(topic);
    if (channel == nullptr) return true;
    const McapSchema* schema = mcap_.FindSchema(channel->schema_id);
    if (channel->message_encoding != kProtobuf || schema == nullptr || schema->name != schema_name ||
        schema->encoding != kProtobuf) {
      if (error != nullptr) {
        *error = name_ + ": channel " + std::string(topic) + ": message encoding " + channel->message_encoding +
                 ", schema " +
                 (schema == nullptr ? std::string("none") : schema->name + " (" + schema->encoding + ")") +
                 "; expected protobuf, schema " + std::string(schema_name) + " (protobuf)";
      }
      return false;
    }
    *id = channel->id;
    return true;
  };
  if (!find(kDeviceTopic, v1::DeviceSamples::descriptor()->full_name(), &device_channel_) ||
      !find(kMeshTopic, v1::Envelope::descriptor()->full_name(), &mesh_channel_) ||
      !find(kEventsTopic, v1::Envelope::descriptor()->full_name(), &events_channel_) ||
      !find(kAnnotationsTopic, v1::Envelope::descriptor()->full_name(), &annotations_channel_)) {
    return false;
  }
  session_.clear();
  for (const auto& [name, map] : mcap_.metadata()) {
    if (name == kSessionMetadataName) session_ = map;
  }
  selected_.clear();
  if (options_.device && device_channel_ != 0) selected_.push_back(device_channel_);
  if (options_.mesh && mesh_channel_ != 0) selected_.push_back(mesh_channel_);
  if (options_.events && events_channel_ != 0) selected_.push_back(events_channel_);
  if (options_.annotations && annotations_channel_ != 0) selected_.push_back(annotations_channel_);
  return Seek(0, error);
}

bool RecordingReader::Seek(uint64_t t_ns, std::string* error) {
  if (error != nullptr) error->clear();
  seek_ns_ = t_ns;
  mesh_from_ns_ = t_ns;
  awaiting_keyframe_ = false;
  if (selected_.empty()) return true;  // no selected topic in the file: Next() reads nothing
  // With /mesh, the catch-up's /mesh frames start at the latest keyframe at or before t.
  if (options_.mesh && mesh_channel_ != 0 && t_ns > 0) {
    std::string find_error;
    uint64_t keyframe_ns = 0;
    if (FindKeyframe(t_ns, &keyframe_ns, &find_error)) {
      mesh_from_ns_ = keyframe_ns;
      awaiting_keyframe_ = true;
    } else if (!find_error.empty()) {
      if (error != nullptr) *error = find_error;
      return false;
    }
  }
  // Its /device batches at that keyframe or device_history_ns back, whichever is earlier, but not
  // before the start.
  const uint64_t since_start = t_ns > start_ns() ? t_ns - start_ns() : 0;
  device_from_ns_ = std::min(t_ns - std::min(since_start, options_.device_history_ns), mesh_from_ns_);
  // One merged read from the earlier of the two: Next() drops what comes before its topic's start
  // by log time alone, without parsing it.
  mcap_.Seek(options_.device && device_channel_ != 0 ? device_from_ns_ : mesh_from_ns_,
             std::numeric_limits<uint64_t>::max(), selected_);
  return true;
}

bool RecordingReader::FindKeyframe(uint64_t t_ns, uint64_t* keyframe_ns, std::string* error) {
  // Windows [chunk start, hi] back from t, one per distinct chunk start holding /mesh frames.
  std::vector<uint64_t> starts;
  for (const McapChunkInfo& chunk : mcap_.chunks()) {
    const bool has_mesh = std::binary_search(chunk.channels.begin(), chunk.channels.end(), mesh_channel_);
    if (has_mesh && chunk.message_start_ns <= t_ns) starts.push_back(chunk.message_start_ns);
  }
  std::sort(starts.begin(), starts.end());
  starts.erase(std::unique(starts.begin(), starts.end()), starts.end());
  const uint16_t mesh[] = {mesh_channel_};
  uint64_t hi = t_ns;
  v1::Envelope envelope;
  for (auto it = starts.rbegin(); it != starts.rend(); ++it) {
    // The last keyframe of a window is the latest overall: later windows held none.
    mcap_.Seek(*it, hi, mesh);
    bool found = false;
    McapMessage m;
    while (mcap_.Next(&m, error)) {
      // An unparsable frame is reported when read, not here.
      if (ParseEnvelope(m.data, &envelope, nullptr, std::numeric_limits<int64_t>::max()) &&
          envelope.has_mesh_keyframe()) {
        *keyframe_ns = m.log_time_ns;
        found = true;
      }
    }
    if (!error->empty()) return false;
    if (found) return true;
    if (*it == 0) break;
    hi = *it - 1;
  }
  return false;
}

bool RecordingReader::Next(RecordedMessage* out, std::string* error) {
  if (error != nullptr) error->clear();
  if (selected_.empty()) return false;
  McapMessage m;
  while (mcap_.Next(&m, error)) {
    // Before the seek time the /mesh frames from the keyframe on are replayed, and the /device
    // batches from device_from_ns_: a viewer that seeks sees the surface, the tool where it was and
    // the force that led there. Events and annotations are not: a viewer has them from the
    // session's record, and replayed on every seek they would be listed again.
    const bool before = m.log_time_ns < seek_ns_;
    const uint64_t from = m.channel_id == mesh_channel_     ? mesh_from_ns_
                          : m.channel_id == device_channel_ ? device_from_ns_
                                                            : seek_ns_;
    if (m.log_time_ns < from) continue;
    if (!Parse(m, out, error)) return false;
    if (awaiting_keyframe_ && m.channel_id == mesh_channel_) {
      if (!out->envelope.has_mesh_keyframe()) continue;
      awaiting_keyframe_ = false;
    }
    out->catch_up = before;
    return true;
  }
  return false;
}

bool RecordingReader::Parse(const McapMessage& m, RecordedMessage* out, std::string* error) const {
  out->log_time_ns = m.log_time_ns;
  out->publish_time_ns = m.publish_time_ns;
  const auto fail = [&](std::string_view topic, const std::string& what) {
    if (error != nullptr) {
      *error = name_ + ": " + std::string(topic) + " message at log time " + std::to_string(m.log_time_ns) +
               " (sequence " + std::to_string(m.sequence) + "): " + what;
    }
    return false;
  };
  // /device holds DeviceSamples; /mesh and /events whole frames with the bodies they allow.
  if (m.channel_id == device_channel_) {
    out->topic = RecordingTopic::kDevice;
    out->envelope.Clear();
    if (m.data.size() > static_cast<size_t>(std::numeric_limits<int>::max()) ||
        !out->envelope.mutable_device_samples()->ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) {
      return fail(kDeviceTopic, "not a valid idms.v1.DeviceSamples");
    }
    return true;
  }
  const bool mesh = m.channel_id == mesh_channel_;
  const bool note = m.channel_id == annotations_channel_;
  out->topic = mesh ? RecordingTopic::kMesh : note ? RecordingTopic::kAnnotations : RecordingTopic::kEvents;
  const std::string_view topic = mesh ? kMeshTopic : note ? kAnnotationsTopic : kEventsTopic;
  std::string parse_error;
  if (!ParseEnvelope(m.data, &out->envelope, &parse_error, std::numeric_limits<int64_t>::max())) {
    return fail(topic, parse_error);
  }
  const bool allowed = mesh   ? out->envelope.has_mesh_keyframe() || out->envelope.has_mesh_delta()
                       : note ? out->envelope.has_annotation()
                              : out->envelope.has_session_event() || out->envelope.has_topology_event();
  if (!allowed) return fail(topic, std::string("a frame with body ") + EnvelopeBodyName(out->envelope));
  return true;
}

}  // namespace idms
