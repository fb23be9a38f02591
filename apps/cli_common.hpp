#pragma once
/// Options and helpers every subcommand shares: config files, --set, --print-config, --quiet,
/// and the progress bar.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cstddef>
#include <string>
#include <vector>

#include "config.hpp"

namespace planeslam::app {

struct ConfigOptions {
  std::vector<std::string> config_files;  ///< applied in order over the defaults
  std::vector<std::string> overrides;     ///< "section.key=value"
  bool print_config = false;
  bool quiet = false;
};

/// Adds --config, --set, --print-config and --quiet to `sub`.
void AddConfigOptions(CLI::App& sub, ConfigOptions& options);

/// Defaults, then each --config file, then each --set. Throws ConfigError/IoError.
Config LoadConfig(const ConfigOptions& options);

/// When --print-config was given, prints the effective config to stdout and returns true (the
/// caller then exits 0 without doing the work).
bool MaybePrintConfig(const ConfigOptions& options, const Config& config);

/// A one-line progress bar on stderr; silent when stderr is not a terminal or when quiet.
class ProgressBar {
 public:
  ProgressBar(std::string label, std::size_t total, bool quiet);
  ~ProgressBar();
  void Update(std::size_t done);
  void Finish();

 private:
  std::string label_;
  std::size_t total_;
  bool enabled_;
  bool finished_ = false;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
};

/// Creates `dir` (and parents); throws IoError naming it when that fails.
void EnsureDirectory(const std::string& dir);

}  // namespace planeslam::app
