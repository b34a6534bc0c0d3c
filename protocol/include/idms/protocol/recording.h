// Session recordings: idms's channels on MCAP. The server's recorder writes them as a session
// happens; its playback, the agent's replay:FILE.mcap device and idms-render read them.
//
//   topic    schema (protobuf)       message
//   /device  idms.v1.DeviceSamples   a batch of 1 kHz ticks, as the agent sent it
//   /mesh    idms.v1.Envelope        mesh_keyframe or mesh_delta: the frame as it went out
//   /events  idms.v1.Envelope        session_event or topology_event
//   /annotations idms.v1.Envelope    annotation (a viewer's note; absent from older recordings)
//
// Envelopes on /mesh and /events keep one channel per topic while carrying two message types
// (an MCAP channel has one schema), and are the WebSocket frames themselves, so playback forwards
// them unchanged. Schemas are FileDescriptorSets, so Foxglove and any MCAP tool decode them.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "idms/protocol/idms.pb.h"
#include "idms/protocol/mcap.h"

namespace google::protobuf {
class Descriptor;
}

namespace idms {

inline constexpr std::string_view kDeviceTopic = "/device";
inline constexpr std::string_view kMeshTopic = "/mesh";
inline constexpr std::string_view kEventsTopic = "/events";
inline constexpr std::string_view kAnnotationsTopic = "/annotations";
// Name of the Metadata record that holds RecordingWriterOptions::session.
inline constexpr std::string_view kSessionMetadataName = "idms.session";

// A serialized google.protobuf.FileDescriptorSet of the message's file and every file it imports
// (dependencies first): the schema data MCAP's "protobuf" encoding asks for.
std::string FileDescriptorSetFor(const google::protobuf::Descriptor& message);

struct RecordingWriterOptions {
  McapWriterOptions mcap;
  // Written as the "idms.session" Metadata record, e.g. {"session_id": ..., "scene": <text format>}.
  std::map<std::string, std::string> session;
};

// Records a session. Owned by one thread (the server's recorder); see McapWriter for when data
// reaches the disk. Log times: any nanosecond clock, the same one for Write and Flush; the server
// uses Unix time of receipt, so that Foxglove shows real dates.
class RecordingWriter {
 public:
  bool Open(const std::string& path, const RecordingWriterOptions& options, std::string* error);
  // Records one frame on its channel by body: device_samples -> /device, mesh_keyframe and
  // mesh_delta -> /mesh, session_event and topology_event -> /events, annotation -> /annotations.
  // Other bodies are refused.
  bool Write(const v1::Envelope& envelope, uint64_t log_time_ns, uint64_t publish_time_ns, std::string* error);
  // McapWriter::Flush: call periodically so that a quiet session's chunk still closes.
  bool Flush(uint64_t now_ns, std::string* error) { return mcap_.Flush(now_ns, error); }
  // Writes the open chunk to the file now: every frame written so far survives a crash (what a
  // server acknowledges must be in the file, not in a chunk still being filled).
  bool CloseChunk(std::string* error) { return mcap_.CloseChunk(error); }
  bool Close(std::string* error) { return mcap_.Close(error); }
  const McapWriter& mcap() const { return mcap_; }

