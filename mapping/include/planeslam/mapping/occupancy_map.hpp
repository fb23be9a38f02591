#pragma once
/// Optional OctoMap output: range frames ray-cast into an octomap::OcTree, written as a .bt file.
///
/// The interface is free of OctoMap and PCL types; when planeslam is built without OctoMap
/// (PLANESLAM_WITH_OCTOMAP=OFF), available() is false, Insert does nothing and Write/Load throw
/// IoError saying so.
///
/// Each frame is voxel-downsampled in the sensor frame first (dense depth images put many rays into
/// one voxel; the ray casting cost is per ray), transformed to the world and inserted with
/// insertPointCloud(points, sensor origin, max_range): voxels along each ray become more likely
/// free (prob_miss), the end voxel more likely occupied (prob_hit); rays longer than max_range only
/// clear up to max_range (far depth is noisy, and long grazing rays erode floors).
#include <Eigen/Core>
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::mapping {

struct OccupancyMapConfig {
  bool enabled =
      true;  ///< whether 'planeslam run' builds and writes the map (the builder ignores it)
  double resolution = 0.05;        ///< [m] leaf voxel edge
  double max_range = 4.0;          ///< [m] longer rays only clear free space up to here; <= 0: none
  double downsample_voxel = 0.05;  ///< [m] voxel grid applied to each frame first; 0 = off
  double prob_hit = 0.7;           ///< [probability] update of an end voxel, > 0.5
  double prob_miss = 0.4;          ///< [probability] update of a traversed voxel, < 0.5

  /// Problems with the values (empty when valid).
  std::vector<std::string> Validate() const;
};

enum class Occupancy { kUnknown, kFree, kOccupied };

/// Counts of an occupancy map's leaves.
struct OccupancyMapStats {
  std::size_t occupied_leaves = 0;
  std::size_t free_leaves = 0;
  std::size_t inserted_frames = 0;
  std::size_t inserted_points = 0;  ///< after downsampling
  std::size_t memory_bytes = 0;     ///< octree memory
};

/// Centroid per occupied voxel of edge `voxel` (> 0); non-finite points are dropped; the output
/// order is deterministic (sorted by voxel).
std::vector<Eigen::Vector3f> VoxelDownsample(const std::vector<Eigen::Vector3f>& points,
                                             double voxel);

class OccupancyMapBuilder {
 public:
  /// CheckError when `config` is invalid.
  explicit OccupancyMapBuilder(const OccupancyMapConfig& config = {});
  ~OccupancyMapBuilder();
  OccupancyMapBuilder(OccupancyMapBuilder&&) noexcept;
  OccupancyMapBuilder& operator=(OccupancyMapBuilder&&) noexcept;

  /// True when built with OctoMap.
  static bool available();

  /// Ray-casts the valid points of a frame (sensor frame) seen from T_world_sensor.
  void Insert(const datasets::OrganizedCloud& cloud, const Pose& T_world_sensor);
  void Insert(const std::vector<Eigen::Vector3f>& points_sensor, const Pose& T_world_sensor);
  /// As Insert on each scan in order, with the ray casting spread over `threads` threads; the map
  /// is the same for every thread count. `scans[i]` is seen from `poses[i]`.
  void InsertAll(const std::vector<const std::vector<Eigen::Vector3f>*>& scans,
                 const std::vector<Pose>& poses, unsigned threads);

  /// Writes the maximum-likelihood map as OctoMap binary (.bt) atomically; IoError on failure or
  /// when built without OctoMap. The in-memory map keeps its probabilities (only pruned).
  void Write(const std::string& path) const;
  /// Reads a .bt file (octomap::OcTree::readBinary) into a builder for queries; IoError when the
  /// file is missing or not a binary OcTree, or when built without OctoMap.
  static OccupancyMapBuilder Load(const std::string& path);

  /// State of the leaf containing world point p.
  Occupancy Query(const Eigen::Vector3d& p) const;
  OccupancyMapStats Stats() const;
  double resolution() const;
  const OccupancyMapConfig& config() const { return config_; }

 private:
  struct Impl;
  OccupancyMapConfig config_;
  std::unique_ptr<Impl> impl_;
};

namespace internal {
/// Whether the rays are walked four at a time with AVX2 where the processor has it (the
/// default); false walks them one at a time, as on other processors. Both give the same cells;
/// the tests compare each with OctoMap.
void SetVectorRayWalk(bool enabled);
}  // namespace internal

}  // namespace planeslam::mapping
