#include "planeslam/mapping/view_bins.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace planeslam::mapping {

std::uint32_t ViewBins::Bin(const Eigen::Vector3d& direction) {
  // Cube map: the face of the largest component, the other two divided by it on the face.
  int axis = 0;
  direction.cwiseAbs().maxCoeff(&axis);
  const double m = direction[axis];
  const int face = 2 * axis + (m < 0 ? 1 : 0);
  const double u = direction[(axis + 1) % 3] / std::abs(m);
  const double v = direction[(axis + 2) % 3] / std::abs(m);
  const auto cell = [](double x) {
    return std::clamp(static_cast<int>((x + 1.0) * 0.5 * kBinsPerFace), 0, kBinsPerFace - 1);
  };
  return static_cast<std::uint32_t>((face * kBinsPerFace + cell(u)) * kBinsPerFace + cell(v));
}

ViewBins::ViewBins(const datasets::OrganizedCloud& cloud, int stride) {
  stride = std::max(1, stride);
  // Every bin of the cube map (24,576 floats, 0 = no return), then the ones with returns in order.
  std::vector<float> farthest(6 * kBinsPerFace * kBinsPerFace, 0.0f);
  for (int r = 0; r < cloud.height; r += stride) {
    for (int c = 0; c < cloud.width; c += stride) {
      const Eigen::Vector3f& p = cloud.at(r, c);
      if (!p.allFinite()) continue;
      const float range = p.norm();
      if (!(range > 0)) continue;
      float& bin = farthest[Bin(p.cast<double>())];
      bin = std::max(bin, range);
    }
  }
  for (std::uint32_t bin = 0; bin < farthest.size(); ++bin) {
    if (farthest[bin] > 0) farthest_.emplace_back(bin, farthest[bin]);
  }
}

bool ViewBins::Reaches(const Eigen::Vector3d& p_sensor, double tolerance) const {
  const double range = p_sensor.norm();
  if (!(range > 0)) return false;
  const std::uint32_t bin = Bin(p_sensor);
  const auto it = std::lower_bound(
      farthest_.begin(), farthest_.end(), bin,
      [](const std::pair<std::uint32_t, float>& e, std::uint32_t b) { return e.first < b; });
  return it != farthest_.end() && it->first == bin && range <= it->second + tolerance;
}

}  // namespace planeslam::mapping
