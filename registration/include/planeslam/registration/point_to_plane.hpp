#pragma once
/// Point-to-plane alignment of two organized clouds by projective association, restricted to
/// chosen directions of the motion: the fallback that fills what the planes left undetermined
/// (a corridor's axis) when the clouds hold other structure (door frames, boxes).
///
/// Projective association (as in KinectFusion): a current point is moved into the previous frame
/// with the current estimate, projected with the previous image's pinhole intrinsics and paired
/// with the point stored at that pixel; the normal there comes from the neighbouring pixels.
/// The residual is n . (R p_curr + t - p_prev). Only the coefficients y of the given directions
/// D (6 x k, tangent of geometry.hpp) are estimated: T = BoxPlus(T_init, D y), with a Gaussian
/// prior on y so that directions the clouds do not constrain either stay where they were.
#include <Eigen/Core>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/registration/plane_registration.hpp"

namespace planeslam::registration {

struct PointToPlaneConfig {
  int pixel_stride = 3;       ///< use every k-th row and column of the current cloud [px]
  int normal_pixel_step = 2;  ///< neighbours for the normal at (r, c +- s), (r +- s, c) [px]
  /// Neighbours farther from the centre than this fraction of its range: a depth edge, no
  /// normal. Relative, because grazing surfaces (a floor far ahead) spread the pixels apart [-].
  double max_neighbour_distance_ratio = 0.1;
  double max_correspondence_distance = 0.2;  ///< pairs farther apart are rejected [m]
  double huber_delta = 0.02;                 ///< Huber threshold on the point-to-plane residual [m]
  double point_sigma = 0.01;       ///< floor on the per-pair residual sigma for the information [m]
  int max_iterations = 20;         ///< [-]
  double convergence_step = 1e-6;  ///< stop when the update is below this [m, rad]
  int min_correspondences = 100;   ///< fewer pairs: no estimate [-]
  /// A direction also needs this many pairs whose normal faces it (|n . dir| > 0.5 for a
  /// translation, the same on the lever arm for a rotation): noisy normals on surfaces parallel
  /// to it would otherwise fake information without any signal [-].
  int min_support = 50;
  /// A direction counts as determined by the clouds when they pin it down better than this
  /// (1-sigma) [m] for translations, [rad] for rotations.
  double max_translation_sigma = 0.02;
  double max_rotation_sigma = 0.01;

  std::vector<std::string> Validate() const;
};

struct PointToPlaneResult {
  Pose T_prev_curr = Pose::Identity();
  /// Information of the coefficients y along the given directions from the point pairs alone
  /// (k x k); the prior is not included.
  Eigen::MatrixXd information;
  /// Posterior covariance of y (point pairs + prior), k x k.
  Eigen::MatrixXd covariance;
  int correspondences = 0;
  /// Per direction: pairs whose normal faces it (see PointToPlaneConfig::min_support).
  std::vector<int> support;
  double residual_rms = 0.0;  ///< of the accepted point-to-plane residuals [m]
  int iterations = 0;
  bool converged = false;
  bool valid = false;  ///< enough correspondences and a finite solution
};

/// Pinhole intrinsics that reproduce the cloud's pixel grid (u = fx x/z + cx, v = fy y/z + cy),
/// fitted by least squares to its valid points; nullopt when the cloud is not a pinhole grid
/// (fit residual above 0.5 px, too few points, or a spherical model).
std::optional<datasets::PinholeIntrinsics> EstimatePinholeIntrinsics(
    const datasets::OrganizedCloud& cloud);

/// Aligns `curr` to `prev` along `directions` (6 x k, unit columns) starting from T_init; the
/// prior on the coefficients is N(0, prior_covariance) (k x k). Never throws on data conditions.
PointToPlaneResult AlignPointToPlane(const datasets::OrganizedCloud& prev,
                                     const datasets::PinholeIntrinsics& prev_intrinsics,
                                     const datasets::OrganizedCloud& curr, const Pose& T_init,
                                     const Eigen::MatrixXd& directions,
                                     const Eigen::MatrixXd& prior_covariance,
                                     const PointToPlaneConfig& config = {});

/// Limits of FillDegenerateDirections: a direction counts as determined by the points when at
/// least min_support pairs face it and they pin it down better than the sigma (1-sigma) [m, rad].
struct FillLimits {
  int min_support = 50;
  double max_translation_sigma = 0.02;
  double max_rotation_sigma = 0.01;
};

/// Aligns along the given directions (6 x k) with the prior N(0, prior_covariance) on their
/// coefficients, from the registration's pose.
using DirectionAligner = std::function<PointToPlaneResult(const Eigen::MatrixXd& directions,
                                                          const Eigen::MatrixXd& prior_covariance)>;

/// The fill shared by every point alignment: runs `align` along result->degenerate_directions
/// (prior: the result's covariance there) and, when the points pin at least one of them down
/// (`limits`), takes the aligned pose, replaces the covariance along those directions and sets
/// used_icp; used_prior stays set when some direction is still undetermined by either. A
/// correction outside the prior's 99.9% region (chi-square on the directions used) is refused as
/// a wrong convergence and the prior kept (returns false). `degenerate` and
/// `degenerate_directions` keep describing the planes. Returns whether the points were used.
bool FillDegenerateDirections(const DirectionAligner& align, const FillLimits& limits,
                              RegistrationResult* result);

/// Runs AlignPointToPlane along result->degenerate_directions (prior: the result's covariance
/// there) and, when the clouds pin at least one of them down (see the config's sigmas), takes
/// the aligned pose, replaces the covariance along those directions and sets used_icp; used_prior
/// stays set when some direction is still undetermined by either. A correction outside the
/// prior's 99.9% region (chi-square on the directions used) is refused as a wrong convergence and
/// the prior kept (returns false). `degenerate` and
/// `degenerate_directions` keep describing the planes. Returns whether ICP was used.
bool FillDegenerateWithPointToPlane(const datasets::OrganizedCloud& prev,
                                    const datasets::PinholeIntrinsics& prev_intrinsics,
                                    const datasets::OrganizedCloud& curr,
                                    const PointToPlaneConfig& config, RegistrationResult* result);

}  // namespace planeslam::registration
