#pragma once
/// In-process PCL baselines for `planeslam bench`: PCL's OrganizedMultiPlaneSegmentation (plane
/// detection) and GeneralizedIterativeClosestPoint (frame-to-frame odometry).
///
/// This header is PCL-free on purpose. The PCL code (apps/pcl/baselines.cpp) is built into a
/// plugin, libplaneslam_pcl.so next to the executable, that OmpsDetector and GicpOdometry load
/// with dlopen when they are first constructed (apps/pcl_plugin.cpp): the executable does not
/// link PCL, whose 40-odd shared libraries would otherwise be loaded and relocated at every start.
/// Code outside apps/pcl/ must guard its use with `#ifdef PLANESLAM_HAVE_PCL_BASELINES` (the
/// plugin is only built when PCL is found).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/trajectory.hpp"
#include "planeslam/detection/plane.hpp"
#include "planeslam/detection/plane_detector.hpp"

namespace planeslam::app::pcl_baselines {

/// Settings of the `pcl_omps` baseline: IntegralImageNormalEstimation followed by
/// OrganizedMultiPlaneSegmentation::segment(). The defaults are tuned so the baseline is not a straw
/// man on noisy Kinect data: each is the best of its plausible range on the synthetic room with
/// Kinect noise, by the share of correctly detected planes (Hoover T = 0.8).
/// PCL's own default maximum curvature (0.001) rejects most real Kinect planes (depth noise grows
/// with z^2, so a noisy wall's lambda_min / trace exceeds it).
struct OmpsConfig {
  /// "covariance" (COVARIANCE_MATRIX) or "average_3d_gradient" (AVERAGE_3D_GRADIENT).
  std::string normal_method = "covariance";
  /// Depth discontinuity factor: neighbours whose depth differs more than factor*z are not smoothed
  /// across [1/m]. PCL's organized segmentation demo uses 0.02.
  double max_depth_change_factor = 0.02;
  /// Smoothing window of the integral-image normals [px] (scaled with depth by PCL). A wider window
  /// (PCL's demo: 20) smooths across edges and under-segments; a narrower one leaves Kinect noise
  /// in the normals.
  double normal_smoothing_size = 10.0;
  /// Minimum region size [px]; the same as our detectors' default minimum plane size (theta).
  int min_inliers = 400;
  /// Maximum angle between neighbouring normals inside one region [deg]. A smaller angle fragments
  /// noisy Kinect walls into pieces, a larger one merges adjacent faces.
  double angular_threshold_deg = 5.0;
  /// Maximum difference of neighbouring plane offsets; PCL scales it by z^2 [m at z = 1 m].
  double distance_threshold = 0.02;
  /// Maximum "surface variation" lambda_min / (lambda_0+lambda_1+lambda_2) of a region [-].
  double maximum_curvature = 0.01;
};

/// The OMPS baseline as a PlaneDetector (name "pcl_omps"). Planes are refitted from their inlier
/// pixels with detection::PlaneMoments, so normal orientation (d >= 0) matches ours.
/// Segmentation::timings_ms holds "convert", "normals", "segment", "output"; benchmarks should time
/// only "normals" + "segment" (PCL's own work) to be conservative.
/// Throws IoError naming the plugin when it cannot be loaded, CheckError on invalid settings.
class OmpsDetector : public detection::PlaneDetector {
 public:
  explicit OmpsDetector(OmpsConfig config = {});
  ~OmpsDetector() override;
  std::string Name() const override { return "pcl_omps"; }
  detection::Segmentation Detect(const datasets::OrganizedCloud& cloud) const override;
  const OmpsConfig& config() const { return config_; }

 private:
  OmpsConfig config_;
  std::unique_ptr<detection::PlaneDetector> impl_;  ///< the plugin's detector
};

/// Settings of the PCL GICP odometry baseline.
struct GicpConfig {
  double voxel_size = 0.05;                 ///< VoxelGrid leaf size [m]
  double max_correspondence_distance = 0.2; ///< [m]
  int max_iterations = 50;                  ///< outer ICP iterations
  int correspondence_randomness = 20;       ///< k neighbours for the point covariances
  double transformation_epsilon = 1e-6;     ///< convergence on the transform change
  double max_range = 0.0;                   ///< drop points farther than this [m]; 0 = keep all
};

/// Result of one GICP step.
struct GicpStep {
  Pose T_prev_curr = Pose::Identity();  ///< maps current-frame points into the previous frame
  bool converged = false;
  double fitness = 0.0;        ///< PCL's mean squared correspondence distance [m^2]
  std::size_t source_points = 0;  ///< after voxel downsampling
  double time_ms = 0.0;        ///< downsampling + covariances + alignment (excludes conversion)
};

/// Frame-to-frame GICP odometry with a constant-velocity prior: the initial guess for frame k is the
/// motion estimated for frame k-1 (identity for the first pair), as in our PlaneOdometry. The
/// previous frame's downsampled cloud and point covariances are kept and reused as the target, so
/// every frame's covariances are computed once (the fair, fast way to run PCL's GICP).
/// The plugin implements it; GicpOdometry forwards to it.
class GicpBackend {
 public:
  virtual ~GicpBackend() = default;
  /// Feeds the next frame. The first call returns identity with converged = true.
  virtual GicpStep Track(const datasets::OrganizedCloud& cloud) = 0;
  /// Forgets the previous frame and the velocity.
  virtual void Reset() = 0;
};

/// Throws IoError naming the plugin when it cannot be loaded, CheckError on invalid settings.
class GicpOdometry {
 public:
  explicit GicpOdometry(GicpConfig config = {});
  ~GicpOdometry();
  GicpOdometry(const GicpOdometry&) = delete;
  GicpOdometry& operator=(const GicpOdometry&) = delete;

  /// Feeds the next frame. The first call returns identity with converged = true.
  GicpStep Track(const datasets::OrganizedCloud& cloud);
  /// Forgets the previous frame and the velocity.
  void Reset();

 private:
  std::unique_ptr<GicpBackend> impl_;
};

/// Version of the interface between the executable and the plugin; a plugin built against another
/// one is refused (a stale build).
constexpr int kPluginAbi = 1;

}  // namespace planeslam::app::pcl_baselines

/// The plugin's entry points, looked up by name with dlsym. The objects they return are owned by
/// the caller; errors are thrown as exceptions (both sides are built with the same compiler).
extern "C" {
int planeslam_pcl_plugin_abi();
planeslam::detection::PlaneDetector* planeslam_pcl_make_omps(
    const planeslam::app::pcl_baselines::OmpsConfig* config);
planeslam::app::pcl_baselines::GicpBackend* planeslam_pcl_make_gicp(
    const planeslam::app::pcl_baselines::GicpConfig* config);
}
