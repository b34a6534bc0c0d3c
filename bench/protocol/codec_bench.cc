// Mesh codec bench: bytes per frame, ratio to raw float32 frames, encode/decode time and max
// error of the idms codec against zstd on float32 frames and meshoptimizer's vertex codec, for
// the thesis's interactions on the hex fragment, a ~10^4-vertex and a ~10^5-atom slab at 60 Hz.
// Motion comes from the real DSM step driven by the scripted device (or, with --motion
// synthetic, a Gaussian dent following the same trajectory; --motion wave, the whole surface
// moving). Prints figures; never fails on time.
#include <meshoptimizer.h>
#include <zstd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "idms/protocol/envelope.h"
#include "idms/protocol/mesh_codec.h"
#include "idms/protocol/mesh_mirror.h"
#include "idms/sim/generate.h"
#include "idms/sim/interaction_script.h"
#include "idms/sim/model.h"
#include "idms/sim/state.h"
#include "idms/sim/step.h"
#include "idms/sim/workspace.h"

namespace idms {
namespace {

constexpr double kFrameRateHz = 60;
constexpr double kStep = kDefaultQuantStep;
constexpr double kKeyframeIntervalS = 5;
constexpr double kToolRadius = 1.5;  // thesis 6.1
constexpr double kToolStiffness = 400;

void Die(const std::string& what) {
  std::fprintf(stderr, "codec_bench: %s\n", what.c_str());
  std::exit(1);
}

// ---------------------------------------------------------------------------------------------
// Motion: a sequence of surface frames (num_vertices x 3) at 60 Hz.

class Motion {
 public:
  virtual ~Motion() = default;
  // The next frame's time and surface positions; false after the script ends.
  virtual bool Next(double* t, std::vector<double>* pos) = 0;
  // The simulation's nonzero warning counters, "" when none.
  virtual std::string warnings() const { return ""; }
};

// The DSM stepped at 1 kHz with the scripted MIO (local simulation, explicit Euler, thesis values).
class SimMotion : public Motion {
 public:
  SimMotion(const Model& model, Script script)
      : model_(model),
        script_(script),
        geometry_(MakeScriptGeometry(model, kToolRadius)),
        state_(MakeState(model)),
        workspace_(MakeWorkspace(model, StepOptions{})) {}

  bool Next(double* t, std::vector<double>* pos) override {
    const double t_frame = frame_ / kFrameRateHz;
    if (t_frame > ScriptDuration(script_) + 1e-9) return false;
    // Step until the frame's time (frame 0 is the rest state).
    while (state_.time_s < t_frame - 1e-9) {
      const ScriptSample s = SampleScript(script_, geometry_, state_.time_s);
      ToolInput input;
      input.num_tools = 1;
      ToolCommand& tool = input.tools[0];
      tool.kind = script_ == Script::kPluck ? ToolKind::kTweezers : ToolKind::kSphere;
      std::copy(s.pos, s.pos + 3, tool.pos);
      tool.radius = kToolRadius;
      tool.stiffness = kToolStiffness;
      tool.closed = s.closed;
      Step(model_, state_, workspace_, input);
    }
    pos->resize(3 * model_.external_atoms.size());
    for (size_t i = 0; i < model_.external_atoms.size(); ++i) {
      const size_t a = 3 * static_cast<size_t>(model_.external_atoms[i]);
      for (size_t c = 0; c < 3; ++c) (*pos)[3 * i + c] = static_cast<double>(state_.atom_pos[a + c]);
    }
    *t = t_frame;
    ++frame_;
    return true;
  }

  std::string warnings() const override {
    std::string out;
    for (const WarningKind& k : WarningKinds(state_.warnings)) {
      if (k.count != 0) out += std::string(out.empty() ? "" : ", ") + k.name + " " + std::to_string(k.count);
    }
    return out;
  }

 private:
  const Model& model_;
  Script script_;
  ScriptGeometry geometry_;
  State state_;
  Workspace workspace_;
  int64_t frame_ = 0;
};

// The rest surface pressed by a Gaussian dent under the scripted MIO: depth = the MIO's
// penetration below the rest surface, width = the MIO radius, plus a small drag along x.
class SyntheticMotion : public Motion {
 public:
  SyntheticMotion(const Model& model, Script script)
      : script_(script), geometry_(MakeScriptGeometry(model, kToolRadius)) {
    rest_.resize(3 * model.external_atoms.size());
    GatherSurface(model, model.atom_pos_eq, rest_);
  }

