#pragma once
/// Config sections "slam" (mapping::SlamConfig) and "run" (RunConfig below).
#include <string>

#include "config.hpp"
#include "planeslam/mapping/slam_system.hpp"

namespace planeslam::app {

/// What `planeslam run` feeds the SLAM system and which optional outputs it writes.
struct RunConfig {
  std::string method = "grid";        ///< plane detector
  bool start_at_ground_truth = true;  ///< first pose = ground truth's when known
  bool octomap = true;                ///< write octomap.bt
  double octomap_resolution = 0.05;   ///< [m]
  double octomap_max_range = 4.0;     ///< [m]
  double octomap_downsample = 0.05;   ///< [m] voxel thinning before insertion
  int max_frames = 0;                 ///< [frames] 0 = all
  int frame_stride = 1;               ///< [frames]
  double ate_max_time_difference = 0.01;  ///< [s] evo's default t_max_diff
};

}  // namespace planeslam::app
