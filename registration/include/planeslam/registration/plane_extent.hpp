#pragma once
/// Bounded planes: a plane whose whole outline is in view (a whiteboard on a wall, a box's top,
/// a picture frame) constrains the motion along the directions the planes leave open. Two
/// parallel planes leave both in-plane translations and the rotation about their normal open;
/// the same whole region seen from two poses pins them: its centroid is a point correspondence,
/// the principal axes of its second moments turn with the rotation about the normal.
///
/// A plane's region is complete when none of its pixels lies on the image border or next to a
/// pixel nearer to the sensor than the plane (an occluder), and every invalid pixel next to it
/// is a dropout of a depth discontinuity: within max_dropout_gap pixels beyond it lies a surface
/// that is not in front of the plane (depth cameras drop both pixels of a jump).
///
/// Each pixel of the region is moved onto the fitted plane along its ray (the depth noise then
/// does not enter) and weighted by its footprint there, the area its solid angle covers on the
/// plane: a = Omega rho^2 / |n . r|, rho the range along the unit ray r, so an oblique view
/// does not pull the centroid towards the near side. Omega comes from the rays of neighbouring
/// pixels, which makes it valid for pinhole and spherical grids alike.
///
/// Noise of the outline (derived once here, used by ComputePlaneExtents): each boundary edge of
/// a pixel moves along the outline's normal by delta ~ N(0, s^2), s = sqrt(a) the footprint's
/// side (one pixel of label jitter), over a length s. An area-weighted moment
/// m = (1/A) sum f(x) a has the first-order change dm = (1/A) sum_b (f(x_b) - m) delta_b s_b, so
///   Var(m) = kappa sum_b (f(x_b) - m)^2 a_b^2 / A^2,
/// with f = x for the centroid (per axis), f = 1 (times A) for the area, f = (e_k . (x - c))^2
/// for the principal moments, and f = (e_1 . (x - c)) (e_2 . (x - c)) for the off-diagonal
/// moment, whose change over (lambda_1 - lambda_2) turns the principal axes. A detector's label
/// boundary moves along whole runs of pixels at once (a shaved side), not pixel by pixel:
/// kappa = boundary_correlation counts the pixels that move together. For a square of side L
/// seen with footprint s this gives sigma(centroid) ~ 0.8 s sqrt(kappa s / L).
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/detection/plane.hpp"
#include "planeslam/registration/plane_registration.hpp"

namespace planeslam::registration {

struct PlaneExtentConfig {
  double sigma0 = 0.0;         ///< constant depth noise along the ray [m]
  double sigma_z2 = 1.425e-3;  ///< quadratic depth noise [1/m]: sigma = sigma0 + sigma_z2 z^2
  /// A neighbour this many sigma(z) in front of the plane's extension along its ray is an
  /// occluder [-]. Five: a boundary of a thousand pixels then has no false occluder from noise.
  double occluder_sigmas = 5.0;
  /// Invalid pixels between the region and a surface behind it that are taken for the dropout
  /// of a depth discontinuity [px]; more, and the region counts as cut.
  int max_dropout_gap = 24;
  /// Boundary pixels whose displacement moves together (see the noise model above) [px].
  double boundary_correlation = 2.0;
  /// A pair's area and principal moments agree within this chi^2 (3 dof; 16.27 = 99.9%) [-].
  double extent_chi2 = 16.27;
  /// A direction counts as determined when the extents pin it down better than this (1-sigma)
  /// [m] for translations, [rad] for rotations.
  double max_translation_sigma = 0.02;
  double max_rotation_sigma = 0.01;
  int max_iterations = 10;  ///< Gauss-Newton iterations [-]

  std::vector<std::string> Validate() const;
};

/// The outline statistics of one detected plane (sensor frame). All but `complete` are set only
/// for complete planes.
struct PlaneExtent {
  bool complete = false;
  int pixels = 0;           ///< pixels of its region
  int boundary_pixels = 0;  ///< of those, next to a pixel of another label or invalid
  double area = 0.0;        ///< sum of the footprints [m^2]
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  ///< area-weighted, on the plane [m]
  /// Principal in-plane axes (unit, orthogonal to the plane's normal) and the area-weighted
  /// second central moments along them, major >= minor [m^2].
  Eigen::Vector3d axis_major = Eigen::Vector3d::UnitX();
  Eigen::Vector3d axis_minor = Eigen::Vector3d::UnitY();
  double moment_major = 0.0;
  double moment_minor = 0.0;
  /// Outline noise (see above): the centroid's covariance (in-plane, rank 2) [m^2], the area's,
  /// the principal moments' variances [m^4], and that of the principal axes' angle about the
  /// normal [rad^2] (infinite for an isotropic outline).
  Eigen::Matrix3d centroid_covariance = Eigen::Matrix3d::Zero();
  double area_variance = 0.0;
  double moment_major_variance = 0.0;
  double moment_minor_variance = 0.0;
  double axis_angle_variance = 0.0;
};

/// One entry per plane of `planes` (labels: plane id = index + 1, else none), computed from the
/// label image and the cloud in one pass for completeness and one over the complete regions.
/// Labels of another size than the cloud give no complete plane.
std::vector<PlaneExtent> ComputePlaneExtents(const datasets::OrganizedCloud& cloud,
                                             const std::vector<std::int32_t>& labels,
                                             const std::vector<detection::Plane>& planes,
                                             const PlaneExtentConfig& config = {});

/// Chi-square (3 dof) of the differences of area and principal moments of two complete
/// extents under their summed variances: the same whole region seen twice stays within
/// extent_chi2. Infinity when either is incomplete.
double ExtentMismatchChi2(const PlaneExtent& a, const PlaneExtent& b);

/// The directions the planes left open in `result` (T_prev_curr, converged and degenerate)
/// taken from the matched pairs of complete planes whose extents agree: each pair's centroids
/// in the plane (2 residuals) and, for an anisotropic outline, its principal axes' angle about
/// the normal (1 residual), with the outline covariances; Gauss-Newton along the open
/// directions with the planes' solution as the prior. Directions the extents pin down below the
/// config's sigmas take the result (covariance: the posterior there), the others stay the
/// prior's. Refused (returns false, result untouched) without such a pair, when a point fill
/// already used the open directions (used_icp), when a pair's residual after the fit or the
/// correction against the prior lies outside its 99.9% region. On success sets
/// extent_directions, used_icp (a measurement filled directions), and prior_directions,
/// prior_translations, used_prior for what is still open.
bool FillDegenerateFromExtents(const std::vector<detection::Plane>& prev_planes,
                               const std::vector<PlaneExtent>& prev_extents,
                               const std::vector<detection::Plane>& curr_planes,
                               const std::vector<PlaneExtent>& curr_extents,
                               const PlaneExtentConfig& config, RegistrationResult* result);

}  // namespace planeslam::registration
