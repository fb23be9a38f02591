#pragma once
/// Config sections "slam" (mapping::SlamConfig) and "run" (RunConfig below).
#include <memory>
#include <string>

#include "config.hpp"
#include "planeslam/mapping/slam_system.hpp"

namespace planeslam::app {

/// What `planeslam run` feeds the SLAM system and which optional outputs it writes.
struct RunConfig {
  bool start_at_ground_truth = true;  ///< first pose = ground truth's when known
  int max_frames = 0;                 ///< [frames] 0 = all
  int frame_stride = 1;               ///< [frames]
  /// Detect and track on every n-th row and column of each frame (datasets::Decimate); as
  /// odometry.decimation, for Kinect-class depth whose neighbouring pixels share their errors.
  int decimation = 1;
  double ate_max_time_difference = 0.01;  ///< [s] evo's default t_max_diff
  /// A frame that cannot be read: "skip" leaves it out and carries on, "stop" ends the run there;
  /// both write the outputs of the frames done.
  std::string on_bad_frame = "skip";
  /// Threads of `planeslam run` (reading and detecting ahead, output files); 0 = the machine's
  /// cores. The outputs do not depend on it.
  int threads = 0;
};

/// The SLAM system configured from `config`'s sections slam, association, registration,
/// point_to_plane, pose_graph and plane_map (as `planeslam run` uses it).
std::unique_ptr<mapping::SlamSystem> MakeSlamSystem(const Config& config);

}  // namespace planeslam::app
