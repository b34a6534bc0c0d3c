// How idms-sim subcommands register themselves: each tools/cmd_*.cc defines one
// IDMS_SIM_COMMAND, so adding a subcommand touches no shared file.
#pragma once

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <string>

namespace idms::tool {

// Adds one subcommand (options and callback) to `app`. Callbacks report failure by throwing
// CLI::RuntimeError(message, exit_code) after printing the message to stderr.
using CommandSetup = void (*)(CLI::App& app);

struct CommandRegistrar {
  CommandRegistrar(int order, CommandSetup setup);
};

// Prints `j` as one JSON object on one line to stdout.
void PrintJson(const nlohmann::json& j);

// Prints "idms-sim <command>: <message>" to stderr and exits the subcommand with status 1.
[[noreturn]] void Fail(const std::string& command, const std::string& message);

}  // namespace idms::tool

#define IDMS_SIM_CONCAT2(a, b) a##b
#define IDMS_SIM_CONCAT(a, b) IDMS_SIM_CONCAT2(a, b)
// ORDER sorts the subcommands in --help.
#define IDMS_SIM_COMMAND(ORDER, SETUP) \
  static const ::idms::tool::CommandRegistrar IDMS_SIM_CONCAT(idms_sim_command_, __LINE__)(ORDER, SETUP)
