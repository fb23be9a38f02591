#pragma once
/// The global plane map: world planes, each the merge of all its observations.
///
/// An observation is one detected plane of one keyframe. It keeps the plane's point statistics in
/// the SENSOR frame (count, centroid, scatter) and a bounded set of sample points of its visible
/// region (one mean point per cell of a grid on the plane, sensor frame), so that when keyframe
/// poses change after pose-graph optimisation the world plane is re-fitted exactly from the
/// transformed statistics (Refit) instead of being frozen at the poses it was first seen with.
///
/// Association of an observation (world normal n_o, centroid c_o, world sample points) with a map
/// plane (n, d, extent) requires, all three:
///   - angle(n_o, n) < max_normal_angle_deg (oriented: both normals point away from the sensors
///     that saw them, so a wall's two faces stay apart);
///   - |n . c_o - d| < max_offset + max_offset_range_coeff r^2 (the observation's mass centre lies
///     near the map plane; r its range from the sensor, for the depth noise);
///   - at least min_touch_points of the observation's samples lie within max_gap of the map plane's
///     occupied cells (spatial overlap or adjacency; two coplanar tables far apart stay apart).
/// An observation that matches several map planes proves them to be one surface: they are merged.
/// MergeCoincidentPlanes() merges touching map planes within the (stricter) merge thresholds (after
/// Refit, loop closures bring duplicates of one surface together), and planes whose extents are
/// apart when they coincide within a given offset: tightly during SLAM, at merge_max_offset for the
/// finished map (merge_across_gaps): each plane once, with an outline of several parts.
///
/// Map plane orientation: the normal points away from the observers (detection's convention carried
/// to the world: the sensors lie on the negative side, n . c_sensor < d). Hence the world offset d
/// can be negative (unlike detection::Plane, whose d >= 0 holds in the sensor frame only).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <absl/container/flat_hash_set.h>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/trajectory.hpp"
#include "planeslam/detection/plane.hpp"
#include "planeslam/detection/plane_moments.hpp"
#include "planeslam/mapping/polygon.hpp"

namespace planeslam::mapping {

/// Point statistics as (count, mass centre, scatter): unlike raw sums they transform exactly and
/// cheaply under a rigid motion, c' = R c + t, C' = R C R^T (equivalent to S' = R S + K t,
/// Q' = R Q R^T + R S t^T + t S^T R^T + K t t^T on the raw moments).
struct PointStats {
  std::int64_t count = 0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  ///< [m]
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();   ///< sum (p - c)(p - c)^T [m^2]

  /// From moments (their centroid and scatter).
  static PointStats FromMoments(const detection::PlaneMoments& moments);
  /// The statistics of the same points mapped by T.
  PointStats Transformed(const Pose& T) const;
  /// Statistics of the union (parallel-axis theorem): C = C1 + C2 + k1 k2 / k (c1 - c2)(c1 - c2)^T.
  void Merge(const PointStats& other);
  /// Least-squares plane (smallest eigenpair of the scatter). The normal's sign is chosen so that
  /// normal . orientation >= 0; d = normal . centroid (any sign). valid = false below 3 points.
  detection::PlaneFit Fit(const Eigen::Vector3d& orientation) const;
};

/// Association, merging and sampling settings.
struct PlaneMapConfig {
  double max_normal_angle_deg = 10.0;  ///< [deg] observation vs map plane normals
  double max_offset = 0.10;            ///< [m] observation centroid to map plane distance
  /// [1/m] the offset gate grows by this times r^2, r = range of the observation's centroid from
  /// its sensor: depth noise grows quadratically (Kinect sigma(z) = 1.425e-3 z^2, Khoshelham &
  /// Elberink 2012; 3 sigma = 0.0043 z^2), and far detections are biased by it. 0 = constant gate.
  double max_offset_range_coeff = 0.0043;
  double max_gap = 0.30;     ///< [m] largest gap between an observation and a map plane's extent
  int min_touch_points = 3;  ///< [samples] within max_gap for the extents to count as touching
  double merge_max_normal_angle_deg = 5.0;  ///< [deg] between two map planes to merge them
  double merge_max_offset = 0.05;  ///< [m] each map plane's centroid to the other plane, to merge
  /// When the map is finished (SlamSystem::Finish, after the last optimisation), map planes
  /// within the merge thresholds are merged however far apart their extents are: one plane seen
  /// in separate parts (a floor seen only along the walls), its outline keeping each part.
  bool merge_across_gaps = true;
  /// [m] During SLAM (Refit after each optimisation), map planes whose extents are apart merge
  /// only when each one's centroid lies within this of the other plane (and their normals within
  /// merge_max_normal_angle_deg): the merged plane is one landmark that ties the keyframes seeing
  /// distant parts of one surface. Before the loop closes, drift sets such parts a few
  /// centimetres apart, so merging them at merge_max_offset would pull the poses towards a
  /// drifted plane; this tighter offset merges only parts that already agree. 0 = only touching
  /// planes merge.
  double refit_merge_across_gaps_offset = 0.02;
  int min_observation_points = 50;  ///< [points] smaller detected planes are not added to the map
  double sample_cell_size = 0.04;   ///< [m] grid cell of the per-observation samples
  int max_samples_per_observation = 3000;  ///< [samples] the cell doubles until below this
  /// [px] AddFrame samples every n-th row and column of depth-camera (pinhole) clouds: at 640 px
  /// and 58 deg a pixel spans 1.6 mm per metre of range, so n = 2 still puts several points in
  /// every 4 cm sample cell up to ~10 m. Spherical (LiDAR) range images always use every pixel.
  int sample_pixel_stride = 2;
  PolygonConfig polygon{0.08, 6.0, 0.0, 4000000};  ///< outline of each map plane (ConcaveHull)

