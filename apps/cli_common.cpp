#include "cli_common.hpp"

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <iostream>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::app {

void AddConfigOptions(CLI::App& sub, ConfigOptions& options) {
  sub.add_option("-c,--config", options.config_files,
                 "YAML config file(s) applied over the defaults (see config/basic.yaml and "
                 "config/reference.yaml)")
      ->type_name("FILE");
  sub.add_option("--set", options.overrides, "Override one key, e.g. --set grid.cell_size=4")
      ->type_name("SECTION.KEY=VALUE");
  sub.add_flag("--print-config", options.print_config,
               "Print the effective configuration as YAML and exit");
  sub.add_flag("-q,--quiet", options.quiet, "No progress bar");
}

Config LoadConfig(const ConfigOptions& options) {
  Config config;
  for (const auto& file : options.config_files) config.LoadFile(file);
  for (const auto& assignment : options.overrides) config.Set(assignment);
  return config;
}

bool MaybePrintConfig(const ConfigOptions& options, const Config& config) {
  if (!options.print_config) return false;
  std::cout << config.ToYaml(true);
  return true;
}

ProgressBar::ProgressBar(std::string label, std::size_t total, bool quiet)
    : label_(std::move(label)),
      total_(total),
      enabled_(!quiet && ::isatty(STDERR_FILENO) && total > 0),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_) {}

ProgressBar::~ProgressBar() { Finish(); }

void ProgressBar::Update(std::size_t done) {
  if (!enabled_ || finished_) return;
  const auto now = std::chrono::steady_clock::now();
  // Redraw at most 10 times a second; the terminal is slower than the pipeline.
  if (done < total_ && now - last_draw_ < std::chrono::milliseconds(100)) return;
  last_draw_ = now;
  const int width = 30;
  const int filled = static_cast<int>(width * done / total_);
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  const double rate = elapsed > 0 ? done / elapsed : 0.0;
  std::fprintf(stderr, "\r%s [%s%s] %zu/%zu %.1f/s", label_.c_str(),
               std::string(filled, '#').c_str(), std::string(width - filled, '.').c_str(), done,
               total_, rate);
  std::fflush(stderr);
}

void ProgressBar::Finish() {
  if (!enabled_ || finished_) return;
  finished_ = true;
  std::fprintf(stderr, "\r\033[K");
  std::fflush(stderr);
}

void EnsureDirectory(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir)) {
    throw IoError(dir, "cannot create output directory" + (ec ? ": " + ec.message() : ""));
  }
}

}  // namespace planeslam::app
