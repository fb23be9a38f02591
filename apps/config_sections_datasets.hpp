#pragma once
/// Config sections of the datasets module: "sensor" (datasets::SensorConfig: intrinsics, depth
/// units, PCD unit scale, ICL y flip, LiDAR range-image projection, ground-truth association) and
/// "limits" (the input limits every reader checks before allocating).
#include "config.hpp"
#include "planeslam/datasets/input_limits.hpp"
#include "planeslam/datasets/sensor_config.hpp"

namespace planeslam::app {

/// YAML section "limits": mirrors datasets::InputLimits (ints, so at most 2^31 - 1 each).
struct LimitsConfig {
  int max_pixels = 64 * 1024 * 1024;  ///< per image / organized cloud [px]
  int max_points = 64 * 1024 * 1024;  ///< per unorganized scan (KITTI .bin) [points]
  int max_side = 65535;               ///< image width or height [px]
  int max_lines = 50 * 1000 * 1000;   ///< lines in a text file (trajectories, frame lists)
};

/// The datasets::InputLimits the "limits" section describes.
datasets::InputLimits ToInputLimits(const LimitsConfig& limits);

/// Sets datasets::GlobalInputLimits() from the config's "limits" section. Commands call it once
/// after loading the config and before reading any input.
void ApplyInputLimits(const Config& config);

}  // namespace planeslam::app
