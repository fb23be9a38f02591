#include "planeslam/datasets/depth_image.hpp"

#include <cmath>
#include <limits>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {

DepthProjector::DepthProjector(const PinholeIntrinsics& intrinsics, double depth_scale,
                               double min_depth, double max_depth)
    : intrinsics_(intrinsics) {
  PLANESLAM_CHECK(intrinsics.width > 0 && intrinsics.height > 0, "empty intrinsics");
  PLANESLAM_CHECK(intrinsics.fx > 0 && intrinsics.fy != 0, "bad focal lengths");
  PLANESLAM_CHECK(depth_scale > 0, "depth_scale must be > 0");
  col_factor_.resize(intrinsics.width);
  row_factor_.resize(intrinsics.height);
  for (int u = 0; u < intrinsics.width; ++u) {
    col_factor_[u] = static_cast<float>((u - intrinsics.cx) / intrinsics.fx);
  }
  for (int v = 0; v < intrinsics.height; ++v) {
    row_factor_[v] = static_cast<float>((v - intrinsics.cy) / intrinsics.fy);
  }
  const float nan = std::numeric_limits<float>::quiet_NaN();
  depth_lut_.assign(65536, nan);
  for (int raw = 1; raw < 65536; ++raw) {
    const double z = raw / depth_scale;
    if (z < min_depth || (max_depth > 0.0 && z > max_depth)) continue;
    depth_lut_[raw] = static_cast<float>(z);
  }
}

OrganizedCloud DepthProjector::Project(const Image16& depth, const std::string& source) const {
  OrganizedCloud cloud;
  Project(depth, &cloud, source);
  return cloud;
}

void DepthProjector::Project(const Image16& depth, OrganizedCloud* cloud,
                             const std::string& source) const {
  PLANESLAM_CHECK(depth.data.size() == static_cast<std::size_t>(depth.width) * depth.height,
                  "image buffer size mismatch");
  Project(depth.data.data(), depth.width, depth.height, cloud, source);
}

void DepthProjector::Project(const std::uint16_t* depth, int width, int height,
                             OrganizedCloud* cloud, const std::string& source, int factor) const {
  if (width != intrinsics_.width || height != intrinsics_.height) {
    throw IoError(source, "depth image is " + std::to_string(width) + "x" +
                              std::to_string(height) + " but the intrinsics are for " +
                              std::to_string(intrinsics_.width) + "x" +
                              std::to_string(intrinsics_.height));
  }
  PLANESLAM_CHECK(factor >= 1 && factor <= 16, "decimation factor " << factor);
  // Rounding up keeps the last row and column, as Decimate does.
  const int out_width = (width + factor - 1) / factor;
  const int out_height = (height + factor - 1) / factor;
  cloud->width = out_width;
  cloud->height = out_height;
  cloud->model = SensorModel::kPinhole;
  cloud->points.resize(static_cast<std::size_t>(out_width) * out_height);
  const float* lut = depth_lut_.data();
  const float* col_factor = col_factor_.data();
  Eigen::Vector3f* out = cloud->points.data();
  for (int v = 0; v < height; v += factor) {
    const float fy = row_factor_[v];
    const std::uint16_t* in = depth + static_cast<std::size_t>(v) * width;
    for (int u = 0; u < width; u += factor, ++out) {
      // NaN propagates through the products, so invalid pixels need no branch.
      const float z = lut[in[u]];
      *out = Eigen::Vector3f(col_factor[u] * z, fy * z, z);
    }
  }
}

OrganizedCloud DepthToCloud(const Image16& depth, const PinholeIntrinsics& intrinsics,
                            double depth_scale, double min_depth, double max_depth) {
  return DepthProjector(intrinsics, depth_scale, min_depth, max_depth).Project(depth);
}

OrganizedCloud ReadDepthCloud(const std::string& path, const PinholeIntrinsics& intrinsics,
                              double depth_scale, double min_depth, double max_depth) {
  return DepthProjector(intrinsics, depth_scale, min_depth, max_depth)
      .Project(ReadPng16(path), path);
}

}  // namespace planeslam::datasets
