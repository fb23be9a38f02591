#pragma once
/// A rotating multi-beam LiDAR (Velodyne HDL-64E-like) over a SyntheticScene.
///
/// Geometry: `beams` lasers at fixed elevations (default: the HDL-64E's two blocks, +2.0 to
/// -8.33 deg and -8.87 to -24.8 deg, evenly spaced within each block), fired `columns` times per
/// turn. The organized cloud has one row per laser (row 0 the highest) and one column per firing,
/// laid out as planeslam's KITTI reader lays out a .bin (column c at azimuth
/// pi - 2 pi (c + 0.25) / columns, so column columns/2 looks along +x): written as a .bin and read
/// back, a scan lands in the same cells. Sensor frame x forward, y left, z up.
///
/// Timing: the head turns clockwise seen from above, once per scan period; the scan's reference
/// time (its stamp and pose) is when it faces forward, so the firing at azimuth a happens
/// -a / (2 pi) * period after it (half a period before at the back, +pi, half a period after at
/// the back, -pi; KITTI's convention). With motion distortion on, each firing is cast from the
/// scanner pose at its own time and its point is written in that pose's frame, as a real scanner
/// writes it (no de-skewing); off, the whole scan is cast from the reference pose.
///
/// Measurements: range noise (normal, constant sigma, truncated), returns beyond the range limits
/// or at grazing incidence dropped, optional random dropouts; reflectance = albedo of the surface
/// (fixed per plane id, drawn from it) times (0.3 + 0.7 cos incidence).
///
/// Speed: primitives are bucketed in a uniform 2D grid (16 m cells); a scan visits the cells
/// within range, and each primitive there is cast only against the rows and columns its bounding
/// sphere covers (widened by the scanner's motion during the scan).
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "planeslam/datasets/synthetic_sensor.hpp"

namespace planeslam::datasets {

struct LidarSimConfig {
  /// Laser elevations [deg], any order (rows are sorted highest first); empty = HDL-64E.
  std::vector<double> elevations_deg;
  int columns = 2083;                ///< firings per turn (0.1728 deg at 2083)
  double min_range = 1.0;            ///< [m]
  double max_range = 120.0;          ///< [m] (HDL-64E: 120 m)
  bool noise = true;                 ///< add range noise
  double range_sigma = 0.02;         ///< [m]
  double noise_truncation = 3.0;     ///< [sigma]
  double max_incidence_deg = 88.0;   ///< returns at a larger angle to the normal are dropped
  double dropout_rate = 0.0;         ///< probability of losing a return at random [1]
  bool motion_distortion = false;    ///< cast each firing from the pose at its own time
};

/// The HDL-64E elevations [deg], highest first (64 values).
std::vector<double> Hdl64ElevationsDeg();

/// The rotating scanner. Render() casts a still scan from one pose; RenderMoving() a scan whose
/// firings follow `pose_at(dt)` (T_world_sensor dt seconds after the reference time).
class RotatingLidar final : public SyntheticSensor {
 public:
  RotatingLidar(const SyntheticScene& scene, const LidarSimConfig& config, double scan_period);
  ~RotatingLidar() override;

  SensorModel Model() const override { return SensorModel::kSpherical; }
  int Width() const override;
  int Height() const override;
  Eigen::Vector3d RayDirection(int row, int col) const override;
  SyntheticRender Render(const Pose& T_world_sensor, std::uint64_t noise_seed) const override;
  SyntheticRender RenderMoving(const std::function<Pose(double dt)>& pose_at,
                               std::uint64_t noise_seed) const;

  /// Firing time of column c after the reference time [s].
  double ColumnTimeOffset(int col) const;
  /// Elevations of the rows, highest first [deg].
  const std::vector<double>& ElevationsDeg() const;
  const LidarSimConfig& config() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace planeslam::datasets