  /// Problems with the values (empty when valid).
  std::vector<std::string> Validate() const;
};

/// One detected plane of one keyframe, as kept by the map.
struct PlaneObservation {
  std::int64_t keyframe_id = 0;
  int detection_id = 0;     ///< the plane's id in its frame's segmentation
  PointStats stats_sensor;  ///< point statistics in the sensor frame
  Eigen::Vector3d normal_sensor = Eigen::Vector3d::UnitZ();  ///< detected normal (sensor frame)
  /// Mean point per sample cell [m], sensor frame; only the samples that extended the map plane's
  /// extent when the observation was added (memory grows with area, not with keyframes).
  std::vector<Eigen::Vector3f> samples_sensor;
};

/// A plane of the map, in the world frame.
struct MapPlane {
  int id = 0;                                          ///< >= 1, stable unless merged away
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();   ///< unit, away from the observers
  double d = 0.0;                                      ///< n . p = d [m] (may be negative)
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  ///< [m]
  double mse = 0.0;                                    ///< lambda_min / K [m^2]
  PointStats stats_world;                              ///< merged world statistics
  std::vector<PlaneObservation> observations;          ///< in insertion order
  std::int64_t first_keyframe = 0;                     ///< smallest observing keyframe id
  std::int64_t last_keyframe = 0;                      ///< largest observing keyframe id

  std::int64_t point_count() const { return stats_world.count; }
};

/// Outline of a map plane (ConcaveHull of its world samples projected on the plane): one polygon
/// per separate part of the plane (a floor seen in pieces along the walls is one plane).
struct MapPlaneOutline {
  int id = 0;
  PlaneBasis basis;      ///< plane coordinates of `region`
  RegionOutline region;  ///< parts counter-clockwise, largest first; total area in region.area
  /// Per part: its vertices in the world [m] and the ear clipping of its polygon (indices).
  std::vector<std::vector<Eigen::Vector3d>> part_vertices;
  std::vector<std::vector<std::array<int, 3>>> part_triangles;
  /// Area actually observed [m^2]: occupied cells (polygon cell size) minus the expected overshoot
  /// of the boundary cells beyond the true edge (see the source). Unlike
  /// region.area it excludes holes (unseen parts inside the outline).
  double observed_area = 0.0;
};

/// What AddObservations did with each input plane.
struct FrameAssociation {
  std::vector<int> map_ids;  ///< per input plane: map plane id, or -1 when skipped (too small)
  int created = 0;           ///< new map planes
  int associated = 0;        ///< observations added to existing map planes
  int merged = 0;            ///< map planes merged away during this frame
};

class PlaneMap {
 public:
  explicit PlaneMap(const PlaneMapConfig& config = {});

  /// Adds the planes of keyframe `keyframe_id` seen at T_world_sensor. `plane_points[i]` are
  /// sensor-frame points of planes[i] (any number, subsampled on a grid; may be empty, then the
  /// extent is approximated by the rectangle with the plane's second moments). plane_points may be
  /// empty as a whole. A keyframe id already in the map must come with the same pose (CheckError
  /// otherwise: change poses with Refit).
  FrameAssociation AddObservations(std::int64_t keyframe_id, const Pose& T_world_sensor,
                                   const std::vector<detection::Plane>& planes,
                                   const std::vector<std::vector<Eigen::Vector3f>>& plane_points);
  /// Same, taking each plane's points from the segmentation's label image over `cloud` (every
  /// sample_pixel_stride-th row and column for pinhole clouds; the moments come from the planes).
  FrameAssociation AddFrame(std::int64_t keyframe_id, const Pose& T_world_sensor,
                            const detection::Segmentation& segmentation,
                            const datasets::OrganizedCloud& cloud);