 private:
  McapWriter mcap_;
  uint16_t device_channel_ = 0;
  uint16_t mesh_channel_ = 0;
  uint16_t events_channel_ = 0;
  uint16_t annotations_channel_ = 0;
  std::string bytes_;  // reused serialization buffer
};

enum class RecordingTopic { kDevice, kMesh, kEvents, kAnnotations };

// One recorded message, parsed.
struct RecordedMessage {
  RecordingTopic topic = RecordingTopic::kDevice;
  uint64_t log_time_ns = 0;
  uint64_t publish_time_ns = 0;
  // A frame from before the seek time that Seek replays: a /mesh frame, so that a MeshMirror holds
  // the surface at it, or a /device batch, so that plots hold the samples that led to it.
  bool catch_up = false;
  // device_samples (/device), mesh_keyframe or mesh_delta (/mesh), session_event or topology_event (/events).
  v1::Envelope envelope;
};

struct RecordingReaderOptions {
  McapReaderOptions mcap;
  // Topics to read; the agent's replay device reads only /device.
  bool device = true;
  bool mesh = true;
  bool events = true;
  bool annotations = true;
  // How much /device history a Seek(t) replays, ns: the catch-up's /device batches start at the
  // earlier of the mesh keyframe it starts from and t - device_history_ns (not before the
  // recording's start), e.g. a viewer's plot window, so that its plots are full at t. 0: the
  // batches since the keyframe only, none without one.
  uint64_t device_history_ns = 0;
};

// Reads a recording (finished, or unfinished after a crash: see McapReader) in log-time order.
// Owned by one thread. Typical use (the agent's replay device):
//   RecordingReader reader;
//   RecordingReaderOptions options;
//   options.mesh = options.events = false;
//   if (!reader.Open(path, options, &error)) ...;
//   RecordedMessage m;
//   while (reader.Next(&m, &error)) Use(m.envelope.device_samples());
//   if (!error.empty()) ...;  // malformed data, with file and byte offset
class RecordingReader {
 public:
  // Opens and checks that the channels present have the schemas above (absent ones are fine).
  bool Open(const std::string& path, const RecordingReaderOptions& options, std::string* error);
  bool OpenBuffer(std::string bytes, std::string_view name, const RecordingReaderOptions& options, std::string* error);

  uint64_t start_ns() const { return mcap_.statistics().start_ns; }  // first and last log time
  uint64_t end_ns() const { return mcap_.statistics().end_ns; }
  const std::map<std::string, std::string>& session() const { return session_; }  // "idms.session" metadata
  const McapReader& mcap() const { return mcap_; }

  // Positions reading at log time t_ns. The next messages are the catch-up (catch_up = true), all
  // logged before t_ns: with /mesh selected, the latest keyframe at or before t_ns and the deltas
  // after it (earlier /mesh frames are skipped: the first /mesh message is that keyframe); with
  // /device selected, the batches since that keyframe or since t_ns - device_history_ns, whichever
  // is earlier. They come in log-time order, so /device batches older than the keyframe come
  // before it. /events and /annotations are not replayed (a viewer has them from the session's
  // record). Then every selected topic from t_ns on. Without a keyframe at or before t_ns, /mesh
  // simply starts at t_ns. Reads the chunks back from t_ns to find the keyframe (keyframes come
  // every few seconds), then those from the catch-up's start on.
  bool Seek(uint64_t t_ns, std::string* error);
  // The next message; false at the end (*error empty) or on malformed data (*error says where).
  bool Next(RecordedMessage* out, std::string* error);

 private:
  bool Setup(const RecordingReaderOptions& options, std::string* error);
  // The log time of the latest /mesh keyframe at or before t_ns; false if none, or on error with
  // *error set (error must not be null).
  bool FindKeyframe(uint64_t t_ns, uint64_t* keyframe_ns, std::string* error);
  bool Parse(const McapMessage& m, RecordedMessage* out, std::string* error) const;

  McapReader mcap_;
  std::string name_;  // the file, for errors
  RecordingReaderOptions options_;
  std::map<std::string, std::string> session_;
  uint16_t device_channel_ = 0;  // 0 = absent
  uint16_t mesh_channel_ = 0;
  uint16_t events_channel_ = 0;
  uint16_t annotations_channel_ = 0;
  std::vector<uint16_t> selected_;
  // Seek state: before seek_ns_ only /mesh frames from mesh_from_ns_ (the keyframe's time, then
  // the keyframe itself) and /device batches from device_from_ns_ are returned.
  uint64_t seek_ns_ = 0;
  uint64_t mesh_from_ns_ = 0;
  uint64_t device_from_ns_ = 0;
  bool awaiting_keyframe_ = false;
};

}  // namespace idms
