#pragma once
/// A local map of recent scans' structure points and the alignment of a scan against it: it
/// fills the directions of the motion the planes leave open (a corridor's or a street's axis) and
/// then refines all six with the planes' estimate as the prior (scan to map, so the frame-to-frame
/// noise of the planes' normals does not accumulate as drift).
///
/// The map is a voxel hash in the style of KISS-ICP (Vizzo et al., RA-L 2023): a few points per
/// voxel, nearest neighbours among the 27 voxels around a query, voxels farther from the sensor
/// than the scans reach dropped. Each map point carries the shape of its neighbourhood in the
/// scan it came from (principal axes of the points within one voxel edge): a surface constrains
/// a query along its normal, an edge or a pole across its axis, scattered clutter in all three
/// directions. The residual of a query q paired with map point m is (q - m)^T M (q - m), M the
/// projector onto the constrained axes, so the same code serves facades, poles and trees.
///
/// Only the points outside the detected planes enter the map and the alignment: the planes
/// already carry their own information, and their points would add only the noise of their
/// normals along the open directions. Works on any organized cloud (range image or depth image).
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/registration/plane_registration.hpp"
#include "planeslam/registration/voxel_index.hpp"

namespace planeslam::registration {

struct LocalMapConfig {
  /// Voxel edge of the map [m]; 0 = a hundredth of the first scan's reach (99th percentile of
  /// its ranges), KISS-ICP's rule, which suits a depth camera and a LiDAR alike. Scans enter the
  /// map thinned to half a voxel and are aligned thinned to 1.5 voxels.
  double voxel_size = 0.0;
  int max_points_per_voxel = 20;  ///< [-]
  int max_iterations = 15;        ///< Gauss-Newton iterations per alignment [-]
  /// A direction counts as determined by the points when they pin it down better than this
  /// (1-sigma) [m] for translations, [rad] for rotations.
  double max_translation_sigma = 0.02;
  double max_rotation_sigma = 0.01;
  /// A direction also needs this many pairs that constrain it (their residual moves by at least
  /// half of a unit step along it) [-].
  int min_support = 30;

  std::vector<std::string> Validate() const;
};

/// A point of an organized cloud (sensor frame) and its pixel.
struct ScanPoint {
  Eigen::Vector3d position;
  int row = 0;
  int col = 0;
};

/// The structure points of an organized cloud: valid pixels whose label is not a plane (all
/// valid pixels when `labels` is null or of another size).
std::vector<ScanPoint> StructurePoints(const datasets::OrganizedCloud& cloud,
                                       const std::vector<std::int32_t>* labels);

/// One point per occupied voxel of edge `voxel` (the first one met), in input order.
std::vector<ScanPoint> VoxelDownsample(const std::vector<ScanPoint>& points, double voxel);

/// The 99th percentile of the valid points' distances from the sensor (0 without any) [m].
double ScanReach(const datasets::OrganizedCloud& cloud);

/// A point with the shape of its neighbourhood: the projector onto the axes along which the
/// neighbourhood is thin (a surface's normal; for an edge or a pole, the plane across it).
struct ShapedPoint {
  Eigen::Vector3d position;
  Eigen::Matrix3d shape;
};

/// The points of `points` whose neighbours within `radius` (among the same points) form a
/// surface or an edge, with that shape; blobs and isolated points are left out.
std::vector<ShapedPoint> ShapePoints(const std::vector<ScanPoint>& points, double radius);

/// What a scan gives the map and the alignment: its structure points (StructurePoints) thinned to
/// half a voxel and shaped within one voxel (ShapePoints).
std::vector<ShapedPoint> ScanStructure(const datasets::OrganizedCloud& cloud,
                                       const std::vector<std::int32_t>* labels, double voxel);

/// One shaped point per occupied voxel of edge `voxel` (the first one met), in input order.
std::vector<ShapedPoint> ThinShapedPoints(const std::vector<ShapedPoint>& points, double voxel);

/// A shaped point stored for later (a SLAM keyframe's structure for loop closures): floats and
/// the shape's axis, 28 bytes where a ShapedPoint takes 96. The shapes ShapePoints makes are
/// projectors of rank 1 (a surface: n n^T, axis n) or rank 2 (an edge or a pole: I - a a^T,
/// axis a along it).
struct CompactShapedPoint {
  Eigen::Vector3f position = Eigen::Vector3f::Zero();
  Eigen::Vector3f axis = Eigen::Vector3f::UnitZ();
  bool edge = false;  ///< rank 2: the shape constrains the plane across `axis`
};

/// `points` stored compactly (a shape of trace above 1.5 counts as rank 2).
std::vector<CompactShapedPoint> CompactShapedPoints(const std::vector<ShapedPoint>& points);
/// The shaped points back from their compact form (to float precision).
std::vector<ShapedPoint> ExpandShapedPoints(const std::vector<CompactShapedPoint>& points);

class LocalVoxelMap {
 public:
  struct MapPoint {
    Eigen::Vector3d position;        ///< world frame
    Eigen::Matrix3d shape;           ///< projector onto the constrained axes (world frame)
  };

  LocalVoxelMap(double voxel_size, int max_points_per_voxel);