  /// Re-fits the map planes seen from keyframes whose pose changed from their observations with
  /// the new keyframe poses (e.g. after pose-graph optimisation); keyframes absent from
  /// `T_world_keyframe` keep their pose. Then merges a re-fitted plane with any plane it now
  /// coincides with (apart ones within refit_merge_across_gaps_offset). Returns the number of
  /// merges.
  int Refit(const std::unordered_map<std::int64_t, Pose>& T_world_keyframe);

  /// Undoes merges the poses now contradict: the observations of a plane that, at the current
  /// poses, fall outside the association gates (max_normal_angle_deg; max_offset plus the range
  /// term) become a plane of their own. Returns the number of planes split.
  int SplitContradicted();

  /// Merges map planes that are one surface: within the merge thresholds and with touching
  /// extents, or with extents apart when each centroid lies within `across_gaps_offset` [m] of the
  /// other plane (0: touching only; capped at merge_max_offset). Returns the number of merges. The
  /// merged plane keeps the smaller id.
  int MergeCoincidentPlanes(double across_gaps_offset = 0.0);

  /// Removes the map planes with these ids (an id removed, or merged into one removed, then
  /// resolves to -1). Returns how many were removed.
  int Remove(const std::unordered_set<int>& ids);

  const std::vector<MapPlane>& planes() const { return planes_; }
  std::size_t size() const { return planes_.size(); }
  /// The plane with `id`, following merges (an id merged away resolves to its survivor); nullptr
  /// when never issued.
  const MapPlane* Find(int id) const;
  /// The current id of a plane once known as `id` (itself when not merged; -1 when unknown).
  int ResolveId(int id) const;
  /// Pose of a keyframe as currently used by the map; CheckError when unknown.
  const Pose& KeyframePose(std::int64_t keyframe_id) const;
  const PlaneMapConfig& config() const { return config_; }

  /// World sample points of a map plane (the observations' samples through the current poses).
  std::vector<Eigen::Vector3d> WorldSamples(const MapPlane& plane) const;
  /// Outline of one map plane; no parts when its samples give no region.
  MapPlaneOutline Outline(const MapPlane& plane) const;
  /// Outlines of all map planes, in the order of planes().
  std::vector<MapPlaneOutline> Outlines() const;

 private:
  /// Occupied sample cells of a map plane in its own basis, for the touching test.
  struct Extent {
    PlaneBasis basis;
    double cell = 0.0;
    // Open-addressing sets: an extent is rebuilt whenever an optimisation moves its plane.
    absl::flat_hash_set<std::int64_t> fine;    ///< cells of size `cell`
    absl::flat_hash_set<std::int64_t> coarse;  ///< cells of size max_gap (fast rejection)
    Eigen::AlignedBox2d box;  ///< of a point of each fine cell, in the basis (faster rejection)
    /// To be built from the plane before use: built on demand, since after an optimisation most
    /// planes are never tested for touching before the next one moves them again.
    bool stale = true;
  };

  PlaneObservation MakeObservation(std::int64_t keyframe_id, const detection::Plane& plane,
                                   const std::vector<Eigen::Vector3f>* points) const;
  void RefitPlane(MapPlane& plane) const;
  /// Drops the extent of `plane`, to be built again from it when next used.
  void InvalidateExtent(const MapPlane& plane);
  /// extents_[i], built first if stale.
  Extent& ExtentAt(std::size_t i);
  void AddToExtent(Extent& extent, const std::vector<Eigen::Vector3d>& world_points) const;
  int CountTouching(const Extent& extent, const std::vector<Eigen::Vector3d>& world_points,
                    int enough) const;
  bool Coincide(const MapPlane& a, const MapPlane& b, double across_gaps_offset);
  /// MergeCoincidentPlanes over the pairs with a plane in `changed` (all pairs when null); a
  /// merged plane joins `changed`.
  int MergeCoincident(double across_gaps_offset, std::unordered_set<int>* changed);
  /// Merges planes_[j] into planes_[i] (i keeps its id); erases j.
  void MergeInto(std::size_t i, std::size_t j);
  std::size_t IndexOf(int id) const;

  PlaneMapConfig config_;
  double cos_merge_;  ///< cos(config_.merge_max_normal_angle_deg): Coincide runs for many pairs
  std::vector<MapPlane> planes_;
  std::vector<Extent> extents_;  ///< parallel to planes_
  std::unordered_map<std::int64_t, Pose> keyframe_poses_;
  std::unordered_map<int, int> merged_into_;  ///< id -> id it was merged into
  int next_id_ = 1;
};

}  // namespace planeslam::mapping
