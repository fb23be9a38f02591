// `planeslam report DIR`: (re)writes DIR/report.html from the files of a `planeslam run` output
// folder.
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "cli_common.hpp"
#include "command_registry.hpp"
#include "config_sections_app.hpp"
#include "exit_codes.hpp"
#include "planeslam/datasets/errors.hpp"
#include "report.hpp"

namespace planeslam::app {
namespace {

class ReportCommand : public Command {
 public:
  std::string Name() const override { return "report"; }
  std::string Summary() const override {
    return "Write report.html (3-D plane map, trajectory, plots, summary) of a run output folder";
  }
  int Order() const override { return 25; }

  void Setup(CLI::App& sub) override {
    sub.add_option("DIR", dir_, "output folder of 'planeslam run'")->required();
    AddConfigOptions(sub, options_);
    sub.footer(
        "Reads summary.json, plane_map.json, pose_graph.g2o (required) and metrics.json,\n"
        "frames.csv, config.yaml, trajectory_tum.txt, ground_truth_tum.txt, keyframe_cloud.pcd,\n"
        "plots/*.svg (when present); writes DIR/report.html, one self-contained page that opens\n"
        "from disk in any current browser.\n\n"
        "Example:\n"
        "  planeslam report planeslam_out --set report.cloud_points=50000");
  }

  int Run() override {
    const Config config = LoadConfig(options_);
    if (MaybePrintConfig(options_, config)) return kExitSuccess;
    if (!std::filesystem::is_directory(dir_)) throw IoError(dir_, "not a folder");
    if (!ReportAvailable()) {
      std::cerr << "planeslam report: error: " << ReportUnavailableReason() << "\n";
      return kExitError;
    }
    const auto& report = config.Get<ReportConfig>("report");
    WriteRunReport(dir_, static_cast<std::size_t>(report.cloud_points));
    if (!options_.quiet) std::printf("wrote %s/report.html\n", dir_.c_str());
    return kExitSuccess;
  }

 private:
  std::string dir_;
  ConfigOptions options_;
};

PLANESLAM_REGISTER_COMMAND(ReportCommand);

}  // namespace
}  // namespace planeslam::app