  bool Next(double* t, std::vector<double>* pos) override {
    const double t_frame = frame_ / kFrameRateHz;
    if (t_frame > ScriptDuration(script_) + 1e-9) return false;
    const ScriptSample s = SampleScript(script_, geometry_, t_frame);
    const double depth = std::max(0.0, geometry_.top_z + kToolRadius - s.pos[2]);
    const double sigma = 0.5 * kToolRadius;
    *pos = rest_;
    for (size_t i = 0; i < pos->size(); i += 3) {
      const double dx = rest_[i] - s.pos[0], dy = rest_[i + 1] - s.pos[1];
      const double g = depth * std::exp(-(dx * dx + dy * dy) / (2 * sigma * sigma));
      (*pos)[i] += 0.1 * g;
      (*pos)[i + 2] -= g;
    }
    *t = t_frame;
    ++frame_;
    return true;
  }

 private:
  Script script_;
  ScriptGeometry geometry_;
  std::vector<double> rest_;
  int64_t frame_ = 0;
};

// The worst case for a sparse delta: every vertex moves every frame (full simulation, a slow
// standing wave of amplitude 0.2 over the whole surface), for the script's duration.
class WaveMotion : public Motion {
 public:
  WaveMotion(const Model& model, Script script) : duration_s_(ScriptDuration(script)) {
    rest_.resize(3 * model.external_atoms.size());
    GatherSurface(model, model.atom_pos_eq, rest_);
  }

  bool Next(double* t, std::vector<double>* pos) override {
    const double t_frame = frame_ / kFrameRateHz;
    if (t_frame > duration_s_ + 1e-9) return false;
    *pos = rest_;
    const double a = 0.2 * std::sin(2 * 3.141592653589793 * 0.5 * t_frame);
    for (size_t i = 0; i < pos->size(); i += 3) {
      (*pos)[i + 2] += a * std::cos(0.3 * rest_[i]) * std::cos(0.3 * rest_[i + 1]);
    }
    *t = t_frame;
    ++frame_;
    return true;
  }

 private:
  double duration_s_;
  std::vector<double> rest_;
  int64_t frame_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Codecs under test: encode a frame to bytes, decode the bytes back to float positions.

class Codec {
 public:
  virtual ~Codec() = default;
  virtual const char* name() const = 0;
  // Encodes one frame; returns the bytes a viewer would receive.
  virtual size_t Encode(double t, std::span<const double> pos) = 0;
  // Decodes the frame just encoded, as the receiver would, and returns what it now shows.
  virtual std::span<const float> Decode() = 0;
  virtual bool last_was_keyframe() const = 0;
};

// Ours: MeshEncoder -> Envelope bytes -> ParseEnvelope -> MeshMirror.
class IdmsCodec : public Codec {
 public:
  IdmsCodec(const char* name, double threshold_steps, std::span<const int32_t> tris)
      : name_(name), encoder_(Options(threshold_steps)) {
    encoder_.SetTopology(1, tris);
  }
  const char* name() const override { return name_; }
  size_t Encode(double t, std::span<const double> pos) override {
    std::string error;
    if (!encoder_.Encode(t, pos, &env_, &error, &stats_)) Die(error);
    SerializeEnvelope(env_, &bytes_);
    return bytes_.size();
  }
  std::span<const float> Decode() override {
    std::string error;
    if (!ParseEnvelope(bytes_, &received_, &error)) Die(error);
    if (mirror_.Apply(received_, &error) != MirrorStatus::kOk) Die(error);
    return mirror_.positions();
  }
  bool last_was_keyframe() const override { return stats_.keyframe; }

 private:
  static EncoderOptions Options(double threshold_steps) {
    EncoderOptions o;
    o.quant_step = kStep;
    o.resend_threshold_steps = threshold_steps;
    o.keyframe_interval_s = kKeyframeIntervalS;
    return o;
  }
  const char* name_;
  MeshEncoder encoder_;
  MeshMirror mirror_;
  EncodeStats stats_;
  v1::Envelope env_, received_;
  std::string bytes_;
};

// (a) Every frame as raw float32, zstd level 3. Lossless apart from double -> float.
class ZstdFloatCodec : public Codec {
 public:
  ZstdFloatCodec() : cctx_(ZSTD_createCCtx()), dctx_(ZSTD_createDCtx()) {
    ZSTD_CCtx_setParameter(cctx_, ZSTD_c_compressionLevel, 3);
  }
  ~ZstdFloatCodec() override {
    ZSTD_freeCCtx(cctx_);
    ZSTD_freeDCtx(dctx_);
  }
  const char* name() const override { return "zstd-f32"; }
  size_t Encode(double, std::span<const double> pos) override {
    f_.resize(pos.size());
    for (size_t i = 0; i < pos.size(); ++i) f_[i] = static_cast<float>(pos[i]);
    out_.resize(ZSTD_compressBound(f_.size() * 4));
    const size_t n = ZSTD_compress2(cctx_, out_.data(), out_.size(), f_.data(), f_.size() * 4);
    if (ZSTD_isError(n)) Die("zstd");
    out_.resize(n);
    return n;
  }
  std::span<const float> Decode() override {
    decoded_.resize(f_.size());
    const size_t n = ZSTD_decompressDCtx(dctx_, decoded_.data(), decoded_.size() * 4, out_.data(), out_.size());
    if (ZSTD_isError(n)) Die("zstd decode");
    return decoded_;
  }
  bool last_was_keyframe() const override { return true; }

