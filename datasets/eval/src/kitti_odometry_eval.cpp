#include "planeslam/datasets/kitti_odometry_eval.hpp"

#include <algorithm>
#include <cmath>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {

namespace {
constexpr double kPi = 3.14159265358979323846;
}  // namespace

double KittiOdometryResult::RotationDegPer100m() const { return r_err * 180.0 / kPi * 100.0; }

std::vector<double> KittiTrajectoryDistances(const std::vector<Pose>& poses) {
  std::vector<double> dist;
  dist.reserve(poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i) {
    dist.push_back(i == 0 ? 0.0
                          : dist.back() +
                                (poses[i].translation() - poses[i - 1].translation()).norm());
  }
  return dist;
}

long KittiLastFrameFromSegmentLength(const std::vector<double>& dist, std::size_t first,
                                     double length) {
  for (std::size_t i = first; i < dist.size(); ++i) {
    if (dist[i] > dist[first] + length) return static_cast<long>(i);
  }
  return -1;
}

KittiOdometryResult EvaluateKittiOdometry(const std::vector<Pose>& gt,
                                          const std::vector<Pose>& est,
                                          const KittiOdometryOptions& options) {
  PLANESLAM_CHECK(gt.size() == est.size(),
                  "KITTI segment errors pair poses by index: " << gt.size() << " vs "
                                                               << est.size());
  PLANESLAM_CHECK(options.step > 0, "step must be positive");
  KittiOdometryResult result;
  const std::vector<double> dist = KittiTrajectoryDistances(gt);
  result.path_length = dist.empty() ? 0.0 : dist.back();
  for (std::size_t first = 0; first < gt.size(); first += options.step) {
    for (double length : options.lengths) {
      const long last = KittiLastFrameFromSegmentLength(dist, first, length);
      if (last < 0) continue;
      const std::size_t l = static_cast<std::size_t>(last);
      const Pose delta_gt = gt[first].inverse() * gt[l];
      const Pose delta_est = est[first].inverse() * est[l];
      const Pose error = delta_est.inverse() * delta_gt;
      const Eigen::Matrix3d R = error.linear();
      const double cos_angle = std::clamp(0.5 * (R.trace() - 1.0), -1.0, 1.0);
      KittiSegmentError e;
      e.first_frame = first;
      e.last_frame = l;
      e.length = length;
      e.t_err = error.translation().norm() / length;
      e.r_err = std::acos(cos_angle) / length;
      result.segments.push_back(e);
    }
  }
  if (result.segments.empty()) {
    double shortest = 0.0;
    if (!options.lengths.empty()) {
      shortest = *std::min_element(options.lengths.begin(), options.lengths.end());
    }
    result.message = "no segment: the ground truth's path (" +
                     std::to_string(static_cast<int>(std::floor(result.path_length))) +
                     " m) is not longer than the shortest segment length (" +
                     std::to_string(static_cast<int>(shortest)) + " m)";
    return result;
  }
  for (const KittiSegmentError& e : result.segments) {
    result.t_err += e.t_err;
    result.r_err += e.r_err;
  }
  result.t_err /= static_cast<double>(result.segments.size());
  result.r_err /= static_cast<double>(result.segments.size());
  for (double length : options.lengths) {
    KittiLengthErrors le;
    le.length = length;
    for (const KittiSegmentError& e : result.segments) {
      if (e.length != length) continue;
      ++le.segments;
      le.t_err += e.t_err;
      le.r_err += e.r_err;
    }
    if (le.segments == 0) continue;
    le.t_err /= static_cast<double>(le.segments);
    le.r_err /= static_cast<double>(le.segments);
    result.per_length.push_back(le);
  }
  result.ok = true;
  return result;
}

}  // namespace planeslam::datasets
