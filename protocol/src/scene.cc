// Scene files: protobuf text format parsed with an error collector (LINE:COL), values checked
// field by field, and a bad field located in the file through the parser's location tree.
#include "idms/protocol/scene.h"

#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <utility>
#include <vector>

#include "idms/sim/preset.h"
#include "idms/sim/state.h"

namespace idms {
namespace {

using google::protobuf::Descriptor;
using google::protobuf::FieldDescriptor;
using google::protobuf::TextFormat;

// The first syntax error, 1-based.
class FirstErrorCollector : public google::protobuf::io::ErrorCollector {
 public:
  void AddError(int line, google::protobuf::io::ColumnNumber column, const std::string& message) override {
    if (!has_error_) {
      has_error_ = true;
      line_ = line + 1;
      col_ = column + 1;
      message_ = message;
    }
  }
  void AddWarning(int, google::protobuf::io::ColumnNumber, const std::string&) override {}

  bool has_error_ = false;
  int line_ = 0;
  int col_ = 0;
  std::string message_;
};

// A bad value: the field path from Scene (name, index; index -1 for singular fields) and what
// was expected.
struct SceneIssue {
  std::vector<std::pair<std::string, int>> path;
  std::string message;

  std::string PathString() const {
    std::string s;
    for (const auto& [name, index] : path) {
      if (!s.empty()) s += '.';
      s += name;
      if (index >= 0) {
        s += '[';
        s += std::to_string(index);
        s += ']';
      }
    }
    return s;
  }
};

std::string Num(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

// Collects the first issue while the checks below walk the scene.
class Checker {
 public:
  bool ok() const { return !issue_.has_value(); }
  const SceneIssue& issue() const { return *issue_; }

  void Fail(std::vector<std::pair<std::string, int>> path, std::string message) {
    if (!issue_) issue_ = SceneIssue{std::move(path), std::move(message)};
  }

  // A value in [lo, hi] (or (lo, hi] when open_lo), finite.
  void Range(std::vector<std::pair<std::string, int>> path, double v, double lo, double hi, bool open_lo) {
    const bool in = std::isfinite(v) && (open_lo ? v > lo : v >= lo) && v <= hi;
    if (!in) {
      Fail(std::move(path), std::string("must be in ") + (open_lo ? "(" : "[") + Num(lo) + ", " +
                                (std::isinf(hi) ? std::string("inf)") : Num(hi) + "]") + ", got " + Num(v));
    }
  }

  void Finite(std::vector<std::pair<std::string, int>> path, const v1::Vec3& v) {
    if (!std::isfinite(v.x()) || !std::isfinite(v.y()) || !std::isfinite(v.z())) {
      Fail(std::move(path), "must be finite");
    }
  }

 private:
  std::optional<SceneIssue> issue_;
};

// NAME or NAME@VERSION with NAME and VERSION made of [A-Za-z0-9_.-], not starting with '.'.
bool ValidModelName(const std::string& s) {
  auto token_ok = [](std::string_view t) {
    if (t.empty() || t.front() == '.') return false;
    for (const char c : t) {
      const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
                      c == '-' || c == '.';
      if (!ok) return false;
    }
    return true;
  };
  const size_t at = s.find('@');
  if (at == std::string::npos) return token_ok(s);
  return token_ok(std::string_view(s).substr(0, at)) && token_ok(std::string_view(s).substr(at + 1));
}

// A needle's parameters in range; a needle message on another kind is refused.
void CheckNeedle(const v1::Tool& tool, int i, Checker* c) {
  const auto path = [i](const char* field) {
    return std::vector<std::pair<std::string, int>>{{"tools", i}, {"needle", -1}, {field, -1}};
  };
  constexpr double kInf = std::numeric_limits<double>::infinity();
  if (!tool.has_needle()) return;
  if (tool.kind() != v1::Tool::KIND_NEEDLE) {
    c->Fail({{"tools", i}, {"needle", -1}}, "applies to KIND_NEEDLE only");
    return;
  }
  const v1::Needle& n = tool.needle();
  if (n.has_length()) c->Range(path("length"), n.length(), 0, kInf, true);
  if (n.has_puncture_force()) c->Range(path("puncture_force"), n.puncture_force(), 0, kInf, true);
  if (n.has_axial_friction()) c->Range(path("axial_friction"), n.axial_friction(), 0, kInf, false);
  if (n.has_grip()) c->Range(path("grip"), n.grip(), 0, kInf, false);
  if (n.has_capture_radius()) c->Range(path("capture_radius"), n.capture_radius(), 0, kInf, true);
  if (n.has_lateral_stiffness()) c->Range(path("lateral_stiffness"), n.lateral_stiffness(), 0, kInf, true);
  if (n.has_lateral_damping()) c->Range(path("lateral_damping"), n.lateral_damping(), 0, kInf, false);
  if (n.has_axial_stiffness()) c->Range(path("axial_stiffness"), n.axial_stiffness(), 0, kInf, true);
  if (n.has_axial_damping()) c->Range(path("axial_damping"), n.axial_damping(), 0, kInf, false);
  if (!n.has_suture()) return;
  const v1::Suture& u = n.suture();
  const auto upath = [i](const char* field) {
    return std::vector<std::pair<std::string, int>>{{"tools", i}, {"needle", -1}, {"suture", -1}, {field, -1}};
  };
  if (!u.has_length()) c->Fail(upath("length"), "required (model units, > 0)");
  if (u.has_length()) c->Range(upath("length"), u.length(), 0, kInf, true);
  if (u.has_segments()) c->Range(upath("segments"), u.segments(), 1, kSutureSegments, false);
  if (u.has_mass()) c->Range(upath("mass"), u.mass(), 0, kInf, true);
  if (u.has_stiffness()) c->Range(upath("stiffness"), u.stiffness(), 0, kInf, false);
  if (u.has_damping()) c->Range(upath("damping"), u.damping(), 0, kInf, false);
  if (u.has_strength()) c->Range(upath("strength"), u.strength(), 0, kInf, false);
  if (u.has_hold_stiffness()) c->Range(upath("hold_stiffness"), u.hold_stiffness(), 0, kInf, true);
  if (u.has_tie_force()) c->Range(upath("tie_force"), u.tie_force(), 0, kInf, true);
  if (u.has_tie_speed()) c->Range(upath("tie_speed"), u.tie_speed(), 0, kInf, true);
  if (u.has_drag()) c->Range(upath("drag"), u.drag(), 0, kInf, false);
}

void CheckTool(const v1::Tool& tool, int i, bool full_simulation, Checker* c) {
  const auto path = [i](const char* field) {
    return std::vector<std::pair<std::string, int>>{{"tools", i}, {field, -1}};
  };
  constexpr double kInf = std::numeric_limits<double>::infinity();
  if (tool.kind() == v1::Tool::KIND_UNSPECIFIED || !v1::Tool::Kind_IsValid(tool.kind())) {
    c->Fail(path("kind"), "set kind: KIND_SPHERE, KIND_TWEEZERS, KIND_SCALPEL or KIND_NEEDLE");
  }
  if (!tool.has_radius()) c->Fail(path("radius"), "required (model units, > 0)");
  if (!tool.has_stiffness()) c->Fail(path("stiffness"), "required (force / length, > 0)");
  c->Range(path("radius"), tool.radius(), 0, kInf, true);
  c->Range(path("stiffness"), tool.stiffness(), 0, kInf, true);
  if (!v1::ForceLaw_IsValid(tool.force_law())) c->Fail(path("force_law"), "unknown force law");
  // Friction: finite coefficients, 0 <= mu_d <= mu_s, a spring and damper in range.
  const bool friction = tool.has_static_friction() || tool.has_kinetic_friction() || tool.has_friction_stiffness() ||
                        tool.has_friction_damping();
  if (friction && (tool.kind() == v1::Tool::KIND_SCALPEL || tool.kind() == v1::Tool::KIND_NEEDLE)) {
    c->Fail(path(tool.has_static_friction() ? "static_friction" : "kinetic_friction"),
            "friction applies to KIND_SPHERE and KIND_TWEEZERS only");
  }
  if (tool.has_static_friction()) c->Range(path("static_friction"), tool.static_friction(), 0, kInf, false);
  if (tool.has_kinetic_friction()) {
    c->Range(path("kinetic_friction"), tool.kinetic_friction(), 0, kInf, false);
    if (!tool.has_static_friction()) {
      c->Fail(path("kinetic_friction"), "needs static_friction (mu_s >= mu_d) set too");
    } else if (tool.kinetic_friction() > tool.static_friction()) {
      c->Fail(path("kinetic_friction"),
              "must be <= static_friction (" + Num(tool.static_friction()) + "), got " + Num(tool.kinetic_friction()));
    }
  }
  if (tool.has_friction_stiffness()) c->Range(path("friction_stiffness"), tool.friction_stiffness(), 0, kInf, true);
  if (tool.has_friction_damping()) c->Range(path("friction_damping"), tool.friction_damping(), 0, kInf, false);
  CheckNeedle(tool, i, c);
  if (tool.has_blade_length()) {
    c->Range(path("blade_length"), tool.blade_length(), 0, kInf, true);
    if (tool.kind() != v1::Tool::KIND_SCALPEL) c->Fail(path("blade_length"), "is for KIND_SCALPEL only");
  }
  if (tool.has_local_radius()) {
    c->Range(path("local_radius"), tool.local_radius(), 0, kInf, true);
    if (!full_simulation && tool.local_radius() < tool.radius()) {
      c->Fail(path("local_radius"), "must be >= radius (" + Num(tool.radius()) +
                                        ") so that contact atoms are simulated, got " + Num(tool.local_radius()));
    }
  }
}

void CheckDevice(const v1::DeviceMapping& d, Checker* c) {
  const auto path = [](const char* field) {
    return std::vector<std::pair<std::string, int>>{{"device", -1}, {field, -1}};
  };
  constexpr double kInf = std::numeric_limits<double>::infinity();
  if (d.has_scale()) c->Range(path("scale"), d.scale(), 0, kInf, true);
  c->Finite(path("rotation_rpy_deg"), d.rotation_rpy_deg());
  c->Finite(path("offset"), d.offset());
  if (d.has_force_scale()) c->Range(path("force_scale"), d.force_scale(), 0, kInf, true);
  if (d.has_max_force()) c->Range(path("max_force"), d.max_force(), 0, kInf, true);
  if (d.has_max_force_rate()) c->Range(path("max_force_rate"), d.max_force_rate(), 0, kInf, false);
  if (d.has_max_rate_hz()) c->Range(path("max_rate_hz"), d.max_rate_hz(), 0, 10000, true);
  if (d.has_transition_force_rate()) {
    c->Range(path("transition_force_rate"), d.transition_force_rate(), 0, kInf, true);
  }
  const v1::Passivity& p = d.passivity();
  const auto ppath = [](const char* field) {
    return std::vector<std::pair<std::string, int>>{{"device", -1}, {"passivity", -1}, {field, -1}};
  };
  if (p.has_window_s()) c->Range(ppath("window_s"), p.window_s(), 0, 1000, false);
  if (p.has_max_damping()) c->Range(ppath("max_damping"), p.max_damping(), 0, kInf, true);
  if (p.has_encoder_quantum()) c->Range(ppath("encoder_quantum"), p.encoder_quantum(), 0, kInf, false);
}

Checker CheckScene(const v1::Scene& scene) {
  Checker c;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  using Path = std::vector<std::pair<std::string, int>>;
  // The model: exactly one of a library name and a file prefix.
  if (scene.model().empty() && scene.model_file().empty()) {
    c.Fail(Path{{"model", -1}}, "set model (a library NAME or NAME@VERSION) or model_file (a .fem/.plg prefix)");
  } else if (!scene.model().empty() && !scene.model_file().empty()) {
    c.Fail(Path{{"model_file", -1}}, "set only one of model and model_file");
  } else if (!scene.model().empty() && !ValidModelName(scene.model())) {
    c.Fail(Path{{"model", -1}},
           "expected NAME or NAME@VERSION of letters, digits, '_', '-', "
           "'.', got \"" +
               scene.model() + "\"");
  } else if (scene.model_file().find('\0') != std::string::npos) {
    c.Fail(Path{{"model_file", -1}}, "contains a NUL byte");
  }
  // Tools.
  if (scene.tools().empty()) c.Fail(Path{{"tools", -1}}, "at least one tool is required");
  for (int i = 0; i < scene.tools_size(); ++i) {
    CheckTool(scene.tools(i), i, scene.full_simulation(), &c);
  }
  // Integration and environment.
  if (!v1::Preset_IsValid(scene.preset())) {
    c.Fail(Path{{"preset", -1}}, "unknown preset");
  }
  if (!v1::Integrator_IsValid(scene.integrator())) {
    c.Fail(Path{{"integrator", -1}}, "unknown integrator");
  }
  if (scene.has_dt_s()) c.Range(Path{{"dt_s", -1}}, scene.dt_s(), 0, 0.1, true);
  c.Finite(Path{{"gravity", -1}}, scene.gravity());
  if (scene.has_air_resistance()) {
    c.Range(Path{{"air_resistance", -1}}, scene.air_resistance(), 0, kInf, false);
  }
  if (scene.has_global_rate_hz()) {
    c.Range(Path{{"global_rate_hz", -1}}, scene.global_rate_hz(), 0, 500, false);
    if (scene.global_rate_hz() > 0 && scene.full_simulation()) {
      c.Fail(Path{{"global_rate_hz", -1}}, "a global pass beside full_simulation, which already moves every atom");
    }
  }
  // Streaming and recording.
  if (scene.has_stream_rate_hz()) {
    c.Range(Path{{"stream_rate_hz", -1}}, scene.stream_rate_hz(), 0, 1000, true);
  }
  if (scene.has_quant_step()) c.Range(Path{{"quant_step", -1}}, scene.quant_step(), 1e-9, 1, false);
  if (scene.has_keyframe_interval_s()) {
    c.Range(Path{{"keyframe_interval_s", -1}}, scene.keyframe_interval_s(), 0, 3600, false);
  }
  if (scene.has_sample_batch() && (scene.sample_batch() < 1 || scene.sample_batch() > 1000)) {
    c.Fail(Path{{"sample_batch", -1}}, "must be in [1, 1000], got " + std::to_string(scene.sample_batch()));
  }
  if (scene.has_device()) CheckDevice(scene.device(), &c);
  if (scene.has_grading()) {
    const v1::Grading& g = scene.grading();
    const auto at = [](const char* field) { return Path{{"grading", -1}, {field, -1}}; };
    if (g.has_max_peak_force()) c.Range(at("max_peak_force"), g.max_peak_force(), 0, kInf, false);
    if (g.has_max_contact_time_s()) c.Range(at("max_contact_time_s"), g.max_contact_time_s(), 0, kInf, false);
    if (g.has_max_path_length()) c.Range(at("max_path_length"), g.max_path_length(), 0, kInf, false);
  }
  if (scene.has_units()) {
    const v1::Units& u = scene.units();
    const auto at = [](const char* field) { return Path{{"units", -1}, {field, -1}}; };
    if (u.has_mm_per_unit()) c.Range(at("mm_per_unit"), u.mm_per_unit(), 0, 1e9, true);
    if (u.has_newtons_per_force_unit()) c.Range(at("newtons_per_force_unit"), u.newtons_per_force_unit(), 0, 1e9, true);
  }
  return c;
}

// Where the issue's field (or its deepest present ancestor) is in the text, 1-based; 0 if unknown.
std::pair<int, int> Locate(const SceneIssue& issue, const TextFormat::ParseInfoTree& root) {
  const Descriptor* descriptor = v1::Scene::descriptor();
  const TextFormat::ParseInfoTree* tree = &root;
  std::pair<int, int> where{0, 0};
  for (const auto& [name, index] : issue.path) {
    const FieldDescriptor* field = descriptor->FindFieldByName(name);
    if (field == nullptr || tree == nullptr) break;
    if (field->is_repeated() && index < 0) break;
    const TextFormat::ParseLocation loc = tree->GetLocation(field, index);
    if (loc.line < 0) break;
    where = {loc.line + 1, loc.column + 1};
    if (field->type() != FieldDescriptor::TYPE_MESSAGE) break;
    tree = tree->GetTreeForNested(field, index);
    descriptor = field->message_type();
  }
  return where;
}

bool ReadFile(const std::string& path, std::string* text, std::string* error) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    *error = path + ": cannot open: " + std::strerror(errno);
    return false;
  }
  text->clear();
  char buffer[4096];
  while (in.read(buffer, sizeof buffer) || in.gcount() > 0) {
    text->append(buffer, static_cast<size_t>(in.gcount()));
    if (static_cast<int64_t>(text->size()) > kMaxSceneBytes) {
      *error = path + ": larger than " + std::to_string(kMaxSceneBytes) + " bytes, not a scene";
      return false;
    }
  }
  if (in.bad()) {
    *error = path + ": read error";
    return false;
  }
  return true;
}

// Protobuf's column of byte `offset` in `line` (a tab advances to the next multiple of 8).
int ProtobufColumn(std::string_view line, size_t offset) {
  int col = 0;
  for (size_t i = 0; i < offset && i < line.size(); ++i) col = line[i] == '\t' ? (col / 8 + 1) * 8 : col + 1;
  return col;
}

// The parser reports an unknown field or enum value at the token after it (often the next line);
// point at the name itself when the message quotes it and it appears just before.
void PointAtQuotedName(std::string_view text, FirstErrorCollector* e) {
  // Byte offset of the reported position (1-based line and protobuf column).
  size_t line_start = 0;
  for (int l = 1; l < e->line_ && line_start != std::string_view::npos; ++l) {
    line_start = text.find('\n', line_start);
    if (line_start != std::string_view::npos) ++line_start;
  }
  if (line_start == std::string_view::npos) return;
  size_t end = line_start;
  while (end < text.size() && text[end] != '\n' &&
         ProtobufColumn(text.substr(line_start), end - line_start) < e->col_ - 1) {
    ++end;
  }
  // Each quoted string in the message, first to last.
  for (size_t q0 = e->message_.find('"'); q0 != std::string::npos;) {
    const size_t q1 = e->message_.find('"', q0 + 1);
    if (q1 == std::string::npos) return;
    const std::string name = e->message_.substr(q0 + 1, q1 - q0 - 1);
    q0 = e->message_.find('"', q1 + 1);
    const size_t at = name.empty() ? std::string_view::npos : text.substr(0, end).rfind(name);
    if (at == std::string_view::npos) continue;
    // Only the token just before: nothing but separators between it and the reported position.
    bool adjacent = true;
    for (size_t i = at + name.size(); i < end; ++i) {
      adjacent = adjacent && std::string_view(" \t\r\n:").find(text[i]) != std::string_view::npos;
    }
    if (!adjacent) continue;
    const size_t prev_newline = text.substr(0, at).rfind('\n');
    const size_t ls = prev_newline == std::string_view::npos ? 0 : prev_newline + 1;
    int line = 1;
    for (size_t i = 0; i < ls; ++i) line += text[i] == '\n';
    e->line_ = line;
    e->col_ = ProtobufColumn(text.substr(ls), at - ls) + 1;
    return;
  }
}

bool ParseWithTree(std::string_view text, std::string_view file, v1::Scene* scene, TextFormat::ParseInfoTree* tree,
                   std::string* error) {
  if (static_cast<int64_t>(text.size()) > kMaxSceneBytes) {
    *error = std::string(file) + ": larger than " + std::to_string(kMaxSceneBytes) + " bytes";
    return false;
  }
  FirstErrorCollector collector;
  TextFormat::Parser parser;
  parser.RecordErrorsTo(&collector);
  parser.WriteLocationsTo(tree);
  v1::Scene parsed;
  const bool ok = parser.ParseFromString(std::string(text), &parsed);
  if (!ok || collector.has_error_) {
    if (collector.has_error_) PointAtQuotedName(text, &collector);
    *error = std::string(file) + ":" + std::to_string(collector.line_) + ":" + std::to_string(collector.col_) + ": " +
             (collector.has_error_ ? collector.message_ : std::string("cannot parse scene"));
    return false;
  }
  scene->Swap(&parsed);
  return true;
}

}  // namespace

