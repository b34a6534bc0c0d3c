// Writes mesh frames made by protocol/'s MeshEncoder, and damaged copies of them, with what the
// C++ MeshMirror made of each, as JSON lines: the browser codec's tests (codec.test.mjs) apply
// the same frames and must end in the same state, status and message. With --sheet, a stream of
// a dent moving over a large sheet for the browser bench (bench/web), as [u32 size][Envelope]...
//   idms-web-mesh-frames OUT.jsonl
//   idms-web-mesh-frames --sheet NX NY FRAMES OUT.bin
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "idms/protocol/mesh_codec.h"
#include "idms/protocol/mesh_mirror.h"

namespace {

using json = nlohmann::json;

std::string Hex(const std::string& bytes) {
  static const char* kDigits = "0123456789abcdef";
  std::string out;
  out.reserve(2 * bytes.size());
  for (const unsigned char c : bytes) {
    out.push_back(kDigits[c >> 4]);
    out.push_back(kDigits[c & 15]);
  }
  return out;
}

// One line: the frame, what the mirror said, and its state after.
class Writer {
 public:
  explicit Writer(const char* path) : out_(path) {}

  void Apply(const std::string& name, const idms::v1::Envelope& e, idms::MeshMirror& mirror) {
    std::string error;
    const idms::MirrorStatus status = mirror.Apply(e, &error);
    const auto q = mirror.quantized();
    const auto tris = mirror.triangles();
    json line{{"name", name},
              {"frame", Hex(e.SerializeAsString())},
              {"status", idms::MirrorStatusName(status)},
              {"error", status == idms::MirrorStatus::kOk ? "" : error},
              {"sequence", mirror.sequence()},
              {"num_changed", mirror.changed().size()},
              {"q", std::vector<int32_t>(q.begin(), q.end())},
              {"triangles", std::vector<int32_t>(tris.begin(), tris.end())}};
    out_ << line.dump() << '\n';
    ++count_;
  }

  int count() const { return count_; }
  bool ok() const { return static_cast<bool>(out_); }

 private:
  std::ofstream out_;
  int count_ = 0;
};

// A wavy sheet of nx x ny vertices, two triangles per cell.
struct Sheet {
  int nx, ny;
  std::vector<int32_t> tris;
  std::vector<double> pos;
  Sheet(int nx_, int ny_) : nx(nx_), ny(ny_), pos(static_cast<size_t>(3 * nx * ny)) {
    for (int j = 0; j + 1 < ny; ++j)
      for (int i = 0; i + 1 < nx; ++i) {
        const int a = j * nx + i;
        tris.insert(tris.end(), {a, a + 1, a + nx, a + 1, a + nx + 1, a + nx});
      }
  }
  // A dent of depth `depth` at (cx, cy) and squared width `width2` (cells^2), offset by `origin`
  // (large offsets test wide varints).
  void Pose(double cx, double cy, double depth, double origin, double width2 = 4.0) {
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const size_t k = 3 * static_cast<size_t>(j * nx + i);
        const double r2 = (i - cx) * (i - cx) + (j - cy) * (j - cy);
        pos[k] = origin + 0.5 * i;
        pos[k + 1] = -origin + 0.5 * j;
        pos[k + 2] = -depth * std::exp(-r2 / width2);
      }
  }
};

