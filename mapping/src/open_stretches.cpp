#include "planeslam/mapping/open_stretches.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <queue>
#include <utility>

#include "planeslam/registration/theil_sen.hpp"

namespace planeslam::mapping {
namespace {

/// Poses a measured end needs to read its motion from.
constexpr std::size_t kMinEndPoses = 3;

bool Measured(const TrackedPose& pose) { return pose.open.cols() == 0; }

/// The projector onto the translation directions among `open` (its columns are either
/// translations or rotations).
Eigen::Matrix3d TranslationProjector(const Eigen::Matrix<double, 6, Eigen::Dynamic>& open) {
  Eigen::Matrix3Xd translations(3, open.cols());
  int count = 0;
  for (Eigen::Index k = 0; k < open.cols(); ++k) {
    if (open.col(k).head<3>().squaredNorm() > 0.5)
      translations.col(count++) = open.col(k).head<3>();
  }
  if (count == 0) return Eigen::Matrix3d::Zero();
  const Eigen::JacobiSVD<Eigen::Matrix3Xd> svd(translations.leftCols(count), Eigen::ComputeThinU);
  const int rank = static_cast<int>((svd.singularValues().array() > 0.5).count());
  const Eigen::Matrix3Xd U = svd.matrixU().leftCols(rank);
  return U * U.transpose();
}

/// A measured end of a stretch: the Theil-Sen line through the positions of its window at the
/// window's middle, where the slope of a line through a curving motion is its velocity.
struct EndState {
  double time = 0.0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
};

/// The cubic Hermite curve between the states `a` and `b` at time `t`.
Eigen::Vector3d HermiteAt(const EndState& a, const EndState& b, double t) {
  const double T = b.time - a.time;
  const double u = (t - a.time) / T;
  const double h00 = (2 * u - 3) * u * u + 1, h10 = ((u - 2) * u + 1) * u;
  const double h01 = (3 - 2 * u) * u * u, h11 = (u - 1) * u * u;
  return h00 * a.position + h10 * T * a.velocity + h01 * b.position + h11 * T * b.velocity;
}

/// The measured end at pose `i`: the line through it and the measured poses within `span` of
/// it on the side `step` (-1 before, +1 after), robust to one frame's error. False with fewer
/// than three poses.
bool MeasuredEnd(const std::vector<TrackedPose>& poses, std::size_t i, int step, double span,
                 EndState* end) {
  std::vector<double> t;
  std::vector<Eigen::Vector3d> position;
  for (std::ptrdiff_t k = static_cast<std::ptrdiff_t>(i);
       k >= 0 && k < static_cast<std::ptrdiff_t>(poses.size()); k += step) {
    const TrackedPose& pose = poses[static_cast<std::size_t>(k)];
    if (!Measured(pose) || std::abs(pose.timestamp - poses[i].timestamp) > span) break;
    t.push_back(pose.timestamp);
    position.push_back(pose.T_world.translation());
  }
  if (t.size() < kMinEndPoses) return false;
  end->time = 0.5 * (*std::min_element(t.begin(), t.end()) + *std::max_element(t.begin(), t.end()));
  const registration::TheilSenLine line = registration::FitTheilSenLine(t, position, end->time);
  end->position = line.value;
  end->velocity = line.slope;
  return line.valid;
}

/// Re-interpolates the positions of poses first..last (open) between the measured poses
/// before first and after last.
void SmoothStretch(std::vector<TrackedPose>* poses, std::size_t first, std::size_t last,
                   double span) {
  std::vector<TrackedPose>& p = *poses;
  EndState a, b;
  if (!MeasuredEnd(p, first - 1, -1, span, &a) || !MeasuredEnd(p, last + 1, +1, span, &b)) return;
  if (!(b.time > a.time)) return;
  for (std::size_t i = first; i <= last; ++i) {
    const Eigen::Vector3d position = HermiteAt(a, b, p[i].timestamp);
    const Eigen::Vector3d translation = p[i].T_world.translation();
    p[i].T_world.translation() += TranslationProjector(p[i].open) * (position - translation);
  }
}

/// Poses on each side of an outlier the motion is read from, and the half width of the window of
/// poses whose deviations set its scale.
constexpr std::size_t kSidePoses = 5;
constexpr std::size_t kScaleHalfWidth = 50;
/// An outlier is off the motion by this many times the median deviation around it ...
constexpr double kOutlierFactor = 10.0;
/// ... and by more than this [m]: below it, a pose is within any sensor's resolution.
constexpr double kOutlierFloor = 0.001;

/// Where the poses on both sides of `i` put it. Each side's Theil-Sen line gives the velocity at
/// its window's mean time, and its position there up to a q / 2 for an acceleration a (q the
/// median squared offset of the window's times from their mean: the line's value is the median
/// of the positions moved along it), a read from the change of velocity between the two; the cubic
/// Hermite curve between the two corrected states is exact on any motion of constant
/// acceleration (a car in a turn at 10 Hz: a line alone would be off by a quarter metre).
Eigen::Vector3d BothSidesPrediction(const std::vector<TrackedPose>& poses, std::size_t i) {
  EndState side[2];
  double spread[2];
  for (const int s : {0, 1}) {
    const std::size_t first = s == 0 ? i - kSidePoses : i + 1;
    std::vector<double> t(kSidePoses);
    std::vector<Eigen::Vector3d> position(kSidePoses);
    double mean = 0.0;
    for (std::size_t k = 0; k < kSidePoses; ++k) {
      t[k] = poses[first + k].timestamp;
      position[k] = poses[first + k].T_world.translation();
      mean += t[k] / kSidePoses;
    }
    std::vector<double> squared_offsets;
    for (const double tk : t) squared_offsets.push_back((tk - mean) * (tk - mean));
    spread[s] = registration::Median(&squared_offsets);
    const registration::TheilSenLine line = registration::FitTheilSenLine(t, position, mean);
    side[s] = {mean, line.value, line.slope};
  }
  const double T = side[1].time - side[0].time;
  if (!(T > 0)) return poses[i].T_world.translation();
  const Eigen::Vector3d acceleration = (side[1].velocity - side[0].velocity) / T;
  for (const int s : {0, 1}) side[s].position -= 0.5 * spread[s] * acceleration;
  return HermiteAt(side[0], side[1], poses[i].timestamp);
}

}  // namespace

std::vector<std::size_t> ReinterpolateOutliers(std::vector<TrackedPose>* poses) {
  std::vector<TrackedPose>& p = *poses;
  std::vector<std::size_t> outliers;
  if (p.size() < 2 * kSidePoses + 1) return outliers;
  const std::size_t begin = kSidePoses, end = p.size() - kSidePoses;
  std::vector<double> deviation(p.size(), 0.0);
  for (std::size_t i = begin; i < end; ++i) {
    deviation[i] = (p[i].T_world.translation() - BothSidesPrediction(p, i)).norm();
  }
  // How far each pose may be off: the scale of the deviations around it, as tracked.
  std::vector<double> limit(p.size(), 0.0);
  for (std::size_t i = begin; i < end; ++i) {
    const std::size_t lo = std::max(begin, i - std::min(i, kScaleHalfWidth));
    const std::size_t hi = std::min(end, i + kScaleHalfWidth + 1);
    std::vector<double> around(deviation.begin() + lo, deviation.begin() + hi);
    limit[i] = std::max(kOutlierFloor, kOutlierFactor * registration::UpperMedian(&around));
  }
  // The worst outlier first: two neighbouring outliers would otherwise bend the lines of the
  // poses next to them; once one is replaced, the deviations that read it are recomputed. The
  // frames between keyframes first, then the keyframes: the frames around a keyframe were tracked
  // against it, and where they and it disagree they are the likelier culprits.
  std::vector<bool> replaced(p.size(), false);
  for (const bool keyframes : {false, true}) {
    std::priority_queue<std::pair<double, std::size_t>> queue;
    const auto consider = [&](std::size_t i) {
      if (p[i].keyframe == keyframes && !replaced[i] && deviation[i] > limit[i]) {
        queue.emplace(deviation[i] / limit[i], i);
      }
    };
    for (std::size_t i = begin; i < end; ++i) consider(i);
    while (!queue.empty()) {
      const auto [ratio, worst] = queue.top();
      queue.pop();
      if (replaced[worst] || ratio != deviation[worst] / limit[worst]) continue;  // stale
      p[worst].T_world.translation() = BothSidesPrediction(p, worst);
      replaced[worst] = true;
      outliers.push_back(worst);
      const std::size_t lo = std::max(begin, worst - kSidePoses);
      for (std::size_t i = lo; i < std::min(end, worst + kSidePoses + 1); ++i) {
        if (replaced[i]) continue;
        deviation[i] = (p[i].T_world.translation() - BothSidesPrediction(p, i)).norm();
        consider(i);
      }
    }
  }
  // An outlier replaced while its neighbour was still out was read through it: read again.
  for (int round = 0; round < 2; ++round) {
    for (const std::size_t i : outliers) p[i].T_world.translation() = BothSidesPrediction(p, i);
  }
  std::sort(outliers.begin(), outliers.end());
  return outliers;
}

void SmoothOpenStretches(std::vector<TrackedPose>* poses, double velocity_span) {
  std::vector<TrackedPose>& p = *poses;
  const std::size_t n = p.size();
  std::size_t i = 0;
  while (i < n) {
    if (Measured(p[i])) {
      ++i;
      continue;
    }
    // The stretch runs on through measured runs too short to read a motion from (a frame or
    // two that saw more): their own poses stay, the curve spans the whole.
    std::size_t last = i;
    for (;;) {
      while (last + 1 < n && !Measured(p[last + 1])) ++last;
      std::size_t next = last + 1;
      while (next < n && Measured(p[next]) && next - last <= kMinEndPoses) ++next;
      if (next >= n || Measured(p[next]) || next - last > kMinEndPoses) break;
      last = next;
    }
    if (i > 0 && last + 1 < n) SmoothStretch(poses, i, last, velocity_span);
    i = last + 1;
  }
}

}  // namespace planeslam::mapping
