// Starting the real idms-agent binary from a test and waiting for it without sleeping: posix_spawn
// with stderr to a file, pidfd + poll for the exit.
#pragma once

#include <chrono>
#include <optional>
#include <string>
#include <vector>

namespace idms::test {

class AgentProcess {
 public:
  // Starts IDMS_AGENT_BIN with args; stdout and stderr go to log_path.
  AgentProcess(const std::vector<std::string>& args, const std::string& log_path);
  ~AgentProcess();  // kills the agent if it is still running
  AgentProcess(const AgentProcess&) = delete;
  AgentProcess& operator=(const AgentProcess&) = delete;

  bool started() const { return pid_ > 0; }
  void Signal(int signal);
  // The exit status (exit code, or 128 + signal) once the agent exited within timeout; nullopt otherwise.
  std::optional<int> Wait(std::chrono::milliseconds timeout);
  std::string Log() const;

 private:
  int pid_ = -1;
  int pidfd_ = -1;
  std::optional<int> status_;
  std::string log_path_;
};

// A fresh directory under the test's temporary directory.
std::string TempDir(const std::string& name);
std::string ReadText(const std::string& path);

}  // namespace idms::test
