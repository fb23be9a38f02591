#pragma once
/// Config sections "output" and "report" owned by the app layer.
#include <string>

namespace planeslam::app {

/// Where outputs go.
struct OutputConfig {
  std::string directory = "planeslam_out";  ///< default output folder of `run`
};

/// The self-contained HTML report (report.html) of `run` and `detect`.
struct ReportConfig {
  bool enabled = true;  ///< write report.html (`run --no-report` turns it off too)
  /// Most points of the keyframe cloud in the report (voxel-thinned to fit); 0 = no cloud.
  int cloud_points = 150000;
};

}  // namespace planeslam::app
