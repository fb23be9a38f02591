#pragma once
/// Depth images to organized clouds by the pinhole model: x = (u - cx) z / fx, y = (v - cy) z / fy,
/// z = value / depth_scale; a zero (or out-of-range) depth is an invalid pixel (NaN).
#include <cstdint>
#include <string>
#include <vector>

#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/organized_cloud.hpp"

namespace planeslam::datasets {

/// Back-projects depth images of one camera. Construction precomputes per-column and per-row
/// factors and a 65536-entry depth table, so Project() is a multiply per coordinate.
class DepthProjector {
 public:
  /// `depth_scale`: image units per metre. `min_depth`/`max_depth` [m]: depths outside become NaN
  /// (max_depth 0 = no upper limit). fy may be negative (flipped y axis, ICL-NUIM).
  DepthProjector(const PinholeIntrinsics& intrinsics, double depth_scale, double min_depth = 0.0,
                 double max_depth = 0.0);

  /// The organized cloud (metres, camera frame). Throws IoError naming `source` when the image
  /// size differs from the intrinsics.
  OrganizedCloud Project(const Image16& depth, const std::string& source = "depth image") const;
  /// Same, into an existing cloud (reuses its storage).
  void Project(const Image16& depth, OrganizedCloud* cloud,
               const std::string& source = "depth image") const;
  /// Same, from a row-major width x height buffer of raw depth values read in place. With
  /// `factor` > 1 only every factor-th row and column: the cloud Decimate(cloud, factor) would
  /// give, point for point, without the full-resolution one (1 <= factor <= 16).
  void Project(const std::uint16_t* depth, int width, int height, OrganizedCloud* cloud,
               const std::string& source = "depth image", int factor = 1) const;

  const PinholeIntrinsics& intrinsics() const { return intrinsics_; }

 private:
  PinholeIntrinsics intrinsics_;
  std::vector<float> col_factor_;  ///< (u - cx) / fx
  std::vector<float> row_factor_;  ///< (v - cy) / fy
  std::vector<float> depth_lut_;   ///< depth [m] per raw value, NaN when invalid
};

/// One-shot back-projection (builds a DepthProjector).
OrganizedCloud DepthToCloud(const Image16& depth, const PinholeIntrinsics& intrinsics,
                            double depth_scale, double min_depth = 0.0, double max_depth = 0.0);

/// Reads a 16-bit depth PNG and back-projects it. Throws IoError naming the file.
OrganizedCloud ReadDepthCloud(const std::string& path, const PinholeIntrinsics& intrinsics,
                              double depth_scale, double min_depth = 0.0, double max_depth = 0.0);

}  // namespace planeslam::datasets
