#include "planeslam/datasets/closure_truth.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <optional>

namespace planeslam::datasets {
namespace {

/// Ground-truth pose nearest in time to `stamp` (stamps sorted or not), within `max_difference`.
std::optional<Pose> PoseAt(const Trajectory& trajectory, double stamp, double max_difference) {
  std::optional<Pose> best;
  double best_difference = max_difference;
  for (std::size_t i = 0; i < trajectory.size(); ++i) {
    const double difference = std::abs(trajectory.stamps[i] - stamp);
    if (difference <= best_difference) {
      best_difference = difference;
      best = trajectory.poses[i];
    }
  }
  return best;
}

}  // namespace

ClosureTruth JudgeClosure(const Trajectory& ground_truth, double stamp_from, double stamp_to,
                          const Pose& T_from_to, const ClosureTruthOptions& options) {
  ClosureTruth truth;
  const auto from = PoseAt(ground_truth, stamp_from, options.max_time_difference);
  const auto to = PoseAt(ground_truth, stamp_to, options.max_time_difference);
  if (!from || !to) return truth;
  truth.known = true;
  const Pose error = (from->inverse() * *to).inverse() * T_from_to;
  truth.translation_error = error.translation().norm();
  truth.rotation_error_deg = Eigen::AngleAxisd(error.rotation()).angle() * 180.0 / M_PI;
  truth.correct = truth.translation_error <= options.max_translation &&
                  truth.rotation_error_deg <= options.max_rotation_deg;
  return truth;
}

}  // namespace planeslam::datasets