  /// Adds a scan's points (sensor frame, already thinned) at T_world_sensor and drops the voxels
  /// farther than `reach` from the sensor (no pruning when reach <= 0).
  void Insert(const std::vector<ShapedPoint>& points_sensor, const Pose& T_world_sensor,
              double reach);
  /// The same from compactly stored points.
  void Insert(const std::vector<CompactShapedPoint>& points_sensor, const Pose& T_world_sensor,
              double reach) {
    Insert(ExpandShapedPoints(points_sensor), T_world_sensor, reach);
  }
  /// The nearest map point to q (world) among the 27 voxels around it whose shape agrees with
  /// `shape` (world; same kind, axes within about 20 deg), or null.
  const MapPoint* Nearest(const Eigen::Vector3d& q, const Eigen::Matrix3d& shape) const;
  /// Nearest() limited to map points within sqrt(max_distance2) of q (null when none is).
  const MapPoint* NearestWithin(const Eigen::Vector3d& q, const Eigen::Matrix3d& shape,
                                double max_distance2) const;
  double voxel_size() const { return voxel_; }
  bool empty() const { return cells_.empty(); }
  std::size_t size() const;
  void Clear();

 private:
  Eigen::Vector3i Key(const Eigen::Vector3d& p) const;

  double voxel_;
  double inverse_voxel_;  ///< 1 / voxel_, for Key
  int max_points_;
  VoxelIndex index_;                         ///< voxel -> index into keys_ and cells_
  VoxelBitmap<20> occupied_;                 ///< the voxels of index_ (128 KiB)
  std::vector<Eigen::Vector3i> keys_;        ///< per voxel, in order of creation
  std::vector<std::vector<MapPoint>> cells_;  ///< per voxel, its points
};

struct MapAlignmentResult {
  Pose T_prev_curr = Pose::Identity();
  Eigen::MatrixXd information;  ///< of the coefficients along the directions, pairs alone (k x k)
  Eigen::MatrixXd covariance;   ///< posterior of the coefficients (pairs + prior), k x k
  int correspondences = 0;
  std::vector<int> support;  ///< per direction: pairs that constrain it (see min_support)
  double residual_rms = 0.0;  ///< of the whitened residuals sqrt((q-m)^T M (q-m)) [m]
  int iterations = 0;
  bool converged = false;
  bool valid = false;  ///< enough pairs and a finite solution
};

/// Aligns `source` (current sensor frame) to `map` along `directions` (6 x k, unit columns in
/// the tangent of geometry.hpp at the previous frame) starting from T_init = T_prev_curr; the
/// previous frame is at T_world_prev in the map. The coefficients have the prior N(0,
/// prior_covariance). Gauss-Newton with a Huber kernel, at most config.max_iterations steps.
MapAlignmentResult AlignToLocalMap(const LocalVoxelMap& map, const Pose& T_world_prev,
                                   const std::vector<ShapedPoint>& source, const Pose& T_init,
                                   const Eigen::MatrixXd& directions,
                                   const Eigen::MatrixXd& prior_covariance,
                                   const LocalMapConfig& config);

/// Aligns `curr` to `prev` (two clouds of one sensor, T_init = T_prev_curr to start from) in all
/// six directions, coarse to fine: all valid points of both, shaped (ScanStructure) at 4, 2 and 1
/// times `voxel`, each level starting from the one before. The wide first level reaches a motion
/// that a prior without a velocity misses by metres (a car's first scans), which a plane
/// association gated around that prior would alias to a repeated facade. `prior_covariance` is
/// over (dt, dtheta); invalid when a level finds too few pairs.
MapAlignmentResult AlignScansCoarseToFine(const datasets::OrganizedCloud& prev,
                                          const datasets::OrganizedCloud& curr,
                                          const Pose& T_init, const Matrix6d& prior_covariance,
                                          double voxel, const LocalMapConfig& config);

/// Aligns along result->degenerate_directions (prior: the result's covariance there, around the
/// planes' pose) and, for the directions the points pin down, takes the aligned pose and the
/// alignment's covariance there; sets used_icp and point_directions, and used_prior and
/// prior_directions for what is still open. The other directions keep the planes' estimate.
/// A correction outside the prior's 99.9% region is refused (the directions stay the prior's).
/// Returns whether the points were used.
bool FillDegenerateFromLocalMap(const LocalVoxelMap& map, const Pose& T_world_prev,
                                const std::vector<ShapedPoint>& source,
                                const LocalMapConfig& config, RegistrationResult* result);

/// The registration's pose refined in all six directions by the scan's points against the map,
/// the registration (planes and whatever filled their open directions) as the prior with its
/// covariance: the planes keep the directions they determine well, the points add what the
/// planes measure coarsely. Refused like FillDegenerateFromLocalMap. Returns whether it moved.
bool RefineWithLocalMap(const LocalVoxelMap& map, const Pose& T_world_prev,
                        const std::vector<ShapedPoint>& source, const LocalMapConfig& config,
                        RegistrationResult* result);

/// What constrained a registration: "planes", "extent", "points", "prior" joined by '+' in that
/// order (e.g. "planes+points"); from its flags and direction counts.
std::string ConstraintSource(const RegistrationResult& result);

}  // namespace planeslam::registration
