// protocol/display.json, embedded by CMake (display_json.inc) and parsed once; the range rules.
#include "idms/render/display.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>

#include "idms/sim/model.h"

namespace idms::render {
namespace {

constexpr char kDisplayJson[] =
#include "display_json.inc"
    ;

// The file is ours and built in: anything wrong with it is a bug, reported where it is.
[[noreturn]] void Broken(const std::string& what) {
  std::fprintf(stderr, "protocol/display.json (embedded): %s\n", what.c_str());
  std::abort();
}

Srgb ParseSrgb(const nlohmann::json& j) {
  const std::string s = j.get<std::string>();
  if (s.size() != 7 || s[0] != '#') Broken("expected a colour as #rrggbb, got " + s);
  Srgb c{};
  for (int i = 0; i < 3; ++i) c[i] = static_cast<uint8_t>(std::strtoul(s.substr(1 + 2 * i, 2).c_str(), nullptr, 16));
  return c;
}

Light ParseLight(const nlohmann::json& j) {
  Light l;
  const auto v = j.at("towards").get<std::vector<double>>();
  if (v.size() != 3) Broken("a light's towards has 3 components");
  const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  for (int i = 0; i < 3; ++i) l.towards[i] = v[i] / n;
  l.intensity = j.at("intensity").get<double>();
  return l;
}

Display Parse() {
  Display d;
  try {
    const nlohmann::json j = nlohmann::json::parse(kDisplayJson);
    for (const auto& c : j.at("map").at("srgb")) d.map.push_back(ParseSrgb(c));
    if (d.map.size() != 256) Broken("map.srgb has " + std::to_string(d.map.size()) + " entries, expected 256");
    const auto& disp = j.at("displacement");
    d.range_fraction = disp.at("range_fraction").get<double>();
    d.nice_steps = disp.at("nice_steps").get<std::vector<double>>();
    d.ticks = disp.at("ticks").get<int>();
    d.rest_note_after_s = disp.at("rest_note_after_s").get<double>();
    d.length_unit = j.at("unit").at("length").get<std::string>();
    d.stiffness_unit = j.at("unit").at("stiffness").get<std::string>();
    const auto& light = j.at("light");
    d.ambient = light.at("ambient").get<double>();
    d.key = ParseLight(light.at("key"));
    d.fill = ParseLight(light.at("fill"));
    d.back = ParseSrgb(light.at("back_srgb"));
    d.plain = ParseSrgb(light.at("plain_srgb"));
    const auto& tool = j.at("tool");
    d.tool_free = ParseSrgb(tool.at("free_srgb"));
    d.tool_contact = ParseSrgb(tool.at("contact_srgb"));
    d.tool_grasp = ParseSrgb(tool.at("grasp_srgb"));
    d.tool_slip = ParseSrgb(tool.at("slip_srgb"));
    d.tool_fill_alpha = tool.at("fill_alpha").get<double>();
    d.tool_outline_px = tool.at("outline_px").get<double>();
    const auto& contact = j.at("contact");
    d.contact_radius_tolerance = contact.at("radius_tolerance").get<double>();
    d.contact_outer = ParseSrgb(contact.at("outer_srgb"));
    d.contact_inner = ParseSrgb(contact.at("inner_srgb"));
    d.contact_outer_px = contact.at("outer_px").get<double>();
    d.contact_inner_px = contact.at("inner_px").get<double>();
    const auto& suture = j.at("suture");
    d.suture_thread = ParseSrgb(suture.at("thread_srgb"));
    d.suture_puncture = ParseSrgb(suture.at("puncture_srgb"));
    d.suture_puncture_px = suture.at("puncture_px").get<double>();
  } catch (const nlohmann::json::exception& e) {
    Broken(e.what());
  }
  if (d.nice_steps.empty() || d.ticks < 1) Broken("displacement.nice_steps and ticks must not be empty");
  return d;
}

}  // namespace

const Display& TheDisplay() {
  static const Display display = Parse();
  return display;
}

int ColourIndex(double v, double lo, double hi) {
  // A span within rounding of the values (a fitted model's k) is no span (display.js says why).
  if (!(hi - lo > 1e-9 * std::max(std::abs(lo), std::abs(hi))) || !std::isfinite(v)) return 0;
  const double t = std::clamp((v - lo) / (hi - lo), 0.0, 1.0);
  return static_cast<int>(std::floor(t * 255 + 0.5));
}

double NiceCeil(double x) {
  if (!(x > 0) || !std::isfinite(x)) return 1;
  // p: the power of ten at or below x, by steps of ten (exact and the same in JavaScript, where
  // pow and log10 may round differently).
  double p = 1;
  while (p > x) p /= 10;
  while (p * 10 <= x) p *= 10;
  // A part in a million over a step is taken as the step: a mesh of unit sides is 1 within the
  // float positions' rounding, either way.
  for (const double m : TheDisplay().nice_steps) {
    if (x <= m * p * (1 + 1e-6)) return m * p;
  }
  return 10 * p;
}

double DisplacementRange(std::span<const float> rest, std::span<const int32_t> triangles) {
  double sum = 0;
  size_t sides = 0;
  auto side = [&](int32_t a, int32_t b) {
    const double dx = static_cast<double>(rest[3 * a]) - rest[3 * b];
    const double dy = static_cast<double>(rest[3 * a + 1]) - rest[3 * b + 1];
    const double dz = static_cast<double>(rest[3 * a + 2]) - rest[3 * b + 2];
    sum += std::sqrt(dx * dx + dy * dy + dz * dz);
    ++sides;
  };
  for (size_t t = 0; t + 2 < triangles.size(); t += 3) {
    side(triangles[t], triangles[t + 1]);
    side(triangles[t + 1], triangles[t + 2]);
    side(triangles[t + 2], triangles[t]);
  }
  if (sides == 0) return 1;
  return NiceCeil(TheDisplay().range_fraction * (sum / static_cast<double>(sides)));
}

std::vector<double> StiffnessPerVertex(const Model& model) {
  std::vector<double> k(model.external_atoms.size(), 0);
  for (size_t v = 0; v < model.external_atoms.size(); ++v) {
    const int32_t atom = model.external_atoms[v];
    const int32_t n = model.atom_elem_num[atom];
    double sum = 0;
    for (int32_t i = 0; i < n; ++i) sum += model.elem_k[model.atom_elem[model.atom_elem_adr[atom] + i]];
    k[v] = n > 0 ? sum / n : 0;
  }
  return k;
}

}  // namespace idms::render
