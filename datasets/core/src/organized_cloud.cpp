#include "planeslam/datasets/organized_cloud.hpp"

#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {
namespace {

void CheckFactor(int factor) {
  PLANESLAM_CHECK(factor >= 1 && factor <= 16, "decimation factor " << factor);
}

}  // namespace

OrganizedCloud Decimate(const OrganizedCloud& cloud, int factor) {
  CheckFactor(factor);
  if (factor == 1) return cloud;
  // Rounding up keeps the last row and column when the size is not a multiple of the factor.
  OrganizedCloud out((cloud.width + factor - 1) / factor, (cloud.height + factor - 1) / factor,
                     cloud.model);
  for (int y = 0; y < out.height; ++y) {
    const Eigen::Vector3f* in = &cloud.at(y * factor, 0);
    Eigen::Vector3f* row = &out.at(y, 0);
    for (int x = 0; x < out.width; ++x) row[x] = in[static_cast<std::size_t>(x) * factor];
  }
  return out;
}

PinholeIntrinsics DecimateIntrinsics(const PinholeIntrinsics& intrinsics, int factor) {
  CheckFactor(factor);
  PinholeIntrinsics out = intrinsics;
  out.width = (intrinsics.width + factor - 1) / factor;
  out.height = (intrinsics.height + factor - 1) / factor;
  out.fx = intrinsics.fx / factor;
  out.fy = intrinsics.fy / factor;
  out.cx = intrinsics.cx / factor;
  out.cy = intrinsics.cy / factor;
  return out;
}

}  // namespace planeslam::datasets