// The bench's stream: a dent of a fixed width in cells circling over the sheet at 60 Hz.
int WriteSheet(int nx, int ny, int frames, const char* path) {
  Sheet sheet(nx, ny);
  idms::EncoderOptions options;
  options.keyframe_interval_s = 0;
  idms::MeshEncoder encoder(options);
  encoder.SetTopology(1, sheet.tris);
  std::ofstream out(path, std::ios::binary);
  std::string error, bytes;
  for (int f = 0; f < frames; ++f) {
    const double a = 2 * 3.14159265358979 * f / 120.0;
    // A dent whose width grows with the sheet: about a tenth of the vertices move per frame.
    sheet.Pose(nx / 2.0 + nx / 4.0 * std::cos(a), ny / 2.0 + ny / 4.0 * std::sin(a), 0.8, 0, 0.0025 * nx * nx);
    idms::v1::Envelope e;
    if (!encoder.Encode(f / 60.0, sheet.pos, &e, &error)) {
      std::fprintf(stderr, "encode: %s\n", error.c_str());
      return 1;
    }
    e.SerializeToString(&bytes);
    const uint32_t n = static_cast<uint32_t>(bytes.size());
    out.write(reinterpret_cast<const char*>(&n), 4).write(bytes.data(), static_cast<std::streamsize>(n));
  }
  return out ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 6 && std::string(argv[1]) == "--sheet")
    return WriteSheet(std::atoi(argv[2]), std::atoi(argv[3]), std::atoi(argv[4]), argv[5]);
  if (argc != 2) {
    std::fprintf(stderr, "usage: idms-web-mesh-frames OUT.jsonl | --sheet NX NY FRAMES OUT.bin\n");
    return 2;
  }
  Writer w(argv[1]);
  std::string error;

  // 1. A session: keyframe, deltas of a moving dent (some frames with nothing moved), a periodic
  // keyframe, a coarser grid, positions far from the origin.
  for (const double origin : {0.0, 150000.0}) {
    Sheet sheet(24, 17);
    idms::EncoderOptions options;
    options.keyframe_interval_s = 0.25;
    options.quant_step = origin > 0 ? 1e-3 : 1e-4;
    idms::MeshEncoder encoder(options);
    encoder.SetTopology(1, sheet.tris);
    idms::MeshMirror mirror;
    for (int f = 0; f < 40; ++f) {
      const double t = f / 60.0;
      // Frames 10-12 repeat frame 9's pose: deltas listing nothing.
      const int g = (f >= 10 && f <= 12) ? 9 : f;
      sheet.Pose(4 + 0.4 * g, 8 + 2 * std::sin(g / 5.0), 0.6 * (g % 7) / 6.0, origin);
      idms::v1::Envelope e;
      if (!encoder.Encode(t, sheet.pos, &e, &error)) {
        std::fprintf(stderr, "encode: %s\n", error.c_str());
        return 1;
      }
      w.Apply("session origin " + std::to_string(origin) + " frame " + std::to_string(f), e, mirror);
    }
  }

  // 2. Damaged frames against a mirror holding a keyframe: each must leave it as it was.
  Sheet sheet(9, 7);
  idms::MeshEncoder encoder;
  encoder.SetTopology(3, sheet.tris);
  idms::MeshMirror mirror;
  sheet.Pose(2, 2, 0.3, 0);
  idms::v1::Envelope key, delta;
  encoder.Encode(0, sheet.pos, &key, &error);
  w.Apply("damaged: the keyframe", key, mirror);
  sheet.Pose(5, 4, 0.5, 0);
  encoder.Encode(0.1, sheet.pos, &delta, &error);
  auto variant = [&](const std::string& name, auto edit) {
    idms::v1::Envelope e = delta;
    edit(*e.mutable_mesh_delta());
    w.Apply("damaged: " + name, e, mirror);
  };
  variant("base ahead", [](idms::v1::MeshDelta& m) { m.set_base_sequence(m.base_sequence() + 5); });
  variant("base behind", [](idms::v1::MeshDelta& m) {
    m.set_sequence(m.sequence() + 10);
    m.set_base_sequence(0);
  });
  variant("sequence not after base", [](idms::v1::MeshDelta& m) { m.set_sequence(m.base_sequence()); });
  variant("topology differs", [](idms::v1::MeshDelta& m) { m.set_topology_version(4); });
  variant("num_changed too large", [](idms::v1::MeshDelta& m) { m.set_num_changed(1000); });
  variant("num_changed disagrees", [](idms::v1::MeshDelta& m) { m.set_num_changed(m.num_changed() - 1); });
  variant("no changes but a payload", [](idms::v1::MeshDelta& m) { m.set_num_changed(0); });
  variant("unknown compression",
          [](idms::v1::MeshDelta& m) { m.set_compression(static_cast<idms::v1::Compression>(7)); });
  variant("zstd claimed, raw sent", [](idms::v1::MeshDelta& m) { m.set_compression(idms::v1::COMPRESSION_ZSTD); });
  variant("bytes after the frame", [](idms::v1::MeshDelta& m) { m.mutable_payload()->append("xyz"); });
  // Raw (uncompressed) payloads, hand-made, for the varint reader's errors.
  auto raw = [&](const std::string& name, uint32_t n, const std::string& payload) {
    variant(name, [&](idms::v1::MeshDelta& m) {
      m.set_compression(idms::v1::COMPRESSION_NONE);
      m.set_num_changed(n);
      m.set_payload(payload);
    });
  };
  raw("raw: truncated varint", 1, std::string("\x02\x02\x80", 3));
  raw("raw: ends early", 2, std::string("\x04\x02\x02\x02\x02", 5));
  raw("raw: ids not increasing", 2, std::string("\x04\x02\x00\x02\x02\x02\x02\x02\x02", 9));
  raw("raw: id beyond the vertices", 1, std::string("\x02\xfe\x01\x02\x02\x02", 6));
  raw("raw: varint over 64 bits", 1, std::string("\x02\x02\xff\xff\xff\xff\xff\xff\xff\xff\xff\x7f", 12));
  raw("raw: leaves int32", 1, std::string("\x02\x02\xfe\xff\xff\xff\x1f\x00\x00", 9));
  raw("raw: bytes left", 1, std::string("\x02\x02\x02\x02\x02\x02", 6));
  raw("raw: a valid one-vertex move", 1, std::string("\x02\x06\x03\x04\x05", 5));
  // Keyframes: damaged ones leave the mirror as it was; the last, a valid raw one, replaces it.
  auto keyframe = [&](const std::string& name, auto edit) {
    idms::v1::Envelope e = key;
    edit(*e.mutable_mesh_keyframe());
    w.Apply("damaged keyframe: " + name, e, mirror);
  };
  keyframe("quant_step 0", [](idms::v1::MeshKeyframe& m) { m.set_quant_step(0); });
  keyframe("too many vertices", [](idms::v1::MeshKeyframe& m) { m.set_num_vertices(1u << 23); });
  keyframe("too short", [](idms::v1::MeshKeyframe& m) { m.set_num_triangles(m.num_triangles() + 100); });
  keyframe("counts disagree", [](idms::v1::MeshKeyframe& m) { m.set_num_triangles(m.num_triangles() - 1); });
  keyframe("triangle id outside", [](idms::v1::MeshKeyframe& m) {
    m.set_compression(idms::v1::COMPRESSION_NONE);
    m.set_num_vertices(1);
    m.set_num_triangles(1);
    m.set_payload(std::string("\x02\x04\x06\x00\x02\x00", 6));
  });
  keyframe("raw, valid", [](idms::v1::MeshKeyframe& m) {
    m.set_compression(idms::v1::COMPRESSION_NONE);
    m.set_sequence(100);
    m.set_num_vertices(3);
    m.set_num_triangles(1);
    m.set_payload(std::string("\x02\x02\x02\x01\x03\x05\x00\x00\x00\x00\x02\x02", 12));
  });
  if (!w.ok()) {
    std::fprintf(stderr, "idms-web-mesh-frames: cannot write %s\n", argv[1]);
    return 1;
  }
  std::printf("%d frames\n", w.count());
  return 0;
}
