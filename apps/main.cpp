// planeslam: one executable, git-style subcommands (see command_registry.hpp).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <exception>
#include <iostream>
#include <memory>
#include <new>

#include "command_registry.hpp"
#include "exit_codes.hpp"
#include "planeslam/datasets/errors.hpp"

int main(int argc, char** argv) {
  using planeslam::app::Command;
  namespace exit_code = planeslam::app;
  CLI::App app{
      "planeslam: fast plane detection and plane-based SLAM on range images\n"
      "(depth cameras, organized laser scans, LiDAR)."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "planeslam 0.1.0");
  app.footer(
      "Examples:\n"
      "  planeslam run                      SLAM on the built-in synthetic room, outputs in "
      "planeslam_out/\n"
      "  planeslam <command> --help         options and examples of one command");

  std::vector<std::unique_ptr<Command>> commands;
  for (const auto& factory : planeslam::app::CommandRegistry()) commands.push_back(factory());
  std::sort(commands.begin(), commands.end(),
            [](const auto& a, const auto& b) { return a->Order() < b->Order(); });
  std::vector<std::pair<CLI::App*, Command*>> subs;
  for (auto& command : commands) {
    CLI::App* sub = app.add_subcommand(command->Name(), command->Summary());
    command->Setup(*sub);
    subs.emplace_back(sub, command.get());
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }

  try {
    for (auto& [sub, command] : subs) {
      if (sub->parsed()) return command->Run();
    }
  } catch (const planeslam::IoError& e) {
    std::cerr << "planeslam: error: " << e.what() << "\n";
    return exit_code::kExitError;
  } catch (const planeslam::ConfigError& e) {
    std::cerr << "planeslam: config error: " << e.what() << "\n";
    return exit_code::kExitError;
  } catch (const std::bad_alloc&) {
    std::cerr << "planeslam: error: out of memory\n";
    return exit_code::kExitOutOfMemory;
  } catch (const std::exception& e) {
    std::cerr << "planeslam: internal error: " << e.what() << "\n";
    return exit_code::kExitInternalError;
  }
  return 1;
}
