#pragma once
/// What one scan saw: the farthest return per viewing direction, on a cube map of the sensor's
/// directions (any sensor model: a depth camera fills part of one face, a spinning LiDAR a band
/// around four). It answers whether a point in the sensor frame was in view and not hidden behind
/// something nearer, which is what the map needs to tell a plane the sensor looked at and did not
/// detect from one it never saw.
#include <Eigen/Core>
#include <cstdint>
#include <utility>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"

namespace planeslam::mapping {

class ViewBins {
 public:
  /// Bins per cube face side: about 1.8 deg at a face's centre, 0.9 deg at its edges.
  static constexpr int kBinsPerFace = 64;

  ViewBins() = default;
  /// From every `stride`-th row and column of the cloud (sensor frame).
  ViewBins(const datasets::OrganizedCloud& cloud, int stride);

  /// Whether the line of sight reached `p_sensor`: its direction was measured, and a return in
  /// that direction's bin lies no closer than |p| - tolerance (the point is on or in front of
  /// something seen there; the farthest return, so that the spread of ranges across one bin of an
  /// oblique surface does not hide it). False for directions without returns (outside the field
  /// of view, or no echo) and behind everything seen there.
  bool Reaches(const Eigen::Vector3d& p_sensor, double tolerance) const;

  bool empty() const { return farthest_.empty(); }
  std::size_t bins() const { return farthest_.size(); }

 private:
  static std::uint32_t Bin(const Eigen::Vector3d& direction);

  std::vector<std::pair<std::uint32_t, float>> farthest_;  ///< (bin, farthest range [m]), by bin
};

}  // namespace planeslam::mapping
