// One session recorded by the real idms-agent (scripted palpation of hex_4x5_home) through the
// real idms-server, shared by the render tests: the server stays up for the endpoint tests.
#pragma once

#include <memory>
#include <string>

#include "server_process.h"

namespace idms::test {

struct RecordedSession {
  std::unique_ptr<ServerProcess> server;
  std::string dir;
  std::string id;             // the session
  std::string recording;      // the downloaded .mcap
  double duration_s = 0;      // log time of the last message - the first, s
  double peak_force_t_s = 0;  // session time of the device batch with the largest |force|
  double peak_force = 0;
  double peak_tool_pos[3] = {0, 0, 0};
  double tool_radius = 0;
  double before_contact_t_s = -1;  // session time of the last device batch with no contact before the first contact
  std::string error;               // why the session could not be made
};

// Made once per test program (the first call runs the server and agent: a few seconds).
RecordedSession& Session();

}  // namespace idms::test
