#pragma once
// Machinery shared by GBRG and PBRG after growth: merging adjacent coplanar regions and turning
// region sums + a region-index image into a Segmentation (planes sorted by size, ids 1..N).
#include <cstdint>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/detection/detection_config.hpp"
#include "planeslam/detection/fast_moments.hpp"
#include "planeslam/detection/plane.hpp"

namespace planeslam::detection::internal {

/// Depth used by the noise model: z for a pinhole camera, range for a spherical scanner.
inline float PointDepth(const Eigen::Vector3f& p, bool spherical) {
  return spherical ? p.norm() : p.z();
}

/// Merges regions that describe one plane: adjacent ones (4-connected in the label image) and,
/// with params.merge_disjoint, also ones that do not touch; the test is normals within
/// merge_angle_deg and MSE of the union below epsilon (of the union's noise). Pairs are tried in
/// order of increasing union MSE (deterministic; ties by region indices); a merged region keeps
/// the smaller index. `labels` holds region indices (-1 none) and is rewritten; merged-away
/// regions get k = 0 in `regions`.
void MergeCoplanarRegions(std::vector<std::int32_t>& labels, int width, int height,
                          std::vector<MomentSums>& regions, const DetectionParams& params);

/// Builds the output: one Plane per region with k >= 3 (sorted by point count descending, then by
/// region index), labels rewritten to plane ids (>= 1) or -1, covariance from the region noise.
/// The plane is the eigen fit of the region's moments, or with params.ray_fit the inverse-depth
/// fit over its pixels in `cloud` (the eigen fit where that is degenerate).
/// The ray fit also drops the pixels it finds far off the plane from `region_labels` and
/// `regions` (see FitAlongRays in the source).
void FinalizeSegmentation(const datasets::OrganizedCloud& cloud,
                          std::vector<std::int32_t>& region_labels,
                          std::vector<MomentSums>& regions, const DetectionParams& params,
                          Segmentation& out);

}  // namespace planeslam::detection::internal
