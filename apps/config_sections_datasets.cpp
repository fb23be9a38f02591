// Config sections of the datasets module (see config_sections_datasets.hpp).
#include "config_sections_datasets.hpp"

namespace planeslam::app {
namespace {

namespace ds = planeslam::datasets;

void VisitSensor(FieldVisitor& v, ds::SensorConfig& c) {
  v.Field("width", c.intrinsics.width, "depth image width [px]", 1, 65535);
  v.Field("height", c.intrinsics.height, "depth image height [px]", 1, 65535);
  v.Field("fx", c.intrinsics.fx, "focal length x [px] (TUM fr3 535.4)", 1e-3, 1e6);
  v.Field("fy", c.intrinsics.fy,
          "focal length y [px] (TUM fr3 539.2); negative = flipped y axis like flip_y", -1e6, 1e6);
  v.Field("cx", c.intrinsics.cx, "principal point x [px]", -1e6, 1e6);
  v.Field("cy", c.intrinsics.cy, "principal point y [px]", -1e6, 1e6);
  v.Field("intrinsics_source", c.intrinsics_source,
          "auto: a dataset folder's intrinsics.yaml (ICL-NUIM: its published camera) wins over "
          "these values; config: always these values",
          {"auto", "config"});
  v.Field("depth_scale", c.depth_scale,
          "depth PNG units per metre (TUM/ICL 5000, millimetre PNGs 1000) [1/m]", 1e-6, 1e9);
  v.Field("flip_y", c.flip_y,
          "negate fy when back-projecting (ICL-NUIM: its ground truth uses a y-up camera)");
  v.Field("min_depth", c.min_depth, "closer depths/ranges become invalid [m]", 0.0, 1e6);
  v.Field("max_depth", c.max_depth, "farther depths/ranges become invalid [m]; 0 = no limit", 0.0,
          1e6);
  v.Field("unit_scale", c.unit_scale,
          "PCD coordinates times this = metres (centimetre scans: 0.01) [m/unit]", 1e-9, 1e9);
  v.Field("pcd_model", c.pcd_model,
          "grid of organized PCD files: pinhole (depth camera) or spherical (laser scanner)",
          {"pinhole", "spherical"});
  v.Field("gt_max_time_difference", c.gt_max_time_difference,
          "largest frame/ground-truth stamp difference to associate a pose (TUM tools: 0.02) [s]",
          0.0, 1e6);
  v.Field("lidar_rows", c.lidar_rows, "LiDAR range image rows, one per laser [rows] (HDL-64E: 64)",
          1, 65535);
  v.Field("lidar_cols", c.lidar_cols,
          "LiDAR range image columns, firings per turn [columns] (HDL-64E at 10 Hz: 2083)", 1,
          65535);
  v.Field("lidar_row_mode", c.lidar_row_mode,
          "scan_order: row = laser ring from KITTI's point order (falls back to elevation when "
          "the ring count is not lidar_rows); elevation: uniform elevation bins",
          {"scan_order", "elevation"});
  v.Field("lidar_column_shift", c.lidar_column_shift,
          "a point whose cell is taken may move this many columns to a free one [cells]", 0, 8);
  v.Field("lidar_elevation_max_deg", c.lidar_elevation_max_deg,
          "elevation of the top row's centre, elevation mode [deg] (HDL-64E: 2.0)", -90.0, 90.0);
  v.Field("lidar_elevation_min_deg", c.lidar_elevation_min_deg,
          "elevation of the bottom row's centre, elevation mode [deg] (HDL-64E: -24.9)", -90.0,
          90.0);
  v.Field("lidar_poses_file", c.lidar_poses_file,
          "KITTI poses file for a .bin folder; empty = the folder's poses.txt if any", {});
}

std::vector<std::string> ValidateSensor(const ds::SensorConfig& c) { return c.Validate(); }

PLANESLAM_REGISTER_CONFIG_SECTION(ds::SensorConfig, "sensor",
                                  "Range sensor: depth camera intrinsics and units, PCD units, "
                                  "LiDAR range-image projection, ground-truth association",
                                  &VisitSensor, &ValidateSensor);

void VisitLimits(FieldVisitor& v, LimitsConfig& c) {
  v.Field("max_pixels", c.max_pixels, "largest image / organized cloud a reader accepts [px]", 1,
          2147483647);
  v.Field("max_points", c.max_points, "largest unorganized scan (KITTI .bin) [points]", 1,
          2147483647);
  v.Field("max_side", c.max_side, "largest image width or height [px]", 1, 2147483647);
  v.Field("max_lines", c.max_lines,
          "most lines in a text input (trajectories, frame lists) [lines]", 1, 2147483647);
}

PLANESLAM_REGISTER_CONFIG_SECTION(LimitsConfig, "limits",
                                  "Input limits: readers refuse larger inputs before allocating",
                                  &VisitLimits);

}  // namespace

datasets::InputLimits ToInputLimits(const LimitsConfig& limits) {
  datasets::InputLimits out;
  out.max_pixels = limits.max_pixels;
  out.max_points = limits.max_points;
  out.max_side = limits.max_side;
  out.max_lines = limits.max_lines;
  return out;
}

void ApplyInputLimits(const Config& config) {
  datasets::GlobalInputLimits() = ToInputLimits(config.Get<LimitsConfig>("limits"));
}

}  // namespace planeslam::app