bool ParseSceneText(std::string_view text, std::string_view file, v1::Scene* scene, std::string* error) {
  TextFormat::ParseInfoTree tree;
  return ParseWithTree(text, file, scene, &tree, error);
}

bool ValidateScene(const v1::Scene& scene, std::string* error) {
  const Checker c = CheckScene(scene);
  if (c.ok()) return true;
  *error = c.issue().PathString() + ": " + c.issue().message;
  return false;
}

void ApplySceneDefaults(v1::Scene* scene) {
  if (scene->preset() == v1::PRESET_UNSPECIFIED) scene->set_preset(v1::PRESET_DEFAULT);
  const PresetSettings preset = SettingsOf(scene->preset() == v1::PRESET_THESIS ? Preset::kThesis : Preset::kDefault);
  for (v1::Tool& tool : *scene->mutable_tools()) {
    if (tool.force_law() == v1::FORCE_LAW_UNSPECIFIED) tool.set_force_law(v1::FORCE_LAW_THESIS);
    if (!tool.has_local_radius()) tool.set_local_radius(preset.local_radius_per_tool_radius * tool.radius());
  }
  if (scene->integrator() == v1::INTEGRATOR_UNSPECIFIED) {
    scene->set_integrator(preset.integrator == Integrator::kExplicitEuler ? v1::INTEGRATOR_EXPLICIT_EULER
                                                                          : v1::INTEGRATOR_SYMPLECTIC_EULER);
  }
  if (!scene->has_dt_s()) scene->set_dt_s(0.001);
  if (!scene->has_air_resistance()) scene->set_air_resistance(0);
  if (!scene->has_stream_rate_hz()) scene->set_stream_rate_hz(60);
  if (!scene->has_quant_step()) scene->set_quant_step(1e-4);
  if (!scene->has_keyframe_interval_s()) scene->set_keyframe_interval_s(5);
  if (!scene->has_sample_batch()) scene->set_sample_batch(20);
  v1::DeviceMapping* d = scene->mutable_device();
  if (!d->has_scale()) d->set_scale(1);
  if (!d->has_force_scale()) d->set_force_scale(1);
  if (!d->has_max_force()) d->set_max_force(10);
  if (!d->has_max_force_rate()) d->set_max_force_rate(0);
  if (!d->has_max_rate_hz()) d->set_max_rate_hz(1000);
  if (!d->has_transition_force_rate()) d->set_transition_force_rate(10);
  // Passivity: `enabled` stays unset (the agent decides by its device); the rest get defaults.
  v1::Passivity* p = d->mutable_passivity();
  if (!p->has_window_s()) p->set_window_s(0.1);
  if (!p->has_max_damping()) p->set_max_damping(0.5);
  if (!p->has_encoder_quantum()) p->set_encoder_quantum(0);
  // Friction's defaults only where there is friction (a frictionless tool keeps no friction
  // fields: the scalpel may not have them).
  for (v1::Tool& tool : *scene->mutable_tools()) {
    if (!(tool.static_friction() > 0)) continue;
    if (!tool.has_kinetic_friction()) tool.set_kinetic_friction(tool.static_friction());
    if (!tool.has_friction_stiffness()) tool.set_friction_stiffness(tool.stiffness());
    if (!tool.has_friction_damping()) tool.set_friction_damping(tool.friction_stiffness() * scene->dt_s());
  }
}

bool LoadSceneText(std::string_view text, std::string_view file, v1::Scene* scene, std::string* error) {
  // Syntax first, then values, each located in the text.
  TextFormat::ParseInfoTree tree;
  v1::Scene parsed;
  if (!ParseWithTree(text, file, &parsed, &tree, error)) return false;
  const Checker c = CheckScene(parsed);
  if (!c.ok()) {
    const auto [line, col] = Locate(c.issue(), tree);
    *error = std::string(file) + ":" +
             (line > 0 ? std::to_string(line) + ":" + std::to_string(col) + ":" : std::string()) + " " +
             c.issue().PathString() + ": " + c.issue().message;
    return false;
  }
  ApplySceneDefaults(&parsed);
  scene->Swap(&parsed);
  return true;
}

bool LoadScene(const std::string& path, v1::Scene* scene, std::string* error) {
  std::string text;
  if (!ReadFile(path, &text, error)) return false;
  return LoadSceneText(text, path, scene, error);
}

}  // namespace idms
