// A session's summary figures, updated from each batch of device samples.
#include <cmath>
#include <nlohmann/json.hpp>

#include "live_session.h"

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
  }
  overruns = ds.stats().overruns();
  tick_p99_us = ds.stats().compute_p99_us();
  samples_dropped = ds.samples_dropped();
}

std::string SessionSummary::Json() const {
  return nlohmann::json{{"peak_force", peak_force},
                        {"mean_contact_force", contact_samples > 0 ? force_sum_in_contact / contact_samples : 0.0},
                        {"contact_time_s", contact_time_s},
                        {"path_length", path_length},
                        {"warnings", warnings},
                        {"overruns", overruns},
                        {"tick_p99_us", tick_p99_us},
                        {"samples_dropped", samples_dropped}}
      .dump();
}

}  // namespace idms::server
