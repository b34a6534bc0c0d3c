// Starting a real idms binary (agent, server, renderer) from a test and waiting for it without
// sleeping: posix_spawn with stderr to a file, stdout to the file or to a pipe the test reads
// line by line, pidfd + poll for the exit.
#pragma once

#include <chrono>
#include <optional>
#include <string>
#include <vector>

namespace idms::test {

class ChildProcess {
 public:
  // Starts `binary` with args; stderr (and stdout, unless capture_stdout) go to log_path.
  ChildProcess(const std::string& binary, const std::vector<std::string>& args, const std::string& log_path,
               bool capture_stdout = false);
  ~ChildProcess();  // kills the child if it is still running
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  bool started() const { return pid_ > 0; }
  int pid() const { return pid_; }
  void Signal(int signal);
  // The exit status (exit code, or 128 + signal) once the child exited within timeout; nullopt otherwise.
  std::optional<int> Wait(std::chrono::milliseconds timeout);
  // The next line the child wrote to stdout (capture_stdout only), without its newline.
  std::optional<std::string> ReadLine(std::chrono::milliseconds timeout);
  std::string Log() const;

 private:
  int pid_ = -1;
  int pidfd_ = -1;
  int stdout_fd_ = -1;
  std::string pending_;  // stdout read but not yet returned
  std::optional<int> status_;
  std::string log_path_;
};

// Runs a command to completion (two minutes at most), its stderr and stdout to `log`; its exit
// status, or -1 if it did not end.
int RunCommand(const std::vector<std::string>& argv, const std::string& log);

// A fresh directory under the test's temporary directory.
std::string TempDir(const std::string& name);
std::string ReadText(const std::string& path);
// The numbers of a file after its first line (the agent's --dump-final: a comment, then "x y z" per vertex).
std::vector<double> ReadNumbersAfterFirstLine(const std::string& path);

}  // namespace idms::test
