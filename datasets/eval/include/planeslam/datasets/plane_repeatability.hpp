#pragma once
/// Plane repeatability on real data with ground-truth poses: the planes detected in frame i and in
/// frame j = i + k, the latter mapped into frame i with the ground-truth relative pose, should be the
/// same physical planes. The angle and offset differences of matched pairs measure how stably a
/// detector estimates planes under noise and viewpoint change; the fraction of large planes that
/// find a partner measures how stably it finds them.
#include <Eigen/Core>

#include <cstdint>
#include <vector>

#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::datasets {

/// A plane as the repeatability test sees it: Hessian form n.p = d in its frame.
struct RepeatabilityPlane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit
  double d = 0.0;                                     ///< [m]
  std::int64_t point_count = 0;                       ///< pixels
};

/// Gates and the "large plane" size of MatchPlanes.
struct RepeatabilityOptions {
  double max_angle_deg = 10.0;      ///< pairs with a larger normal angle are never matched [deg]
  double max_offset = 0.10;         ///< pairs with a larger offset difference never match [m]
  std::int64_t large_pixels = 5000; ///< planes of frame i with at least this many pixels [px]
                                    ///< count towards the matching fraction
};

/// One matched pair.
struct PlanePairMatch {
  int index_i = 0;          ///< into planes_i
  int index_j = 0;          ///< into planes_j
  double angle_deg = 0.0;   ///< angle between the normal lines [deg]
  double offset_m = 0.0;    ///< |d_i - d_j'| with both normals oriented alike [m]
  bool large = false;       ///< plane i has >= large_pixels
};

struct RepeatabilityResult {
  std::vector<PlanePairMatch> matches;
  int large_planes = 0;   ///< planes of frame i with >= large_pixels
  int large_matched = 0;  ///< of them matched
  /// large_matched / large_planes; 1 when there is no large plane (nothing to miss).
  double MatchingFraction() const {
    return large_planes ? double(large_matched) / large_planes : 1.0;
  }
};

/// Maps a plane from frame j into frame i given T_i_j (p_i = T_i_j p_j): n_i = R n_j,
/// d_i = d_j + n_i.t, then re-oriented so that d_i >= 0 (normal from the origin to the plane).
RepeatabilityPlane TransformPlane(const RepeatabilityPlane& plane_j, const Pose& T_i_j);

/// Matches planes of frame i with planes of frame j (mapped into frame i with T_i_j). A pair is a
/// candidate when its angle <= max_angle_deg and offset <= max_offset; candidates are taken
/// greedily by increasing cost angle/max_angle + offset/max_offset, each plane used once, so a plane
/// is paired with its nearest partner in angle and offset. Deterministic (ties by index).
RepeatabilityResult MatchPlanes(const std::vector<RepeatabilityPlane>& planes_i,
                                const std::vector<RepeatabilityPlane>& planes_j,
                                const Pose& T_i_j, const RepeatabilityOptions& options = {});

/// Pooled pairs over many frame pairs.
struct RepeatabilitySummary {
  std::vector<double> angles_deg;  ///< of all matched pairs with a large plane i
  std::vector<double> offsets_m;
  int large_planes = 0;
  int large_matched = 0;
  int frame_pairs = 0;

  void Add(const RepeatabilityResult& result);
  double MedianAngleDeg() const;   ///< -1 when empty
  double MedianOffset() const;     ///< -1 when empty
  double MatchingFraction() const {
    return large_planes ? double(large_matched) / large_planes : 1.0;
  }
};

}  // namespace planeslam::datasets
