#pragma once
/// Frame-to-frame odometry on planes: association, closed-form motion with covariance, the
/// alignment of the scan's other structure to a local map of recent scans along the directions
/// the planes leave open and then in all six (local_map.hpp), a constant-velocity prior (the
/// scans' coarse-to-fine alignment while there is no velocity), and the accumulated pose.
/// Used by `planeslam bench odometry` and the library's odometry example.
#include <Eigen/Core>
#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/trajectory.hpp"
#include "planeslam/detection/plane.hpp"
#include "planeslam/detection/plane_detector.hpp"
#include "planeslam/registration/depth_local_map.hpp"
#include "planeslam/registration/local_map.hpp"
#include "planeslam/registration/plane_association.hpp"
#include "planeslam/registration/plane_registration.hpp"
#include "planeslam/registration/point_to_plane.hpp"
#include "planeslam/registration/velocity_model.hpp"

namespace planeslam::registration {

struct PlaneOdometryConfig {
  AssociationConfig association;
  RegistrationConfig registration;
  PointToPlaneConfig point_to_plane;
  LocalMapConfig local_map;
  DepthMapConfig depth_map;
  /// Fill the planes' degenerate directions from the points: projective point-to-plane against
  /// the previous image for pinhole clouds (point_to_plane), and the structure outside the planes
  /// aligned to a local map of recent scans (local_map) for any organized cloud.
  bool use_point_to_plane = true;
  /// Constant-velocity prior: 1-sigma of the change of motion between consecutive frames
  /// (acceleration over one frame interval) [m].
  double prior_translation_sigma = 0.05;
  double prior_rotation_sigma = 0.05;  ///< same for rotation [rad]
  /// The registration's systematic_point_sigma for frame-to-frame odometry; it replaces the one
  /// in `registration` [m]. A millimetre keeps the odometry from registering on a sliver of a
  /// plane at the image border, whose tilt its pixel noise alone makes look well determined. SLAM
  /// tracking keeps 0: there it leaves more loop registrations degenerate, as the loop-closure
  /// thresholds are set for planes without that error.
  double systematic_point_sigma = 0.001;
  /// Velocity is not extrapolated over a gap longer than this; the prior is then "no motion"
  /// with MotionPrior's weak default covariance [s].
  double max_prior_gap = 1.0;
  /// The predicted velocity is the mean rate of the motions of the last this many seconds
  /// (VelocityModel); 0 = the last motion alone [s].
  double velocity_window = 0.5;
  /// Track() detects and registers planes on every n-th row and column of the cloud
  /// (datasets::Decimate); 1 = full resolution. Kinect-class depth is correlated over several
  /// pixels (the disparity comes from correlation windows), so half resolution keeps most of
  /// its plane information at a quarter of the detection time; config/tum_fr3.yaml uses 2. The
  /// synthetic sensors' noise is independent per pixel, and there full resolution pays.
  int decimation = 1;

  /// Problems in this struct and the nested ones, empty when fine.
  std::vector<std::string> Validate() const;
};

/// What one Process() call did.
struct OdometryStep {
  std::size_t frame = 0;  ///< 0 for the first frame
  double timestamp = 0.0;
  bool first_frame = false;  ///< no previous frame: identity motion, nothing estimated
  Pose T_prev_curr = Pose::Identity();
  Matrix6d covariance = Matrix6d::Zero();  ///< of T_prev_curr over (dt, dtheta), geometry.hpp
  Pose T_world_sensor = Pose::Identity();  ///< accumulated
  /// Flags (converged, degenerate + directions, used_prior, used_icp), inliers, residuals.
  RegistrationResult registration;
  MotionPrior prior;  ///< the constant-velocity prediction used
  /// No velocity to predict from (first pair, long gap): the prior is the coarse-to-fine
  /// alignment of the two clouds (AlignScansCoarseToFine).
  bool bootstrapped = false;
  int planes_prev = 0;
  int planes_curr = 0;
  int candidates = 0;  ///< association candidates after gating
  double association_ms = 0.0;
  double point_to_plane_ms = 0.0;  ///< alignment to the local map and its update
};

/// Feed frames in time order; keeps the previous frame's planes and cloud.
class PlaneOdometry {
 public:
  explicit PlaneOdometry(PlaneOdometryConfig config = {},
                         const Pose& T_world_first = Pose::Identity());

  /// Intrinsics of the (pinhole) clouds the point-to-plane fallback aligns: those given to
  /// Process, or Track's after its decimation (datasets::DecimateIntrinsics). Without them they
  /// are estimated from the first such cloud's grid (EstimatePinholeIntrinsics).
  void SetIntrinsics(const datasets::PinholeIntrinsics& intrinsics) { intrinsics_ = intrinsics; }

  /// Detects the planes of a frame with `detector` on every config.decimation-th row and column
  /// of `cloud` and registers them against the previous frame (the whole odometry of a frame).
  OdometryStep Track(double timestamp, const datasets::OrganizedCloud& cloud,
                     const detection::PlaneDetector& detector);
  /// Registers a frame against the previous one. `segmentation.planes` are in `cloud`'s frame
  /// and were detected on it (no decimation here).
  OdometryStep Process(double timestamp, const datasets::OrganizedCloud& cloud,
                       const detection::Segmentation& segmentation);
  /// Same with only the planes (no point alignment).
  OdometryStep Process(double timestamp, const std::vector<detection::Plane>& planes);

  const Pose& T_world_sensor() const { return T_world_sensor_; }
  const datasets::Trajectory& trajectory() const { return trajectory_; }
  const PlaneOdometryConfig& config() const { return config_; }
  /// Forgets every frame; the next one starts at T_world_first.
  void Reset(const Pose& T_world_first = Pose::Identity());

 private:
  /// Registers the planes, fills what they leave open from the local map and adds the frame's
  /// structure points (pixels not labelled as a plane in `labels`) to it.
  OdometryStep Step(double timestamp, const std::vector<detection::Plane>& planes,
                    const datasets::OrganizedCloud* cloud, const std::vector<std::int32_t>* labels);
  MotionPrior Predict(double timestamp) const;
  /// Whether a velocity predicts the frame at `timestamp` (else Predict gives "no motion").
  bool HasVelocity(double timestamp) const;
  /// Fills the directions the planes left open in `reg`: for pinhole clouds the alignment of
  /// the pixels outside the planes to the depth map of recent frames, or where it does not pin
  /// them down, projective point-to-plane against the previous cloud (same grid); for other
  /// clouds the alignment of the frame's structure points to the local map.
  void FillOpenDirections(const datasets::OrganizedCloud& cloud,
                          const std::vector<std::int32_t>* labels,
                          const std::vector<ShapedPoint>& structure, RegistrationResult* reg);

  PlaneOdometryConfig config_;
  Pose T_world_first_;
  Pose T_world_sensor_;
  datasets::Trajectory trajectory_;
  std::optional<datasets::PinholeIntrinsics> intrinsics_;
  bool intrinsics_estimated_ = false;
  bool have_prev_ = false;
  double prev_stamp_ = 0.0;
  std::vector<detection::Plane> prev_planes_;
  datasets::OrganizedCloud prev_cloud_;
  std::unique_ptr<LocalVoxelMap> map_;  ///< created with the first cloud (its voxel size)
  std::unique_ptr<DepthLocalMap> depth_map_;  ///< pinhole clouds: created with the first one
  VelocityModel velocity_;
  double last_dt_ = 0.0;  ///< interval of the last motion, the prior's unit of time
  std::size_t frames_ = 0;
};

}  // namespace planeslam::registration
