#include "planeslam/datasets/sensor_config.hpp"

#include <cmath>
#include <map>
#include <sstream>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/input_limits.hpp"
#include "reader_util.hpp"

namespace planeslam::datasets {

PinholeIntrinsics SensorConfig::EffectiveIntrinsics() const {
  PinholeIntrinsics k = intrinsics;
  if (flip_y) k.fy = -k.fy;
  return k;
}

std::vector<std::string> SensorConfig::Validate() const {
  std::vector<std::string> problems;
  auto finite = [](double v) { return std::isfinite(v); };
  const InputLimits& limits = GlobalInputLimits();
  if (intrinsics.width <= 0 || intrinsics.height <= 0 || intrinsics.width > limits.max_side ||
      intrinsics.height > limits.max_side) {
    problems.push_back("intrinsics width and height must be in [1, " +
                       std::to_string(limits.max_side) + "]");
  }
  if (!finite(intrinsics.fx) || intrinsics.fx <= 0.0) problems.push_back("fx must be > 0");
  if (!finite(intrinsics.fy) || intrinsics.fy == 0.0) {
    problems.push_back("fy must be non-zero (negative = flipped y axis)");
  }
  if (!finite(intrinsics.cx) || !finite(intrinsics.cy)) problems.push_back("cx, cy must be finite");
  if (intrinsics_source != "auto" && intrinsics_source != "config") {
    problems.push_back("intrinsics_source must be 'auto' or 'config'");
  }
  if (!finite(depth_scale) || depth_scale <= 0.0) problems.push_back("depth_scale must be > 0");
  if (pcd_model != "pinhole" && pcd_model != "spherical") {
    problems.push_back("pcd_model must be 'pinhole' or 'spherical'");
  }
  if (!finite(unit_scale) || unit_scale <= 0.0) problems.push_back("unit_scale must be > 0");
  if (!finite(max_depth) || max_depth < 0.0) problems.push_back("max_depth must be >= 0");
  if (!finite(min_depth) || min_depth < 0.0) problems.push_back("min_depth must be >= 0");
  if (max_depth > 0.0 && min_depth >= max_depth) {
    problems.push_back("min_depth must be below max_depth (or max_depth 0 = no limit)");
  }
  if (!finite(gt_max_time_difference) || gt_max_time_difference < 0.0) {
    problems.push_back("gt_max_time_difference must be >= 0");
  }
  if (lidar_rows <= 0 || lidar_cols <= 0 || lidar_rows > limits.max_side ||
      lidar_cols > limits.max_side) {
    problems.push_back("lidar_rows and lidar_cols must be in [1, " +
                       std::to_string(limits.max_side) + "]");
  }
  if (lidar_column_shift < 0 || lidar_column_shift > 8) {
    problems.push_back("lidar_column_shift must be in [0, 8]");
  }
  if (lidar_row_mode != "scan_order" && lidar_row_mode != "elevation") {
    problems.push_back("lidar_row_mode must be 'scan_order' or 'elevation'");
  }
  if (!finite(lidar_elevation_max_deg) || !finite(lidar_elevation_min_deg) ||
      lidar_elevation_max_deg <= lidar_elevation_min_deg || lidar_elevation_max_deg > 90.0 ||
      lidar_elevation_min_deg < -90.0) {
    problems.push_back(
        "lidar elevation range must satisfy -90 <= lidar_elevation_min_deg < "
        "lidar_elevation_max_deg <= 90");
  }
  return problems;
}

void SensorConfig::ValidateOrThrow() const {
  const auto problems = Validate();
  if (problems.empty()) return;
  std::string msg = "sensor config: ";
  for (std::size_t i = 0; i < problems.size(); ++i) msg += (i ? "; " : "") + problems[i];
  throw ConfigError(msg);
}

CameraFile ParseCameraFile(const std::string& text, const std::string& name) {
  CameraFile out;
  std::map<std::string, long> seen;
  detail::LineReader reader(text, name);
  std::string_view line;
  double values[7] = {};
  static const char* kRequired[7] = {"width", "height", "fx", "fy", "cx", "cy", "depth_scale"};
  while (reader.Next(&line)) {
    const std::size_t hash = line.find('#');
    if (hash != std::string_view::npos) line = line.substr(0, hash);
    line = detail::Trim(line);
    if (line.empty()) continue;
    const std::size_t colon = line.find(':');
    if (colon == std::string_view::npos) {
      throw IoError(name, reader.line_number(), "expected 'key: value'");
    }
    const std::string key(detail::Trim(line.substr(0, colon)));
    const std::string_view value = detail::Trim(line.substr(colon + 1));
    if (seen.count(key)) {
      throw IoError(
          name, reader.line_number(),
          "duplicate key '" + key + "' (first on line " + std::to_string(seen[key]) + ")");
    }
    seen[key] = reader.line_number();
    if (key == "flip_y") {
      if (value == "true") {
        out.flip_y = true;
      } else if (value == "false") {
        out.flip_y = false;
      } else {
        throw IoError(name, reader.line_number(), "flip_y must be true or false");
      }
      continue;
    }
    int index = -1;
    for (int i = 0; i < 7; ++i) {
      if (key == kRequired[i]) index = i;
    }
    if (index < 0) {
      throw IoError(name, reader.line_number(),
                    "unknown key '" + key +
                        "' (expected width, height, fx, fy, cx, cy, depth_scale, flip_y)");
    }
    if (!detail::ParseDouble(value, &values[index])) {
      throw IoError(name, reader.line_number(),
                    "key '" + key + "': expected a number, got '" + std::string(value) + "'");
    }
  }
  for (const char* key : kRequired) {
    if (!seen.count(key)) throw IoError(name, std::string("missing key '") + key + "'");
  }
  const InputLimits& limits = GlobalInputLimits();
  for (int i = 0; i < 2; ++i) {
    if (values[i] != std::floor(values[i]) || values[i] < 1 ||
        values[i] > static_cast<double>(limits.max_side)) {
      throw IoError(name, seen[kRequired[i]],
                    std::string(kRequired[i]) + " must be an integer in [1, " +
                        std::to_string(limits.max_side) + "]");
    }
  }
  if (values[2] <= 0) throw IoError(name, seen["fx"], "fx must be > 0");
  if (values[3] == 0) throw IoError(name, seen["fy"], "fy must be non-zero");
  if (values[6] <= 0) throw IoError(name, seen["depth_scale"], "depth_scale must be > 0");
  out.intrinsics.width = static_cast<int>(values[0]);
  out.intrinsics.height = static_cast<int>(values[1]);
  out.intrinsics.fx = values[2];
  out.intrinsics.fy = values[3];
  out.intrinsics.cx = values[4];
  out.intrinsics.cy = values[5];
  out.depth_scale = values[6];
  // Fold the flip into fy so the result is directly usable for back-projection.
  if (out.flip_y) out.intrinsics.fy = -out.intrinsics.fy;
  out.flip_y = out.intrinsics.fy < 0;
  return out;
}

CameraFile ReadCameraFile(const std::string& path) {
  return ParseCameraFile(detail::ReadWholeFile(path, 1 << 20), path);
}

CameraFile IclNuimCamera() {
  // Handa et al., ICL-NUIM (ICRA 2014): 481.20, -480.00, 319.50, 239.50; depth PNG / 5000 = m.
  CameraFile c;
  c.intrinsics.width = 640;
  c.intrinsics.height = 480;
  c.intrinsics.fx = 481.2;
  c.intrinsics.fy = -480.0;
  c.intrinsics.cx = 319.5;
  c.intrinsics.cy = 239.5;
  c.depth_scale = 5000.0;
  c.flip_y = true;
  return c;
}

}  // namespace planeslam::datasets
