#pragma once
/// Builds plane detectors by method name from the configuration (sections "detection", "grid",
/// "point"; see config_sections_detection.cpp and config/detection_*.yaml).
#include <memory>
#include <string>
#include <vector>

#include "config.hpp"
#include "planeslam/detection/detection_config.hpp"
#include "planeslam/detection/grid_region_growing.hpp"
#include "planeslam/detection/plane_detector.hpp"
#include "planeslam/detection/point_region_growing.hpp"

namespace planeslam::app {

/// YAML section "detection": the shared thresholds with the threshold model as a string.
struct DetectionSection {
  std::string method = "grid";            ///< default detector of `detect` and `run`
  std::string threshold_model = "depth";  ///< constant (the paper) | depth (sensor noise model)
  detection::DetectionParams params;      ///< params.model is set from threshold_model
};

/// Method names MakeDetector accepts, e.g. for --help and the benchmark: grid (GBRG with
/// grid.cell_size grids, 3 by default), grid-fast (GBRG's grid-level pipeline, 6x6 grids by
/// default), grid-paper (the paper's GBRG alone: refit on every join, no refinement, merging or
/// ray fit), point (PBRG, adaptive refit), point-paper (the paper's PBRG: refit on every point,
/// no merging or ray fit).
std::vector<std::string> DetectorMethods();

/// The shared thresholds of `config` (section "detection") with the model resolved.
detection::DetectionParams DetectionParamsFrom(const Config& config);

/// A detector for `method` configured from `config`, for clouds decimated by `decimation`
/// (datasets::Decimate): detection.theta counts full-resolution pixels, so such a detector needs
/// theta / decimation^2 of its own. Throws ConfigError naming the method and the valid ones when
/// `method` is unknown, or the problem when the parameters are invalid.
std::unique_ptr<detection::PlaneDetector> MakeDetector(const std::string& method,
                                                       const Config& config, int decimation = 1);

}  // namespace planeslam::app
