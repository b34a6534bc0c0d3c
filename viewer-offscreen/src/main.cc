// idms-render: a PNG of a model at rest, a recording at a session time (or every S seconds of
// it), or a live session, drawn with OSMesa. Exit 0 on success, 1 on a usage error, 2 on failure.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>

#include "idms/protocol/cli.h"
#include "idms/render/live.h"
#include "idms/render/png.h"
#include "idms/render/render.h"
#include "idms/render/source.h"

namespace {

using namespace idms::render;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double Ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); }

struct Output {
  Renderer renderer;
  RenderOptions options;
  Image image;
  std::string png;
  bool fixed_camera = false;  // --every: the automatic camera of the first frame, for all

  bool Write(const ViewerState& state, const std::string& path, double t_s, std::string* error) {
    const SceneView view = state.View();
    if (options.camera.automatic && fixed_camera) options.camera = CameraFor(view, options);
    const auto t0 = Clock::now();
    if (!renderer.Render(view, options, &image, error)) return false;
    const auto t1 = Clock::now();
    if (!EncodePng(image, &png, error)) return false;
    const auto t2 = Clock::now();
    if (!WriteFile(path, png, error)) return false;
    std::printf("%s: %dx%d, t=%.3f s, %d triangles, render %.1f ms, png %.1f ms, %zu bytes\n", path.c_str(),
                image.width, image.height, t_s, state.mirror.num_triangles(), Ms(t0, t1), Ms(t1, t2), png.size());
    return true;
  }
};

std::string FramePath(const std::string& dir, int index) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%06d.png", index);
  return (fs::path(dir) / name).string();
}

int Fail(const std::string& error) {
  std::fprintf(stderr, "idms-render: %s\n", error.c_str());
  return 2;
}

// A model at rest.
int RunModel(Output& o, const std::string& model, const std::string& out) {
  ViewerState state;
  std::string error;
  if (!LoadRestState(model, &state, &error) || !o.Write(state, out, 0, &error)) return Fail(error);
  return 0;
}

// A recording: one time (at_s < 0: its end), or every S seconds from the start.
int RunRecording(Output& o, const std::string& recording, double at_s, double every_s, const std::string& out) {
  RecordingPlayer player;
  std::string error;
  if (!player.Open(recording, &error)) return Fail(error);
  if (every_s == 0) {
    const double t = at_s < 0 ? player.duration_s() : at_s;
    if (!player.MoveTo(t, &error) || !o.Write(player.state(), out, t, &error)) return Fail(error);
    return 0;
  }
  int index = 0;
  for (double t = 0; t <= player.duration_s() + 1e-9; t = ++index * every_s) {
    if (!player.MoveTo(std::min(t, player.duration_s()), &error)) return Fail(error);
    if (!o.Write(player.state(), FramePath(out, index), t, &error)) return Fail(error);
  }
  return 0;
}

