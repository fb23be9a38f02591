#pragma once
/// KITTI Velodyne scans (.bin: float32 x y z reflectance per point, not organized) and their
/// projection to an organized range image (rows by elevation, columns by azimuth).
#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "planeslam/datasets/file_sequence.hpp"
#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/sensor_config.hpp"

namespace planeslam::datasets {

/// One LiDAR return: x y z [m] (sensor frame) and reflectance.
using LidarPoint = Eigen::Vector4f;

/// Parses a KITTI .bin held in memory. Throws IoError naming `name` when the size is not a multiple
/// of 16 bytes (truncated), the scan is empty (no bytes, or every point at the origin), a point has
/// a NaN or infinite coordinate, or it holds more points than the input limits allow.
std::vector<LidarPoint> ParseKittiScan(const std::string& bytes, const std::string& name);
/// Reads a KITTI .bin file (see ParseKittiScan).
std::vector<LidarPoint> ReadKittiScan(const std::string& path);

/// What happened to the points of a scan during projection.
struct RangeProjectionStats {
  std::size_t points = 0;             ///< input points
  std::size_t invalid = 0;            ///< non-finite or at the origin
  std::size_t outside_elevation = 0;  ///< beyond the image's elevation range (elevation mode)
  std::size_t outside_range = 0;      ///< beyond min/max range of the config
  std::size_t shifted = 0;            ///< placed in a free neighbouring column (see config)
  std::size_t collisions = 0;         ///< lost to a nearer point in the same cell
  std::size_t placed = 0;             ///< stored in the image
  bool used_scan_order = false;       ///< rows came from the rings of the point order
  double PlacedFraction() const { return points ? static_cast<double>(placed) / points : 0.0; }
};

/// Projects a scan to a lidar_rows x lidar_cols range image (SensorModel::kSpherical). Column c
/// covers azimuth pi - 2 pi (c + 0.5) / cols (column cols/2 looks along +x); the row is the laser
/// ring (scan_order mode) or the nearest of lidar_rows evenly spaced elevations. A point whose cell
/// is taken moves to a free cell up to lidar_column_shift columns away (nearer side first); when
/// none is free the nearer of the two points is kept. Points keep their sensor-frame coordinates.
OrganizedCloud ProjectToRangeImage(const std::vector<LidarPoint>& scan, const SensorConfig& config,
                                   RangeProjectionStats* stats = nullptr);

/// Ring index of every point from KITTI's point order (a new ring starts where the azimuth wraps
/// by more than pi), renumbered so ring 0 has the highest mean slope z / r (the highest laser).
/// Returns the number of rings; `rings` gets one index per point.
int RecoverRings(const std::vector<LidarPoint>& scan, std::vector<int>* rings);

namespace internal {
/// atan2(y, x) of every point, approximately (within 1e-6 rad of std::atan2; exposed for its
/// test): the projection's first guess at each azimuth.
void ApproximateAzimuths(const std::vector<LidarPoint>& scan, std::vector<float>* azimuths);
/// Whether the reader's vector loops may take their AVX2 versions where the processor has them
/// (default true); false takes the baseline versions everywhere (for tests of both).
void UseAvx2Clones(bool use);
}  // namespace internal

/// Reads a .bin and projects it with the config (and its range limits).
OrganizedCloud ReadKittiRangeImage(const std::string& path, const SensorConfig& config,
                                   RangeProjectionStats* stats = nullptr);

/// A folder of KITTI .bin scans, in natural file-name order: a bare folder of scans, or a KITTI
/// odometry sequence folder (scans in its velodyne/; `folder` may also name velodyne/ itself).
/// Ground truth: config.lidar_poses_file, else the sequence folder's poses.txt, else KITTI's own
/// tree's dataset/poses/NN.txt for dataset/sequences/NN (KITTI odometry format, 12 numbers a line,
/// the pose of scan N on line N, N taken from the file name); if the sequence folder has calib.txt
/// with a `Tr:` line (velodyne to camera), the camera poses are converted to velodyne poses
/// Tr^-1 P Tr. Timestamps: the sequence folder's times.txt (one per line, indexed like the poses)
/// when present, else from the file names.
std::unique_ptr<FileSequence> OpenKittiFolder(const std::string& folder,
                                              const SensorConfig& config);

}  // namespace planeslam::datasets
