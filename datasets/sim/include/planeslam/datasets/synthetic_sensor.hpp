#pragma once
/// Simulated range sensors over a SyntheticScene: a pinhole depth camera (Kinect-like noise and
/// dropouts) and a spherical scanner (panning laser). Both cast one exact ray per pixel.
///
/// Frames: the pinhole sensor frame is the optical frame (x right, y down, z forward, as in TUM);
/// the spherical sensor frame is x forward, y left, z up. T_world_sensor maps sensor to world.
#include <cstdint>
#include <memory>
#include <vector>

#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/synthetic_scene.hpp"
#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::datasets {

/// Depth camera model. Defaults: TUM fr3 intrinsics, Kinect v1 noise.
struct PinholeSimConfig {
  PinholeIntrinsics intrinsics;   ///< [px]
  double min_depth = 0.3;         ///< closer returns are dropped [m]
  double max_depth = 8.0;         ///< farther returns are dropped [m]
  bool noise = true;              ///< add depth noise
  /// sigma(z) = noise_k * z^2 [1/m]: Khoshelham & Elberink 2012 (Kinect v1 depth error).
  double noise_k = 1.425e-3;
  /// Noise is a normal truncated at this many sigma (outliers are not modelled) [sigma].
  double noise_truncation = 3.0;
  bool quantize_disparity = false;  ///< round disparity to 1/disparity_subpixel pixel
  double baseline = 0.075;          ///< projector-camera baseline for quantisation [m]
  double disparity_subpixel = 8.0;  ///< disparity steps per pixel (Kinect v1: 1/8 px)
  /// Returns whose angle between ray and surface normal exceeds this are dropped [deg].
  double max_incidence_deg = 80.0;
  bool edge_dropout = true;  ///< drop both pixels of a depth discontinuity
  /// A depth jump between 4-neighbours larger than edge_jump * depth is a discontinuity [1].
  double edge_jump = 0.05;
  double dropout_rate = 0.0;  ///< probability of losing any pixel at random [1]
};

/// Spherical scanner: rows are elevation (top row = elevation_max), columns azimuth (column 0 at
/// +azimuth_fov/2, i.e. to the left/behind, increasing to the right). Ranges along the ray.
struct SphericalSimConfig {
  double azimuth_fov_deg = 360.0;          ///< [deg]
  double azimuth_resolution_deg = 0.5;     ///< [deg/column]
  double elevation_min_deg = -45.0;        ///< [deg]
  double elevation_max_deg = 45.0;         ///< [deg]
  double elevation_resolution_deg = 0.5;   ///< [deg/row]
  double min_range = 0.3;                  ///< [m]
  double max_range = 30.0;                 ///< [m]
  bool noise = true;                       ///< add range noise
  double range_sigma = 0.01;               ///< constant range noise sigma [m]
  double noise_truncation = 3.0;           ///< [sigma]
  double max_incidence_deg = 85.0;         ///< [deg]
  double dropout_rate = 0.0;               ///< [1]

  int Width() const;   ///< number of azimuth columns
  int Height() const;  ///< number of elevation rows
};

/// One simulated measurement and its exact ground truth.
struct SyntheticRender {
  OrganizedCloud cloud;  ///< measured points in the sensor frame [m], NaN = no return
  Image16 labels;        ///< plane id of each valid pixel; 0 = no return or curved surface
  /// Exact depth z (pinhole) or range (spherical) of the first surface hit before noise and
  /// dropouts; NaN where the ray hits nothing [m]. Primitives lying wholly beyond the maximum
  /// range are not cast, so a value beyond the maximum range may belong to a farther surface.
  std::vector<float> true_range;
  /// Reflectance in [0, 1] per pixel (rotating LiDAR only; empty for the other sensors).
  std::vector<float> intensity;
};

/// Ray caster for one scene and one sensor. Thread-safe: Render() is const.
class SyntheticSensor {
 public:
  virtual ~SyntheticSensor() = default;
  virtual SensorModel Model() const = 0;
  virtual int Width() const = 0;
  virtual int Height() const = 0;
  /// Renders the view from T_world_sensor; `noise_seed` drives noise and random dropouts.
  virtual SyntheticRender Render(const Pose& T_world_sensor, std::uint64_t noise_seed) const = 0;
  /// Unit ray direction of pixel (row, col) in the sensor frame.
  virtual Eigen::Vector3d RayDirection(int row, int col) const = 0;
};

/// The scene is copied; the sensor keeps no reference to it.
std::unique_ptr<SyntheticSensor> MakePinholeSensor(const SyntheticScene& scene,
                                                   const PinholeSimConfig& config);
std::unique_ptr<SyntheticSensor> MakeSphericalSensor(const SyntheticScene& scene,
                                                     const SphericalSimConfig& config);

/// Rotation from the forward-left-up body frame to the optical frame: R_body_optical, so
/// T_world_optical = T_world_body * R_body_optical.
Eigen::Matrix3d BodyFromOptical();

}  // namespace planeslam::datasets
