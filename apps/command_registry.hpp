#pragma once
/// Self-registering subcommands. Each apps/cmd_*.cpp defines a Command subclass and registers it
/// with PLANESLAM_REGISTER_COMMAND; main() lists exactly the registered (working) subcommands.
#include <CLI/CLI.hpp>

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace planeslam::app {

class Command {
 public:
  virtual ~Command() = default;
  virtual std::string Name() const = 0;
  /// One line for the top-level --help.
  virtual std::string Summary() const = 0;
  /// Position in the --help listing (detect, run, eval, simulate, bench, ...).
  virtual int Order() const { return 100; }
  /// Declares options (bound to members) and examples on `sub`.
  virtual void Setup(CLI::App& sub) = 0;
  /// Runs after parsing; returns the process exit code. Throws IoError/ConfigError on bad input.
  virtual int Run() = 0;
};

using CommandFactory = std::function<std::unique_ptr<Command>()>;
std::vector<CommandFactory>& CommandRegistry();

struct CommandRegistrar {
  explicit CommandRegistrar(CommandFactory factory) {
    CommandRegistry().push_back(std::move(factory));
  }
};

}  // namespace planeslam::app

#define PLANESLAM_REGISTER_COMMAND(Type)                                 \
  static const ::planeslam::app::CommandRegistrar planeslam_registrar_##Type( \
      [] { return std::unique_ptr<::planeslam::app::Command>(new Type()); })
