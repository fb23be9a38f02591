// planeslam: one executable, git-style subcommands (see command_registry.hpp).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <exception>
#include <iostream>
#include <memory>
#include <new>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "command_registry.hpp"
#include "exit_codes.hpp"
#include "planeslam/datasets/errors.hpp"

namespace {

/// A run allocates its frame-sized buffers (images, clouds, label maps, a few MB each) anew for
/// every frame. glibc serves blocks over its adaptive mmap threshold with fresh mappings and hands
/// freed heap tops back to the system, so each frame would fault in and zero its pages again:
/// blocks up to 32 MB (glibc's largest threshold) come from the heap, and up to 1 GB of freed
/// memory is kept for the next frame. The peak stays that of the largest frame's buffers.
void KeepFrameBuffers() {
#if defined(__GLIBC__)
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
#endif
}

}  // namespace

int main(int argc, char** argv) {
  KeepFrameBuffers();
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
