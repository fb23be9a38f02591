#pragma once
/// Interface shared by every plane detector (grid-based GBRG, point-based PBRG, variants).
#include <string>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/detection/plane.hpp"

namespace planeslam::detection {

class PlaneDetector {
 public:
  virtual ~PlaneDetector() = default;
  /// Short method name used in reports and benchmarks, e.g. "grid3", "grid5", "point".
  virtual std::string Name() const = 0;
  /// Detects planes in one organized cloud. Deterministic; never throws on data conditions (an
  /// empty or all-invalid cloud gives a segmentation with no planes).
  virtual Segmentation Detect(const datasets::OrganizedCloud& cloud) const = 0;
};

}  // namespace planeslam::detection
