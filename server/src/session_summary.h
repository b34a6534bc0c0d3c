// A session's summary figures (the session list's columns), accumulated from its device samples:
// live, as they arrive; at start-up, from a recording a crash left; and carried through a resume
// after a restart (FromJson), so that they always describe the whole recording.
#pragma once

#include <cstdint>
#include <string>

#include "idms/protocol/idms.pb.h"

namespace idms::server {

struct SessionSummary {
  double peak_force = 0;            // |force| maximum, force units
  double force_sum_in_contact = 0;  // for the mean contact force
  int64_t contact_samples = 0;
  double contact_time_s = 0;
  double path_length = 0;  // of the tool centre, model units
  int64_t warnings = 0;
  uint64_t overruns = 0;
  uint32_t tick_p99_us = 0;         // compute time p99 (the agent's LoopStats)
  uint64_t samples_dropped = 0;     // lost to the agent's backlog while disconnected
  int64_t force_limit_hits = 0;     // times the device force reached its limit (runs of clamped samples)
  double force_limited_s = 0;       // time spent at the limit
  double passivity_dissipated = 0;  // energy dissipated by the passivity controller (the agent's LoopStats)
  bool last_limited = false;        // the last sample was clamped (a run continues across batches)
  int64_t punctures = 0;            // a needle's entries into the tissue (runs of punctured samples)
  double needle_deepest = 0;        // its largest inserted length, model units
  bool last_punctured = false;      // the last sample's needle was in
  int64_t stitches = 0;             // a suture's knots (the last sample's DeviceSample.suture_ties)
  double incision_gap = 0;          // the incision's gap and open width at the last sample (0: no cut)
  double incision_open = 0;
  bool have_last = false;
  double last_pos[3] = {0, 0, 0};
  double first_time_s = -1, last_time_s = 0;  // simulation time of the first and last sample
  uint64_t notes = 0;  // the last note id given (notes made live and added in replay share the count)

  void Add(const v1::DeviceSamples& batch);
  // Every field, so that FromJson(Json()) carries on exactly where the summary was.
  std::string Json() const;
  // A summary stored by Json(); an empty or unreadable text gives an empty summary.
  static SessionSummary FromJson(const std::string& text);
};

}  // namespace idms::server
