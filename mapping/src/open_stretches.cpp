#include "planeslam/mapping/open_stretches.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstddef>

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
  const double T = b.time - a.time;
  if (!(T > 0)) return;
  for (std::size_t i = first; i <= last; ++i) {
    const double u = (p[i].timestamp - a.time) / T;
    const double h00 = (2 * u - 3) * u * u + 1, h10 = ((u - 2) * u + 1) * u;
    const double h01 = (3 - 2 * u) * u * u, h11 = (u - 1) * u * u;
    const Eigen::Vector3d position =
        h00 * a.position + h10 * T * a.velocity + h01 * b.position + h11 * T * b.velocity;
    const Eigen::Vector3d translation = p[i].T_world.translation();
    p[i].T_world.translation() += TranslationProjector(p[i].open) * (position - translation);
  }
}

}  // namespace

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
