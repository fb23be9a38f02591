#pragma once
/// `planeslam bench odometry SEQUENCE`: our plane odometry against PCL's GICP on the same frames
/// with the same constant-velocity prior; time per frame and RPE (evo semantics) for both.
#include <string>

#include "config.hpp"

namespace planeslam::app::bench {

struct OdometryOptions {
  std::string out_dir;        ///< DIR/planes.txt and DIR/gicp.txt (TUM format); empty = none
  std::string json_path;      ///< empty = none
  int max_frames = 0;         ///< 0 = all
  std::string method;         ///< our detector; empty = the config's detection.method
  double gicp_voxel = 0.05;   ///< GICP voxel grid leaf [m]
  double gicp_max_distance = 0.2;  ///< GICP max correspondence distance [m]
  bool quiet = false;
};

/// Runs the comparison, prints a table; returns the exit code.
int RunOdometryBench(const std::string& sequence, const Config& config,
                     const OdometryOptions& options);

}  // namespace planeslam::app::bench
