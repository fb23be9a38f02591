#pragma once
/// Frame-to-frame motion from matched planes: closed form, Gauss-Newton refinement, covariance
/// and honest degeneracy (Pathak et al. T-RO 2010; Zhang, Kaess, Singh ICRA 2016 for the
/// degenerate directions).
///
/// Convention: frame "prev" (a) and "curr" (b), T_prev_curr = (R, t) maps current points to the
/// previous frame, p_prev = R p_curr + t. A plane n.p = d seen in both satisfies
///   n_prev = R n_curr,   d_prev = d_curr + n_prev . t.
/// Covariances and information matrices are 6x6 over the tangent (dt, dtheta) of geometry.hpp:
/// translation additive, rotation a left perturbation, both in the previous frame.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "planeslam/datasets/trajectory.hpp"
#include "planeslam/detection/plane.hpp"
#include "planeslam/registration/geometry.hpp"

namespace planeslam::registration {

/// A correspondence: index into the previous frame's planes and into the current frame's.
struct PlaneMatch {
  int prev = -1;
  int curr = -1;
  /// True when the current plane is used with its normal and offset negated (same geometric
  /// plane; happens for planes through the sensor origin, whose orientation is arbitrary).
  bool flip_curr = false;
  bool operator==(const PlaneMatch& o) const {
    return prev == o.prev && curr == o.curr && flip_curr == o.flip_curr;
  }
};

/// What is known about the motion before the planes are looked at (e.g. constant velocity).
struct MotionPrior {
  Pose T_prev_curr = Pose::Identity();
  /// Covariance of the prior over (dt, dtheta) [m^2, rad^2]. The default is weak (1 m, 0.5 rad).
  Matrix6d covariance = (Vector6d() << 1.0, 1.0, 1.0, 0.25, 0.25, 0.25).finished().asDiagonal();
};

/// Parameters of the plane registration. Defaults suit depth cameras (TUM/ICL-NUIM scale).
struct RegistrationConfig {
  /// Added in quadrature to each plane's normal uncertainty: systematic errors (calibration,
  /// depth bias) that a fit's covariance does not model [rad].
  double min_normal_sigma = 0.002;
  /// Same for the plane offset [m].
  double min_offset_sigma = 0.005;
  /// Error of a plane's points along its normal that does not average out over them (depth bias
  /// that varies across the image, mixed pixels along the plane's edges) [m]. It tilts a plane
  /// by about sigma / width, so a narrow plane (a sliver at the image border) is uncertain by
  /// that rather than by its noise's sigma / (width sqrt(K)); each plane's covariance gains the
  /// fit covariance of K points with noise sigma sqrt(K) (planes that carry their moments, as the
  /// detectors' do; others have no known extent). 0 = off. See PlaneOdometryConfig for the
  /// odometry's value and why SLAM tracking keeps 0.
  double systematic_point_sigma = 0.0;
  /// Multiplies the planes' own covariances (>1 when the detector is overconfident) [-]. The
  /// default 4 doubles sigma: on real depth frames the detectors' fit covariances are tighter
  /// than the planes' frame-to-frame scatter, and the chi^2 verification would otherwise drop
  /// correct matches.
  double covariance_scale = 4.0;
  /// Per-point noise assumed when a plane carries no covariance (all zero) and its MSE is
  /// smaller [m].
  double fallback_point_sigma = 0.005;
  /// A translation direction the planes pin down worse than this (1-sigma) is degenerate [m].
  double max_translation_sigma = 0.05;
  /// A rotation axis the planes pin down worse than this (1-sigma) is degenerate [rad].
  double max_rotation_sigma = 0.03;
  /// Numerical floor: eigenvalues below this fraction of the largest are degenerate [-].
  double min_eigen_ratio = 1e-8;
  /// Gauss-Newton iterations over all matched planes after the closed form (0 = closed form only).
  int max_iterations = 10;
  /// Stop iterating when the update is below this (norm of the tangent step) [m, rad].
  double convergence_step = 1e-10;

  /// Problems with the values, empty when fine.
  std::vector<std::string> Validate() const;
};

/// Outcome of a registration. Never contains NaN; on failure the pose is the prior's.
struct RegistrationResult {
  Pose T_prev_curr = Pose::Identity();
  /// Covariance over (dt, dtheta): the planes' in the observable directions, the prior's (or the
  /// point-to-plane fallback's) in the degenerate ones. Always finite and positive definite when
  /// the prior covariance is.
  Matrix6d covariance = Matrix6d::Identity();
  /// Information from the planes alone (J^T Sigma^-1 J), singular along degenerate directions.
  Matrix6d information = Matrix6d::Zero();
  bool converged = false;   ///< the estimate was computed from planes and the iteration settled
  bool degenerate = false;  ///< some direction could not be determined from the planes
  /// Unit 6-vectors (dt, dtheta) of the directions the planes left undetermined; each is either a
  /// pure translation (corridor axis) or a pure rotation axis.
  std::vector<Vector6d> degenerate_directions;
  bool used_prior = false;  ///< some degenerate direction was filled from the prior
  bool used_icp = false;    ///< some degenerate direction was filled by points or extents
  int point_directions = 0;  ///< degenerate directions the point alignment determined
  int extent_directions = 0;  ///< degenerate directions complete planes' extents determined
  int prior_directions = 0;  ///< degenerate directions left to the prior
  int prior_translations = 0;  ///< of those, translation directions
  std::vector<PlaneMatch> inliers;  ///< the matches used
  int iterations = 0;
  double residual_rms = 0.0;         ///< RMS of the offset residuals d_prev - predicted [m]
  double normal_residual_rms = 0.0;  ///< RMS angle between n_prev and R n_curr [rad]
  double chi2 = 0.0;                 ///< sum of whitened squared residuals (3 per match)
};

/// The 4x4 covariance of (n, d) registration uses for a plane: its own when set, else one
/// derived from its moments/eigenvalues with per-point noise max(mse, fallback_point_sigma^2):
/// Var(n along in-plane axis e_k) = sigma^2 / lambda_k, Var(d) = sigma^2 / K + c^T Cov(n) c.
Eigen::Matrix4d PlaneCovarianceOrFallback(const detection::Plane& plane,
                                          double fallback_point_sigma);

/// Motion from matched planes. `matches` index `prev` and `curr`; invalid indices are a
/// CheckError (a bug), but any number of matches (0, 1, parallel, identical) is a data condition
/// reported through the flags.
RegistrationResult RegisterPlanes(const std::vector<detection::Plane>& prev,
                                  const std::vector<detection::Plane>& curr,
                                  const std::vector<PlaneMatch>& matches, const MotionPrior& prior,
                                  const RegistrationConfig& config = {});

/// Innovation of a registration against its prior: chi^2 (6 dof) of BoxMinus(result, prior) with
/// covariance prior + result; infinity when not finite. Used to prefer (association) or refuse
/// (SLAM tracking) a motion that disagrees with the constant-velocity prediction.
double PriorInnovationChi2(const RegistrationResult& result, const MotionPrior& prior);

}  // namespace planeslam::registration
