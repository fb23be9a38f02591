#pragma once
/// How range data is turned into organized clouds: camera intrinsics and depth units, the unit of
/// PCD coordinates, the ICL-NUIM y-flip, the LiDAR range-image projection and ground-truth
/// association. Mirrored by the YAML section "sensor" (apps/config_sections_datasets.cpp).
#include <string>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"

namespace planeslam::datasets {

/// Sensor configuration shared by every reader. Defaults fit TUM RGB-D freiburg3.
struct SensorConfig {
  /// Depth camera intrinsics [px]; used for depth PNGs unless the dataset folder provides its own
  /// (see intrinsics_source).
  PinholeIntrinsics intrinsics;
  /// "auto": a depth folder's intrinsics.yaml wins when present, else the layout's published
  /// values for ICL-NUIM, else `intrinsics`; "config": always `intrinsics`.
  std::string intrinsics_source = "auto";
  double depth_scale = 5000.0;  ///< depth PNG units per metre (TUM/ICL 5000, millimetre PNGs 1000)
  /// Negate fy when back-projecting: ICL-NUIM's ground truth is expressed for a y-up camera, so
  /// its depth must be back-projected with fy < 0 for the poses to agree with the clouds.
  bool flip_y = false;
  double max_depth = 0.0;   ///< [m] depth/range beyond this becomes invalid (NaN); 0 = no limit
  double min_depth = 0.0;   ///< [m] depth/range below this becomes invalid (NaN)
  double unit_scale = 1.0;  ///< PCD coordinates are multiplied by this to get metres (cm: 0.01)
  /// Grid of organized PCD files: "pinhole" (depth camera, e.g. Kinect) or "spherical" (rows =
  /// elevation, columns = azimuth: terrestrial laser scans).
  std::string pcd_model = "pinhole";
  /// Largest |t_frame - t_groundtruth| for a ground-truth pose to be associated [s] (TUM tools:
  /// 0.02).
  double gt_max_time_difference = 0.02;
  /// LiDAR (.bin) range image: rows by elevation, columns by azimuth. The HDL-64E at 10 Hz fires
  /// about 2083 times per revolution (0.1728 deg), so 2083 columns hold about one point per cell
  /// (a coarser grid such as 2048 columns puts more pairs of returns into one cell).
  int lidar_rows = 64;
  int lidar_cols = 2083;
  /// How a scan point finds its row: "scan_order" recovers the laser ring from the point order of
  /// a KITTI .bin (each ring is one azimuth sweep; rings sorted by mean elevation), which keeps the
  /// HDL-64E's unevenly spaced lasers on separate rows; falls back to "elevation" when the number
  /// of sweeps is not lidar_rows. "elevation": uniform bins between the elevation limits.
  std::string lidar_row_mode = "scan_order";
  /// When a point's cell is taken, it may move this many columns sideways to a free cell (the
  /// nearer side first). KITTI rings hold 1960-2160 points, some only half a step apart, so
  /// neighbours share a cell; shifting by one column (0.17 deg) keeps most of them. 0 = the
  /// nearer point wins.
  int lidar_column_shift = 1;
  double lidar_elevation_max_deg = 2.0;    ///< [deg] elevation of the top row's centre (HDL-64E)
  double lidar_elevation_min_deg = -24.9;  ///< [deg] elevation of the bottom row's centre
  /// KITTI poses file (12 numbers a line) for a .bin folder; empty = look for poses.txt there.
  std::string lidar_poses_file;

  /// Intrinsics with fy negated when flip_y is set (what the back-projection uses).
  PinholeIntrinsics EffectiveIntrinsics() const;
  /// Problems with the values (empty when fine).
  std::vector<std::string> Validate() const;
  /// Throws ConfigError listing the problems when Validate() finds any.
  void ValidateOrThrow() const;
};

/// Camera description read from a dataset folder's intrinsics.yaml.
struct CameraFile {
  PinholeIntrinsics intrinsics;  ///< ready for back-projection: fy < 0 when the file flips y
  double depth_scale = 5000.0;   ///< PNG units per metre
  bool flip_y = false;           ///< true when fy < 0 (flip_y: true, or a negative fy, in the file)
};

/// Parses a flat `key: value` file (# comments) with keys width height fx fy cx cy depth_scale
/// and optionally flip_y (true/false). Strict: unknown, duplicate or missing keys and bad numbers
/// throw IoError(file, line, reason).
CameraFile ParseCameraFile(const std::string& text, const std::string& name);
/// Reads and parses `path` (see ParseCameraFile).
CameraFile ReadCameraFile(const std::string& path);

/// ICL-NUIM's published intrinsics (481.2, 480, 319.5, 239.5), depth 5000 units/m, with the y flip.
CameraFile IclNuimCamera();

}  // namespace planeslam::datasets
