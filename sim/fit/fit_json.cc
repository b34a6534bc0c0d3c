#include "fit_json.h"

namespace idms::fit {

nlohmann::json MapJson(const MapResult& r) {
  nlohmann::json j = {{"presses", r.points.size()}, {"background", r.background}, {"spread", r.spread},
                      {"replays", r.replays},       {"seconds", r.seconds},       {"lump", {{"found", r.lump.found}}}};
  if (r.lump.found) {
    j["lump"].update({{"x", r.lump.x},
                      {"y", r.lump.y},
                      {"xy_sigma", r.lump.xy_sigma},
                      {"radius", r.lump.radius},
                      {"ratio", r.lump.ratio},
                      {"ratio_sigma", r.lump.ratio_sigma},
                      {"presses", r.lump.presses}});
  }
  j["points"] = nlohmann::json::array();
  for (const MapPoint& p : r.points) {
    j["points"].push_back(
        {{"x", p.x}, {"y", p.y}, {"scale", p.scale}, {"sigma", p.sigma}, {"peak_force", p.peak_force}});
  }
  return j;
}

}  // namespace idms::fit
