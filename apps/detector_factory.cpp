#include "detector_factory.hpp"

#include <algorithm>
#include <cmath>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::app {

std::vector<std::string> DetectorMethods() {
  return {"grid", "grid-fast", "grid-paper", "point", "point-paper"};
}

detection::DetectionParams DetectionParamsFrom(const Config& config) {
  const auto& section = config.Get<DetectionSection>("detection");
  detection::DetectionParams params = section.params;
  if (!detection::ParseThresholdModel(section.threshold_model, params.model)) {
    throw ConfigError("key 'detection.threshold_model': expected constant or depth, got '" +
                      section.threshold_model + "'");
  }
  return params;
}

namespace {

void ThrowIfInvalid(const std::string& method, std::vector<std::string> problems) {
  if (problems.empty()) return;
  std::string text = "detector '" + method + "': ";
  for (std::size_t i = 0; i < problems.size(); ++i) text += (i ? "; " : "") + problems[i];
  throw ConfigError(text);
}

}  // namespace

std::unique_ptr<detection::PlaneDetector> MakeDetector(const std::string& method,
                                                       const Config& config, int decimation) {
  PLANESLAM_CHECK(decimation >= 1, "decimation " << decimation);
  detection::DetectionParams params = DetectionParamsFrom(config);
  params.theta = std::max(1, static_cast<int>(std::lround(static_cast<double>(params.theta) /
                                                          (decimation * decimation))));
  detection::GridParams grid = config.Get<detection::GridParams>("grid");
  detection::PointParams point = config.Get<detection::PointParams>("point");
  std::string name = method;
  if (method == "grid" || method == "grid-paper" || method == "grid-fast") {
    if (method == "grid-fast") detection::UseFastVariant(params, grid);
    if (method == "grid") name = "grid" + std::to_string(grid.CellSize());
    if (method == "grid-paper") {
      grid.refit_interval = 1;
      params.refine_boundary = false;
      params.merge_regions = false;
      params.ray_fit = false;
    }
    auto problems = params.Validate();
    auto more = grid.Validate();
    problems.insert(problems.end(), more.begin(), more.end());
    ThrowIfInvalid(method, problems);
    return std::make_unique<detection::GridRegionGrowing>(params, grid, name);
  }
  if (method == "point" || method == "point-paper") {
    if (method == "point-paper") {
      point.refit_interval = 1;
      params.merge_regions = false;
      params.ray_fit = false;
    }
    auto problems = params.Validate();
    auto more = point.Validate();
    problems.insert(problems.end(), more.begin(), more.end());
    ThrowIfInvalid(method, problems);
    return std::make_unique<detection::PointRegionGrowing>(params, point, name);
  }
  std::string valid;
  for (const auto& m : DetectorMethods()) valid += (valid.empty() ? "" : ", ") + m;
  throw ConfigError("unknown detection method '" + method + "' (valid: " + valid + ")");
}

}  // namespace planeslam::app
