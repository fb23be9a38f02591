#pragma once
/// The range image every detector works on: a width x height grid of 3D points.
#include <Eigen/Core>

#include <cmath>
#include <cstddef>
#include <limits>
#include <vector>

namespace planeslam::datasets {

/// How the grid was produced; it decides what "neighbour" means near the image borders.
enum class SensorModel {
  kPinhole,    ///< depth camera: rows/cols are image rows/cols
  kSpherical,  ///< laser/LiDAR: rows are elevation, columns azimuth (may wrap around)
};

/// Pinhole camera intrinsics (pixels). fy may be negative for datasets with a flipped y axis
/// (ICL-NUIM), which mirrors the back-projected cloud so it agrees with their ground truth.
struct PinholeIntrinsics {
  int width = 640;     ///< image width [px]
  int height = 480;    ///< image height [px]
  double fx = 535.4;   ///< focal length x [px] (TUM fr3 default)
  double fy = 539.2;   ///< focal length y [px]
  double cx = 320.1;   ///< principal point x [px]
  double cy = 247.6;   ///< principal point y [px]
};

/// Organized point cloud: row-major, metres, sensor frame; an invalid pixel is NaN in all three
/// coordinates.
struct OrganizedCloud {
  int width = 0;
  int height = 0;
  SensorModel model = SensorModel::kPinhole;
  std::vector<Eigen::Vector3f> points;  ///< width*height entries, index = row*width + col

  OrganizedCloud() = default;
  OrganizedCloud(int w, int h, SensorModel m = SensorModel::kPinhole)
      : width(w), height(h), model(m),
        points(static_cast<std::size_t>(w) * h,
               Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN())) {}

  std::size_t size() const { return points.size(); }
  bool empty() const { return points.empty(); }
  const Eigen::Vector3f& at(int row, int col) const {
    return points[static_cast<std::size_t>(row) * width + col];
  }
  Eigen::Vector3f& at(int row, int col) {
    return points[static_cast<std::size_t>(row) * width + col];
  }
  static bool IsValid(const Eigen::Vector3f& p) { return std::isfinite(p.z()); }
  bool IsValid(std::size_t index) const { return IsValid(points[index]); }
  /// Number of pixels holding a measurement.
  std::size_t CountValid() const {
    std::size_t n = 0;
    for (const auto& p : points) n += IsValid(p) ? 1 : 0;
    return n;
  }
};

/// The cloud at 1/factor resolution: every factor-th row and column, starting with the first
/// (picked, not averaged: an average across a depth edge would invent points in mid-air). The
/// grid stays organized, so a pinhole cloud keeps a pinhole grid with DecimateIntrinsics.
/// Requires 1 <= factor <= 16 (CheckError otherwise); factor 1 returns a copy.
OrganizedCloud Decimate(const OrganizedCloud& cloud, int factor);

/// Intrinsics of the pixel grid Decimate keeps: pixel (u, v) of the result is pixel (f u, f v) of
/// the full image, so fx, fy, cx, cy scale by 1/f and the size rounds up.
PinholeIntrinsics DecimateIntrinsics(const PinholeIntrinsics& intrinsics, int factor);

}  // namespace planeslam::datasets
