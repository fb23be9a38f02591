#pragma once
/// A local map of a depth camera's recent frames, for the directions of the motion the planes
/// leave open (a corridor's axis, the run along a single wall): the frame's pixels outside the
/// detected planes are aligned to the map, not to the previous frame, so a pipe or a lamp that
/// stays in view for many frames holds the open direction without the frame-to-frame noise
/// accumulating.
///
/// The map is a depth image fused in a reference view (a recent frame's pose, the camera's
/// intrinsics), as KinectFusion's model seen from one pose: every frame's points outside the
/// planes are projected into it and averaged per pixel along the reference's ray, weighted by
/// the depth noise model sigma(z) = sigma0 + sigma_z2 z^2 (Khoshelham & Elberink 2012 for a
/// Kinect). A depth camera's noise along the ray (9 cm at 8 m) exceeds any voxel that resolves a
/// pipe, so a voxel map splits one surface's samples over several voxels; a per-pixel average
/// along the ray does not. When the camera has moved or turned too far from the reference, the
/// model is re-projected, weights and all, into the current view, which becomes the reference:
/// the averaging carries over and nothing is re-estimated from one frame.
///
/// A query q (noise sigma_q along its ray r_q) projected into the reference pairs with the fused
/// point m at that pixel (information W along the reference ray r_m); n is the fused image's
/// normal there. The residual n . (q - m) has the variance
///   sigma_q^2 (n . r_q)^2 + (n . r_m)^2 / W + sigma_floor^2.
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/registration/plane_registration.hpp"
#include "planeslam/registration/point_to_plane.hpp"

namespace planeslam::registration {

struct DepthMapConfig {
  double sigma0 = 0.0;         ///< constant depth noise along the ray [m]
  double sigma_z2 = 1.425e-3;  ///< quadratic depth noise [1/m]: sigma = sigma0 + sigma_z2 z^2
  /// Residual sigma that no averaging removes (the pixel grid, calibration) [m].
  double sigma_floor = 0.001;
  int insert_stride = 1;      ///< every k-th row and column enters the model [px]
  int query_stride = 1;       ///< every k-th row and column is aligned [px]
  int normal_pixel_step = 2;  ///< neighbours for the fused normal at (r, c +- s), (r +- s, c) [px]
  /// Neighbours farther from the centre than this fraction of its range: a depth edge [-].
  double max_neighbour_distance_ratio = 0.1;
  double max_correspondence_distance = 0.2;  ///< pairs farther apart are rejected [m]
  /// Fusion: a sample within this many sigmas of the fused depth is averaged in; a nearer one
  /// takes its weight off the fused depth and replaces it once that is used up (an occluder),
  /// a farther one is hidden [-].
  double fusion_sigmas = 3.0;
  /// The current view becomes the reference when it is this far from it [m] or turned this much
  /// [deg].
  double reanchor_distance = 1.0;
  double reanchor_angle_deg = 10.0;
  double huber_sigmas = 2.0;           ///< Huber threshold on the whitened residual [-]
  double max_whitened_residual = 6.0;  ///< pairs farther off (in sigmas) are dropped [-]
  int max_iterations = 15;             ///< Gauss-Newton iterations [-]
  double convergence_step = 1e-6;      ///< stop when the update is below this [m, rad]
  /// Fewer pairs: no estimate. Low, because a far lamp alone (a few hundred pixels) must hold
  /// the axis between two pipes; each pair's variance comes from the noise model [-].
  int min_correspondences = 30;
  /// A direction needs this many pairs whose normal faces it (as PointToPlaneConfig::min_support).
  int min_support = 30;
  /// A direction counts as determined when the pairs pin it down better than this (1-sigma) [m]
  /// for translations, [rad] for rotations.
  double max_translation_sigma = 0.02;
  double max_rotation_sigma = 0.01;

  std::vector<std::string> Validate() const;
};

class DepthLocalMap {
 public:
  DepthLocalMap(const datasets::PinholeIntrinsics& intrinsics, const DepthMapConfig& config);

  /// Fuses the frame's pixels outside the planes (labels >= 1 are planes; all valid pixels when
  /// `labels` is null or of another size) seen at T_world_sensor, re-anchoring the model in this
  /// view first when it has moved too far from the reference (see DepthMapConfig).
  void Insert(const datasets::OrganizedCloud& cloud, const std::vector<std::int32_t>* labels,
              const Pose& T_world_sensor);
  /// Moves the model with its reference pose (after an optimisation moved the poses it was
  /// built at).
  void SetReferencePose(const Pose& T_world_ref) { T_world_ref_ = T_world_ref; }

  const Pose& T_world_ref() const { return T_world_ref_; }
  const datasets::PinholeIntrinsics& intrinsics() const { return K_; }
  const DepthMapConfig& config() const { return config_; }
  bool empty() const { return filled_ == 0; }
  std::size_t filled() const { return filled_; }  ///< pixels holding a fused point
  void Clear();
  /// Depth noise of a point at optical depth z [m].
  double Sigma(double z) const { return config_.sigma0 + config_.sigma_z2 * z * z; }
  /// The fused point at a pixel (reference frame) and its information along the ray, or false.
  bool FusedPoint(int row, int col, Eigen::Vector3d* p, double* weight) const;
  /// The fused image's normal at a pixel (reference frame), or false.
  bool Normal(int row, int col, Eigen::Vector3d* n) const;

 private:
  /// Adds a point of the reference frame with information w along the ray.
  void Splat(const Eigen::Vector3d& p_ref, double w);
  void Reanchor(const Pose& T_world_new);

  datasets::PinholeIntrinsics K_;
  DepthMapConfig config_;
  Pose T_world_ref_ = Pose::Identity();
  std::vector<float> depth_;   ///< fused depth along the reference's optical axis, 0 = none [m]
  std::vector<float> weight_;  ///< its information [1/m^2]
  std::size_t filled_ = 0;
};

/// Aligns the pixels of `curr` outside the planes to `map` along `directions` (6 x k, unit
/// columns in the tangent of geometry.hpp at the previous frame, which is at T_world_prev in the
/// map) starting from T_init = T_prev_curr, with the prior N(0, prior_covariance) on the
/// coefficients. Gauss-Newton with a Huber kernel. Never throws on data conditions.
PointToPlaneResult AlignToDepthMap(const DepthLocalMap& map, const Pose& T_world_prev,
                                   const datasets::OrganizedCloud& curr,
                                   const std::vector<std::int32_t>* labels, const Pose& T_init,
                                   const Eigen::MatrixXd& directions,
                                   const Eigen::MatrixXd& prior_covariance);

/// FillDegenerateDirections (point_to_plane.hpp) with AlignToDepthMap: the directions the planes
/// left open in `result` (T_prev_curr, the previous frame at T_world_prev) taken from the map
/// where it pins them down.
bool FillDegenerateFromDepthMap(const DepthLocalMap& map, const Pose& T_world_prev,
                                const datasets::OrganizedCloud& curr,
                                const std::vector<std::int32_t>* labels,
                                RegistrationResult* result);

}  // namespace planeslam::registration