// A live session: the first frame with the device's position, or every S seconds until it ends.
int RunLive(Output& o, const LiveOptions& live, double every_s, const std::string& out) {
  ViewerState state;
  std::string error;
  double next_s = -1;
  int index = 0;
  bool wrote = false, failed = false;
  const bool ok = WatchLive(
      live, &state,
      [&](const ViewerState& s) {
        if (!s.has_sample) return true;
        const double t = s.mirror.time_s();
        if (every_s == 0) {
          failed = !o.Write(s, out, t, &error);
          wrote = true;
          return false;
        }
        if (next_s < 0) next_s = t;
        if (t + 1e-9 < next_s) return true;
        next_s += every_s;
        failed = !o.Write(s, FramePath(out, index++), t, &error);
        wrote = true;
        return !failed;
      },
      &error);
  if (!ok || failed) return Fail(error);
  if (!wrote) return Fail("the session ended before its surface arrived");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"idms-render: PNG screenshots of idms models, recordings and live sessions (OSMesa, no display)"};
  std::string model, recording, server, session, token, token_file, out, size = "1280x720", camera = "auto";
  std::string at_text, every_text, colour = "displacement";
  double deformation_scale = 1;
  bool wireframe = false, show_tool = false, show_force = false, no_legend = false;
  auto* model_opt = app.add_option("--model", model, "A model at rest: PREFIX of PREFIX.fem + PREFIX.plg");
  auto* rec_opt = app.add_option("--recording", recording, "A session recording (.mcap)");
  auto* server_opt = app.add_option("--server", server, "A live session's server, http://HOST:PORT (or ws://)");
  app.add_option("--session", session, "The live session's id (with --server)");
  auto* token_opt = app.add_option("--token", token,
                                   "Bearer token for --server (observer or above); `ps` shows it: prefer IDMS_TOKEN "
                                   "or --token-file")
                        ->envname("IDMS_TOKEN");
  app.add_option("--token-file", token_file, "A file holding the token alone")->excludes(token_opt);
  app.set_version_flag("--version", idms::Version());
  app.add_option("--at", at_text, "Session time to render, s (recordings; default: the end)");
  app.add_option("--every", every_text, "Render a frame every S seconds of session time into --out DIR");
  app.add_option("--out", out, "The PNG to write, or with --every the directory for frame_NNNNNN.png")->required();
  app.add_option("--size", size, "Image size WIDTHxHEIGHT")->capture_default_str();
  app.add_option("--camera", camera, "auto, or EYE_X,EYE_Y,EYE_Z:TARGET_X,TARGET_Y,TARGET_Z")->capture_default_str();
  app.add_flag("--wireframe", wireframe, "Draw the triangles' edges instead of the shaded surface");
  app.add_flag("--show-tool", show_tool, "Draw the tool sphere at the device position");
  app.add_flag("--show-force", show_force, "Draw the device force as an arrow from the tool");
  app.add_option("--color,--colour", colour,
                 "What the surface's colour shows: displacement (from rest), stiffness (--model only) or plain")
      ->capture_default_str();
  app.add_option("--deformation-scale", deformation_scale,
                 "Exaggerate the deformation: drawn = rest + S (p - rest), S in (0, 100]; colours stay true")
      ->capture_default_str();
  app.add_flag("--no-legend", no_legend, "Leave out the colour legend");
  model_opt->excludes(rec_opt)->excludes(server_opt);
  rec_opt->excludes(server_opt);
  CLI11_PARSE(app, argc, argv);

  // Parameters, checked before any work.
  std::string error;
  Output o;
  double at_s = -1, every_s = 0;
  if (!ParseSize(size, &o.options.width, &o.options.height, &error) ||
      !ParseCamera(camera, &o.options.camera, &error) || (!at_text.empty() && !ParseSeconds(at_text, &at_s, &error)) ||
      (!every_text.empty() && !ParseSeconds(every_text, &every_s, &error))) {
    std::fprintf(stderr, "idms-render: %s\n", error.c_str());
    return 1;
  }
  if (!token_file.empty() && !idms::ReadTokenFile(token_file, &token, &error)) {
    std::fprintf(stderr, "idms-render: %s\n", error.c_str());
    return 1;
  }
  if (model.empty() + recording.empty() + server.empty() != 2 || (!server.empty() && session.empty())) {
    std::fprintf(stderr, "idms-render: give one of --model PREFIX, --recording FILE, --server URL --session ID\n");
    return 1;
  }
  if (!at_text.empty() && recording.empty()) {
    std::fprintf(stderr, "idms-render: --at applies to --recording only\n");
    return 1;
  }
  if (!every_text.empty() && (every_s <= 0 || !model.empty())) {
    std::fprintf(stderr, "idms-render: --every needs a positive period and a recording or a live session\n");
    return 1;
  }
  if (colour != "displacement" && colour != "stiffness" && colour != "plain") {
    std::fprintf(stderr, "idms-render: --color %s: expected displacement, stiffness or plain\n", colour.c_str());
    return 1;
  }
  if (colour == "stiffness" && model.empty()) {
    std::fprintf(stderr, "idms-render: --color stiffness needs --model (a recording carries no elements)\n");
    return 1;
  }
  if (!(deformation_scale > 0 && deformation_scale <= kMaxDeformationScale)) {
    std::fprintf(stderr, "idms-render: --deformation-scale: expected a number in (0, 100]\n");
    return 1;
  }
  o.options.colour_by = colour == "stiffness" ? ColourBy::kStiffness
                        : colour == "plain"   ? ColourBy::kPlain
                                              : ColourBy::kDisplacement;
  o.options.deformation_scale = deformation_scale;
  o.options.legend = !no_legend;
  o.options.wireframe = wireframe;
  o.options.show_tool = show_tool;
  o.options.show_force = show_force;
  o.fixed_camera = every_s > 0;
  if (!o.renderer.ok()) return Fail(o.renderer.error());
  if (every_s > 0) {
    std::error_code ec;
    fs::create_directories(out, ec);
    if (ec) return Fail("cannot create " + out + ": " + ec.message());
  }

  if (!model.empty()) return RunModel(o, model, out);
  if (!recording.empty()) return RunRecording(o, recording, at_s, every_s, out);
  return RunLive(o, LiveOptions{server, session, token}, every_s, out);
}
