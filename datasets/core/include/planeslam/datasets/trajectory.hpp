#pragma once
/// Timestamped poses (T_world_sensor). IO for TUM/KITTI/EuRoC lives in trajectory_io.hpp.
#include <Eigen/Geometry>

#include <cstddef>
#include <vector>

namespace planeslam {

/// A rigid transform; names say the frames: T_world_sensor maps sensor coordinates to world.
using Pose = Eigen::Isometry3d;

namespace datasets {

/// Poses with timestamps (seconds), in order of increasing time.
struct Trajectory {
  std::vector<double> stamps;
  std::vector<Pose> poses;

  std::size_t size() const { return poses.size(); }
  bool empty() const { return poses.empty(); }
  void Add(double stamp, const Pose& pose) {
    stamps.push_back(stamp);
    poses.push_back(pose);
  }
};

}  // namespace datasets
}  // namespace planeslam
