// The real idms-agent binary, started from a test (see tests/common/child_process.h).
#pragma once

#include "child_process.h"

namespace idms::test {

class AgentProcess : public ChildProcess {
 public:
  AgentProcess(const std::vector<std::string>& args, const std::string& log_path)
      : ChildProcess(IDMS_AGENT_BIN, args, log_path) {}
};

}  // namespace idms::test