 private:
  ZSTD_CCtx* cctx_;
  ZSTD_DCtx* dctx_;
  std::vector<float> f_, decoded_;
  std::string out_;
};

// (b) meshoptimizer's vertex codec on int32 x 3 quantized frames (same grid as ours):
// "meshopt-q" each frame alone, "meshopt-q+zstd" with zstd after it (meshoptimizer's advice),
// "meshopt-dq+zstd" on the change from the previous frame (keyframes as ours), then zstd.
class MeshoptCodec : public Codec {
 public:
  MeshoptCodec(const char* name, bool temporal, bool zstd)
      : name_(name), temporal_(temporal), zstd_(zstd), cctx_(ZSTD_createCCtx()), dctx_(ZSTD_createDCtx()) {}
  ~MeshoptCodec() override {
    ZSTD_freeCCtx(cctx_);
    ZSTD_freeDCtx(dctx_);
  }
  const char* name() const override { return name_; }

  size_t Encode(double t, std::span<const double> pos) override {
    const size_t nv = pos.size() / 3;
    q_.resize(pos.size());
    std::string error;
    if (!Quantize(pos, kStep, q_, &error)) Die(error);
    // Keyframe at start and every interval; otherwise the change since the previous frame.
    key_ = !temporal_ || prev_q_.size() != q_.size() || t - last_key_t_ >= kKeyframeIntervalS;
    if (key_) last_key_t_ = t;
    d_.resize(q_.size());
    for (size_t i = 0; i < q_.size(); ++i) d_[i] = key_ ? q_[i] : q_[i] - prev_q_[i];
    prev_q_ = q_;
    mo_.resize(meshopt_encodeVertexBufferBound(nv, 12));
    mo_.resize(meshopt_encodeVertexBuffer(mo_.data(), mo_.size(), d_.data(), nv, 12));
    if (!zstd_) return mo_.size();
    z_.resize(ZSTD_compressBound(mo_.size()));
    const size_t n = ZSTD_compress2(cctx_, z_.data(), z_.size(), mo_.data(), mo_.size());
    if (ZSTD_isError(n)) Die("zstd");
    z_.resize(n);
    return n;
  }

  std::span<const float> Decode() override {
    const unsigned char* src = mo_.data();
    size_t size = mo_.size();
    if (zstd_) {
      unz_.resize(mo_.size());
      const size_t n = ZSTD_decompressDCtx(dctx_, unz_.data(), unz_.size(), z_.data(), z_.size());
      if (ZSTD_isError(n)) Die("zstd decode");
      src = unz_.data();
      size = n;
    }
    const size_t nv = q_.size() / 3;
    dd_.resize(q_.size());
    if (meshopt_decodeVertexBuffer(dd_.data(), nv, 12, src, size) != 0) Die("meshopt decode");
    mirror_q_.resize(q_.size());
    for (size_t i = 0; i < dd_.size(); ++i) mirror_q_[i] = key_ ? dd_[i] : mirror_q_[i] + dd_[i];
    pos_.resize(q_.size());
    Dequantize(mirror_q_, kStep, pos_);
    return pos_;
  }
  bool last_was_keyframe() const override { return key_; }

