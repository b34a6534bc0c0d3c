// replay:FILE.mcap — device input from a recorded session: the /device channel's DeviceSamples
// (DESIGN.md, server "Recording"), read whole at start so the loop never touches the file.
#include <algorithm>
#include <string>
#include <vector>

#include "device_internal.h"
#include "idms/protocol/idms.pb.h"
#include "idms/protocol/recording.h"
#include "text_internal.h"

namespace idms::agent {
namespace {

constexpr size_t kMaxReplaySamples = size_t{1} << 26;  // ~18 h at 1 kHz; bounds the memory

struct ReplaySample {
  double time_s = 0;  // recorded simulation time, from the first sample
  double pos_model[3] = {0, 0, 0};
  bool closed = false;  // the recording's grasp flag stands for the button
  bool oriented = false;
  float orientation[4] = {1, 0, 0, 0};  // model frame (float: the bound's memory, 1e-7 of a turn)
  int32_t tool = 0;                     // the scene tool held (DeviceSample.tool_index)
};

class ReplayDevice final : public Device {
 public:
  ReplayDevice(std::vector<ReplaySample> samples, const Registration& registration, std::string name)
      : samples_(std::move(samples)), registration_(registration), name_(std::move(name)) {}

  void Read(int64_t, double t_s, DeviceReading* out) override {
    // The last recorded sample at or before t (time only moves forwards).
    while (next_ + 1 < samples_.size() && samples_[next_ + 1].time_s <= t_s + 1e-9) ++next_;
    const ReplaySample& s = samples_[next_];
    registration_.ModelToDevice(s.pos_model, out->pos);
    if (s.oriented) {
      const double q[4] = {s.orientation[0], s.orientation[1], s.orientation[2], s.orientation[3]};
      out->oriented = registration_.OrientationToDevice(q, out->orientation);
    }
    out->closed = s.closed;
    out->tool = s.tool;
    out->valid = true;
    finished_ = next_ + 1 >= samples_.size() && t_s >= s.time_s;
  }
  void Write(int64_t, const double*) override {}
  void Release() override {}
  bool finished() const override { return finished_; }
  const char* name() const override { return name_.c_str(); }

 private:
  std::vector<ReplaySample> samples_;
  Registration registration_;
  std::string name_;
  size_t next_ = 0;
  bool finished_ = false;
};

}  // namespace

std::unique_ptr<Device> MakeReplayDevice(std::string_view path, const Registration& registration, std::string* error) {
  // The recording's /device channel only (recording.h checks the schema).
  RecordingReader reader;
  RecordingReaderOptions options;
  options.mesh = options.events = false;
  if (!reader.Open(std::string(path), options, error)) return nullptr;
  // Every sample, in tick order, once.
  std::vector<ReplaySample> samples;
  RecordedMessage message;
  bool has_tick = false;
  uint64_t last_tick = 0;
  double t0 = 0;
  while (reader.Next(&message, error)) {
    if (!message.envelope.has_device_samples()) continue;
    for (const v1::DeviceSample& s : message.envelope.device_samples().samples()) {
      if (has_tick && s.tick() <= last_tick) continue;
      if (!has_tick) t0 = s.time_s();
      has_tick = true;
      last_tick = s.tick();
      ReplaySample r;
      r.time_s = s.time_s() - t0;
      r.pos_model[0] = s.tool_pos().x(), r.pos_model[1] = s.tool_pos().y(), r.pos_model[2] = s.tool_pos().z();
      r.closed = s.grasp() || s.tie();  // the button: the tweezers' hold, or a needle's tie
      r.tool = static_cast<int32_t>(std::min<uint32_t>(s.tool_index(), kMaxTools - 1));  // the loop checks the scene's
      if (s.has_tool_orientation()) {
        const v1::Quat& q = s.tool_orientation();
        r.oriented = true;
        r.orientation[0] = static_cast<float>(q.w()), r.orientation[1] = static_cast<float>(q.x());
        r.orientation[2] = static_cast<float>(q.y()), r.orientation[3] = static_cast<float>(q.z());
      }
      samples.push_back(r);
      if (samples.size() > kMaxReplaySamples) {
        *error = Cat({path, ": more than ", std::to_string(kMaxReplaySamples), " device samples"});
        return nullptr;
      }
    }
  }
  if (!error->empty()) return nullptr;
  if (samples.empty()) {
    *error = Cat({path, ": no device samples on ", kDeviceTopic});
    return nullptr;
  }
  return std::make_unique<ReplayDevice>(std::move(samples), registration, Cat({"replay:", path}));
}

}  // namespace idms::agent
