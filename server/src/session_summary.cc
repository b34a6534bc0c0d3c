// A session's summary figures, updated from each batch of device samples (session_summary.h).
#include "session_summary.h"

#include <cmath>
#include <nlohmann/json.hpp>

namespace idms::server {
namespace {

double Norm(const v1::Vec3& v) { return std::sqrt(v.x() * v.x() + v.y() * v.y() + v.z() * v.z()); }

}  // namespace

void SessionSummary::Add(const v1::DeviceSamples& ds) {
  for (const v1::DeviceSample& s : ds.samples()) {
    const double f = Norm(s.force());
    peak_force = std::max(peak_force, f);
    const double dt = have_last ? s.time_s() - last_time_s : 0;
    if (s.contact()) force_sum_in_contact += f, ++contact_samples, contact_time_s += dt;
    const double p[3] = {s.tool_pos().x(), s.tool_pos().y(), s.tool_pos().z()};
    if (have_last) path_length += std::hypot(p[0] - last_pos[0], p[1] - last_pos[1], p[2] - last_pos[2]);
    std::copy(p, p + 3, last_pos);
    have_last = true;
    if (first_time_s < 0) first_time_s = s.time_s();
    last_time_s = s.time_s();
    warnings += s.warnings();
    if (s.force_limited()) {
      force_limit_hits += last_limited ? 0 : 1;
      force_limited_s += dt;
    }
    last_limited = s.force_limited();
    punctures += s.needle_punctured() && !last_punctured ? 1 : 0;
    last_punctured = s.needle_punctured();
    needle_deepest = std::max(needle_deepest, s.needle_inserted());
    stitches = std::max<int64_t>(stitches, s.suture_ties());
    if (s.incision_open() > 0) incision_gap = s.incision_gap(), incision_open = s.incision_open();
  }
  overruns = ds.stats().overruns();
  tick_p99_us = ds.stats().compute_p99_us();
  samples_dropped = ds.samples_dropped();
  if (ds.has_stats()) passivity_dissipated = ds.stats().passivity_dissipated();
}

std::string SessionSummary::Json() const {
  nlohmann::json j{{"peak_force", peak_force},
                   {"mean_contact_force", contact_samples > 0 ? force_sum_in_contact / contact_samples : 0.0},
                   {"contact_time_s", contact_time_s},
                   {"path_length", path_length},
                   {"warnings", warnings},
                   {"overruns", overruns},
                   {"tick_p99_us", tick_p99_us},
                   {"samples_dropped", samples_dropped},
                   {"force_limit_hits", force_limit_hits},
                   {"force_limited_s", force_limited_s},
                   {"passivity_dissipated", passivity_dissipated},
                   {"last_limited", last_limited},
                   {"punctures", punctures},
                   {"needle_deepest", needle_deepest},
                   {"stitches", stitches},
                   {"incision_gap", incision_gap},
                   {"incision_open", incision_open},
                   {"last_punctured", last_punctured},
                   {"contact_samples", contact_samples},
                   {"first_time_s", first_time_s},
                   {"last_time_s", last_time_s},
                   {"notes", notes}};
  if (have_last) j["last_tool_pos"] = {last_pos[0], last_pos[1], last_pos[2]};
  return j.dump();
}

SessionSummary SessionSummary::FromJson(const std::string& text) {
  SessionSummary s;
  const nlohmann::json j = nlohmann::json::parse(text.empty() ? "{}" : text, nullptr, false);
  if (!j.is_object()) return s;
  const auto number = [&j](const char* key, auto fallback) {
    const auto it = j.find(key);
    return it != j.end() && it->is_number() ? it->get<decltype(fallback)>() : fallback;
  };
  s.peak_force = number("peak_force", 0.0);
  s.contact_samples = number("contact_samples", int64_t{0});
  s.force_sum_in_contact = number("mean_contact_force", 0.0) * static_cast<double>(s.contact_samples);
  s.contact_time_s = number("contact_time_s", 0.0);
  s.path_length = number("path_length", 0.0);
  s.warnings = number("warnings", int64_t{0});
  s.overruns = number("overruns", uint64_t{0});
  s.tick_p99_us = number("tick_p99_us", uint32_t{0});
  s.samples_dropped = number("samples_dropped", uint64_t{0});
  s.force_limit_hits = number("force_limit_hits", int64_t{0});
  s.force_limited_s = number("force_limited_s", 0.0);
  s.passivity_dissipated = number("passivity_dissipated", 0.0);
  if (const auto it = j.find("last_limited"); it != j.end() && it->is_boolean()) s.last_limited = it->get<bool>();
  s.punctures = number("punctures", int64_t{0});
  s.needle_deepest = number("needle_deepest", 0.0);
  s.stitches = number("stitches", int64_t{0});
  s.incision_gap = number("incision_gap", 0.0);
  s.incision_open = number("incision_open", 0.0);
  if (const auto it = j.find("last_punctured"); it != j.end() && it->is_boolean()) s.last_punctured = it->get<bool>();
  s.first_time_s = number("first_time_s", -1.0);
  s.last_time_s = number("last_time_s", 0.0);
  s.notes = number("notes", uint64_t{0});
  if (const auto it = j.find("last_tool_pos"); it != j.end() && it->is_array() && it->size() == 3) {
    for (int c = 0; c < 3; ++c) s.last_pos[c] = (*it)[c].is_number() ? (*it)[c].get<double>() : 0.0;
    s.have_last = true;
  }
  return s;
}

}  // namespace idms::server
