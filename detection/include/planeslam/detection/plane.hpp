#pragma once
/// A detected plane and a frame's segmentation.
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "planeslam/detection/plane_moments.hpp"

namespace planeslam::detection {

/// Plane in Hessian form n.p = d (unit n, d >= 0: n points from the sensor origin to the plane),
/// in the frame of the cloud it was detected in.
struct Plane {
  int id = 0;                                         ///< >= 1, equals its label in the label image
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit
  double d = 0.0;                                     ///< [m]
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();     ///< mass centre [m]
  std::int64_t point_count = 0;                           ///< pixels assigned
  double mse = 0.0;                                       ///< lambda_min / K [m^2]
  Eigen::Vector3d eigenvalues = Eigen::Vector3d::Zero();  ///< of the scatter matrix, ascending
  /// Covariance of (n_x, n_y, n_z, d); rank 3 (no variance along the unit-norm constraint).
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Zero();
  PlaneMoments moments;  ///< for merging in the map
};

/// Shape class of a grid cell (paper Section III-A, Fig. 2).
enum class CellClass : std::uint8_t { kSparse = 0, kLinear = 1, kPlanar = 2, kSpherical = 3 };

/// The output of a detector on one range image.
struct Segmentation {
  int width = 0;
  int height = 0;
  std::vector<std::int32_t> labels;  ///< per pixel: plane id (>= 1) or -1 = none
  std::vector<Plane> planes;         ///< planes[i].id == i + 1
  /// Grid shape classes (grid methods only; empty otherwise), cells_x * cells_y, row-major.
  int cells_x = 0;
  int cells_y = 0;
  int cell_size = 0;
  std::vector<CellClass> cell_classes;
  /// Milliseconds per stage, in order (e.g. "moments", "grow", "refine").
  std::vector<std::pair<std::string, double>> timings_ms;
};

}  // namespace planeslam::detection