 private:
  const char* name_;
  bool temporal_, zstd_;
  ZSTD_CCtx* cctx_;
  ZSTD_DCtx* dctx_;
  bool key_ = true;
  double last_key_t_ = 0;
  std::vector<int32_t> q_, prev_q_, d_, dd_, mirror_q_;
  std::vector<unsigned char> mo_, z_, unz_;
  std::vector<float> pos_;
};

// ---------------------------------------------------------------------------------------------
// Measurement.

struct Row {
  std::string model, script, codec;
  int64_t vertices = 0, atoms = 0, frames = 0, keyframes = 0;
  double mean_bytes = 0, delta_mean_bytes = 0, max_bytes = 0, keyframe_bytes = 0;
  double ratio = 0;               // raw float32 bytes / mean bytes
  double enc_us = 0, dec_us = 0;  // medians per frame
  double max_err = 0;             // model units, max over frames, vertices and axes
};

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

struct Accum {
  std::vector<double> enc_us, dec_us;
  double bytes = 0, delta_bytes = 0, max_bytes = 0, keyframe_bytes = 0, max_err = 0;
  int64_t frames = 0, keyframes = 0;
};

// Runs one motion through every codec, frame by frame (frames are not stored: the 10^5 model
// would need ~0.5 GB), and returns one row per codec.
std::vector<Row> Measure(const Model& model, const std::string& model_name, Script script,
                         const std::string& motion_name, std::string* sim_warnings) {
  std::unique_ptr<Motion> motion;
  if (motion_name == "synthetic") {
    motion = std::make_unique<SyntheticMotion>(model, script);
  } else if (motion_name == "wave") {
    motion = std::make_unique<WaveMotion>(model, script);
  } else {
    motion = std::make_unique<SimMotion>(model, script);
  }
  const std::vector<int32_t> tris = SurfaceTriangles(model);
  std::vector<std::unique_ptr<Codec>> codecs;
  codecs.push_back(std::make_unique<IdmsCodec>("idms", 0.5, tris));
  codecs.push_back(std::make_unique<IdmsCodec>("idms-deadband1", 1.0, tris));
  codecs.push_back(std::make_unique<ZstdFloatCodec>());
  codecs.push_back(std::make_unique<MeshoptCodec>("meshopt-q", false, false));
  codecs.push_back(std::make_unique<MeshoptCodec>("meshopt-q+zstd", false, true));
  codecs.push_back(std::make_unique<MeshoptCodec>("meshopt-dq+zstd", true, true));
  std::vector<Accum> acc(codecs.size());
  using Clock = std::chrono::steady_clock;
  double t = 0;
  std::vector<double> pos;
  while (motion->Next(&t, &pos)) {
    for (size_t c = 0; c < codecs.size(); ++c) {
      // Encode and decode, timed separately.
      const auto t0 = Clock::now();
      const size_t bytes = codecs[c]->Encode(t, pos);
      const auto t1 = Clock::now();
      const std::span<const float> shown = codecs[c]->Decode();
      const auto t2 = Clock::now();
      Accum& a = acc[c];
      a.enc_us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
      a.dec_us.push_back(std::chrono::duration<double, std::micro>(t2 - t1).count());
      // Bytes and error against the simulated truth.
      a.bytes += static_cast<double>(bytes);
      a.max_bytes = std::max(a.max_bytes, static_cast<double>(bytes));
      if (codecs[c]->last_was_keyframe()) {
        ++a.keyframes;
        a.keyframe_bytes = std::max(a.keyframe_bytes, static_cast<double>(bytes));
      } else {
        a.delta_bytes += static_cast<double>(bytes);
      }
      ++a.frames;
      for (size_t i = 0; i < pos.size(); ++i) {
        a.max_err = std::max(a.max_err, std::fabs(static_cast<double>(shown[i]) - pos[i]));
      }
    }
  }
  *sim_warnings = motion->warnings();
  std::vector<Row> rows;
  for (size_t c = 0; c < codecs.size(); ++c) {
    const Accum& a = acc[c];
    Row r;
    r.model = model_name;
    r.script = ScriptName(script);
    r.codec = codecs[c]->name();
    r.vertices = static_cast<int64_t>(model.external_atoms.size());
    r.atoms = model.num_atoms;
    r.frames = a.frames;
    r.keyframes = a.keyframes;
    r.mean_bytes = a.bytes / static_cast<double>(std::max<int64_t>(1, a.frames));
    r.delta_mean_bytes = a.frames > a.keyframes ? a.delta_bytes / static_cast<double>(a.frames - a.keyframes) : 0;
    r.max_bytes = a.max_bytes;
    r.keyframe_bytes = a.keyframe_bytes;
    r.ratio = 12.0 * static_cast<double>(r.vertices) / r.mean_bytes;
    r.enc_us = Median(a.enc_us);
    r.dec_us = Median(a.dec_us);
    r.max_err = a.max_err;
    rows.push_back(r);
  }
  return rows;
}

void PrintHeader() {
  std::printf("%-6s %-12s %-16s %6s %4s %9s %9s %9s %9s %8s %8s %8s %10s %6s\n", "model", "script", "codec", "frames",
              "keys", "mean_B", "delta_B", "max_B", "key_B", "ratio", "enc_us", "dec_us", "max_err", "steps");
}

void PrintRow(const Row& r) {
  std::printf("%-6s %-12s %-16s %6lld %4lld %9.1f %9.1f %9.0f %9.0f %8.1f %8.1f %8.1f %10.3g %6.3f\n", r.model.c_str(),
              r.script.c_str(), r.codec.c_str(), static_cast<long long>(r.frames), static_cast<long long>(r.keyframes),
              r.mean_bytes, r.delta_mean_bytes, r.max_bytes, r.keyframe_bytes, r.ratio, r.enc_us, r.dec_us, r.max_err,
              r.max_err / kStep);
}

void WriteCsv(const std::string& path, const std::vector<Row>& rows, const std::string& motion) {
  std::ofstream out(path);
  if (!out) Die("cannot write " + path);
  out << "model,vertices,atoms,script,motion,codec,frames,keyframes,mean_bytes,delta_mean_bytes,"
         "max_bytes,keyframe_bytes,ratio_to_float32,encode_us_median,decode_us_median,"
         "max_error,max_error_steps\n";
  for (const Row& r : rows) {
    out << r.model << ',' << r.vertices << ',' << r.atoms << ',' << r.script << ',' << motion << ',' << r.codec << ','
        << r.frames << ',' << r.keyframes << ',' << r.mean_bytes << ',' << r.delta_mean_bytes << ',' << r.max_bytes
        << ',' << r.keyframe_bytes << ',' << r.ratio << ',' << r.enc_us << ',' << r.dec_us << ',' << r.max_err << ','
        << r.max_err / kStep << '\n';
  }
}

struct ModelSpec {
  std::string name;
  int32_t rows, cols;
};

int Main(int argc, char** argv) {
  CLI::App app{"Mesh codec bench: idms codec vs zstd float32 vs meshoptimizer, 60 Hz frames"};
  std::string csv;
  std::vector<std::string> model_names = {"hex", "10k", "100k"};
  std::vector<std::string> script_names = {"palpate", "stroke-slow", "stroke-fast"};
  std::string motion = "sim";
  app.add_option("--csv", csv, "write the table as CSV to this path");
  app.add_option("--models", model_names, "hex (22 vertices), 10k (~10^4 vertices), 100k (~10^5 atoms)");
  app.add_option("--scripts", script_names, "palpate, stroke-slow, stroke-fast, pluck");
  app.add_option("--motion", motion,
                 "sim (the DSM step, default), synthetic (a Gaussian dent on the script's path) or "
                 "wave (every vertex moves every frame; the script sets only the duration)")
      ->check(CLI::IsMember({"sim", "synthetic", "wave"}));
  CLI11_PARSE(app, argc, argv);

  const std::vector<ModelSpec> specs = {{"hex", 5, 4}, {"10k", 100, 100}, {"100k", 183, 183}};
  std::printf(
      "quantization step %g model units, keyframes every %g s, %g Hz frames, motion: %s\n"
      "ratio = raw float32 frame (12 B x vertices) / mean bytes per frame (keyframes "
      "included); idms bytes are whole Envelopes, the others bare payloads.\n"
      "max_err: max |shown - simulated| over frames, vertices and axes (model units; "
      "steps = / quantization step).\n\n",
      kStep, kKeyframeIntervalS, kFrameRateHz, motion.c_str());
  PrintHeader();
  std::vector<Row> all;
  for (const std::string& name : model_names) {
    const auto spec = std::find_if(specs.begin(), specs.end(), [&](const ModelSpec& s) { return s.name == name; });
    if (spec == specs.end()) Die("unknown model " + name);
    const Model model = GenerateSlab(SlabOptions{.rows = spec->rows, .cols = spec->cols});
    for (const std::string& script_name : script_names) {
      Script script;
      if (!ParseScriptName(script_name, &script)) Die("unknown script " + script_name);
      std::string warnings;
      const std::vector<Row> rows = Measure(model, name, script, motion, &warnings);
      for (const Row& r : rows) PrintRow(r);
      if (!warnings.empty()) std::printf("  (simulation warnings: %s)\n", warnings.c_str());
      all.insert(all.end(), rows.begin(), rows.end());
    }
    std::printf("  %s: %lld vertices, %d atoms, raw float32 frame %lld B\n", name.c_str(),
                static_cast<long long>(model.external_atoms.size()), model.num_atoms,
                static_cast<long long>(12 * model.external_atoms.size()));
  }
  if (!csv.empty()) WriteCsv(csv, all, motion);
  return 0;
}

}  // namespace
}  // namespace idms

int main(int argc, char** argv) { return idms::Main(argc, argv); }
