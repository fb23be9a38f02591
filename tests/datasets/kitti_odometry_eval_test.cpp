// KITTI odometry segment errors against figures computed independently: closed forms for
// hand-made trajectories, and a single-precision re-implementation written from the devkit's
// evaluate_odometry.cpp (trajectoryDistances, lastFrameFromSegmentLength, calcSequenceErrors with
// step_size 10, rotationError from the trace, translationError as the norm) on random ones.
#include "planeslam/datasets/kitti_odometry_eval.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace planeslam::datasets {
namespace {

constexpr double kPi = 3.14159265358979323846;

Pose At(double x, double y, double yaw) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, 0.0);
  return T;
}

/// Ground truth: 1001 poses 1 m apart on a line (1000 m). dist[i] = i, so a segment of length L
/// from frame f ends at l = f + L + 1 and exists when f + L + 1 <= 1000.
std::vector<Pose> Line() {
  std::vector<Pose> gt;
  for (int i = 0; i <= 1000; ++i) gt.push_back(At(i, 0.0, 0.0));
  return gt;
}

TEST(KittiOdometryEval, ScaleDriftHasClosedForm) {
  // The estimate moves (1 + eps) m a frame: every segment's error is eps (L + 1) m, divided by L.
  const double eps = 0.012;
  const std::vector<Pose> gt = Line();
  std::vector<Pose> est;
  for (int i = 0; i <= 1000; ++i) est.push_back(At((1 + eps) * i, 0.0, 0.0));
  const KittiOdometryResult r = EvaluateKittiOdometry(gt, est);
  ASSERT_TRUE(r.ok);
  double sum = 0.0;
  std::size_t count = 0;
  for (int L = 100; L <= 800; L += 100) {
    const int n = (1000 - L - 1) / 10 + 1;  // first frames 0, 10, ..., <= 999 - L
    sum += n * eps * (L + 1.0) / L;
    count += static_cast<std::size_t>(n);
    bool found = false;
    for (const KittiLengthErrors& le : r.per_length) {
      if (le.length != L) continue;
      found = true;
      EXPECT_EQ(le.segments, static_cast<std::size_t>(n));
      EXPECT_NEAR(le.t_err, eps * (L + 1.0) / L, 1e-12);
      EXPECT_NEAR(le.r_err, 0.0, 1e-12);
    }
    EXPECT_TRUE(found) << L;
  }
  EXPECT_EQ(r.segments.size(), count);
  EXPECT_NEAR(r.t_err, sum / count, 1e-12);
  EXPECT_NEAR(r.TranslationPercent(), 100.0 * sum / count, 1e-10);
  EXPECT_NEAR(r.path_length, 1000.0, 1e-9);
}

TEST(KittiOdometryEval, HeadingDriftHasClosedForm) {
  // Same positions, heading drifting by w a frame. Segment (f, l): the estimate's relative
  // rotation is Rz(w (l - f)) and its relative translation Rz(-w f) D, D = (l - f, 0, 0); so
  // E = [Rz(-w (l - f)), Rz(-w (l - f)) (D - Rz(-w f) D)]: angle w (l - f), translation
  // |D - Rz(-w f) D| = 2 |D| sin(w f / 2).
  const double w = 2e-5;
  const std::vector<Pose> gt = Line();
  std::vector<Pose> est;
  for (int i = 0; i <= 1000; ++i) est.push_back(At(i, 0.0, w * i));
  const KittiOdometryResult r = EvaluateKittiOdometry(gt, est);
  ASSERT_TRUE(r.ok);
  double t_sum = 0.0, r_sum = 0.0;
  for (const KittiSegmentError& e : r.segments) {
    const double span = static_cast<double>(e.last_frame - e.first_frame);
    EXPECT_EQ(e.last_frame, e.first_frame + static_cast<std::size_t>(e.length) + 1);
    EXPECT_NEAR(e.r_err, w * span / e.length, 1e-10);
    EXPECT_NEAR(e.t_err, 2.0 * span * std::sin(0.5 * w * e.first_frame) / e.length, 1e-10);
    t_sum += 2.0 * span * std::sin(0.5 * w * e.first_frame) / e.length;
    r_sum += w * span / e.length;
  }
  EXPECT_NEAR(r.t_err, t_sum / r.segments.size(), 1e-12);
  EXPECT_NEAR(r.RotationDegPer100m(), r_sum / r.segments.size() * 180.0 / kPi * 100.0, 1e-8);
}

// ---- Single-precision re-implementation of the devkit's evaluation (row-major 4x4 floats).
using M4 = Eigen::Matrix<float, 4, 4, Eigen::RowMajor>;

M4 Inverse(const M4& m) { return m.inverse(); }  // the devkit inverts by Gauss-Jordan in float

struct DevkitResult {
  float t_err = 0, r_err = 0;
  int count = 0;
};

DevkitResult Devkit(const std::vector<M4>& poses_gt, const std::vector<M4>& poses_result) {
  const float lengths[] = {100, 200, 300, 400, 500, 600, 700, 800};
  std::vector<float> dist = {0};
  for (std::size_t i = 1; i < poses_gt.size(); ++i) {
    const float dx = poses_gt[i - 1](0, 3) - poses_gt[i](0, 3);
    const float dy = poses_gt[i - 1](1, 3) - poses_gt[i](1, 3);
    const float dz = poses_gt[i - 1](2, 3) - poses_gt[i](2, 3);
    dist.push_back(dist[i - 1] + std::sqrt(dx * dx + dy * dy + dz * dz));
  }
  DevkitResult out;
  for (std::size_t first = 0; first < poses_gt.size(); first += 10) {
    for (float len : lengths) {
      int last = -1;
      for (std::size_t i = first; i < dist.size(); ++i) {
        if (dist[i] > dist[first] + len) {
          last = static_cast<int>(i);
          break;
        }
      }
      if (last == -1) continue;
      const M4 delta_gt = Inverse(poses_gt[first]) * poses_gt[last];
      const M4 delta_result = Inverse(poses_result[first]) * poses_result[last];
      const M4 e = Inverse(delta_result) * delta_gt;
      const float d = 0.5f * (e(0, 0) + e(1, 1) + e(2, 2) - 1.0f);
      const float r = std::acos(std::max(std::min(d, 1.0f), -1.0f));
      const float t = std::sqrt(e(0, 3) * e(0, 3) + e(1, 3) * e(1, 3) + e(2, 3) * e(2, 3));
      out.r_err += r / len;
      out.t_err += t / len;
      ++out.count;
    }
  }
  out.t_err /= out.count;
  out.r_err /= out.count;
  return out;
}

TEST(KittiOdometryEval, MatchesDevkitReimplementationOnRandomTrajectories) {
  std::mt19937_64 rng(33);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  for (int draw = 0; draw < 5; ++draw) {
    // A car-like path: 0.6..1.2 m a frame, smoothly turning, gentle slopes; the estimate adds a
    // random walk in rotation and translation.
    const int n = 900 + static_cast<int>(400 * uni(rng));
    std::vector<Pose> gt, est;
    Pose T = Pose::Identity(), E = Pose::Identity();
    double yaw_rate = 0.0;
    for (int i = 0; i < n; ++i) {
      gt.push_back(T);
      est.push_back(E);
      yaw_rate = 0.98 * yaw_rate + 0.004 * noise(rng);
      Pose step = Pose::Identity();
      step.linear() = (Eigen::AngleAxisd(yaw_rate, Eigen::Vector3d::UnitZ()) *
                       Eigen::AngleAxisd(0.002 * noise(rng), Eigen::Vector3d::UnitY()))
                          .toRotationMatrix();
      step.translation() = Eigen::Vector3d(0.6 + 0.6 * uni(rng), 0.02 * noise(rng), 0.01 * noise(rng));
      Pose drift = Pose::Identity();
      drift.linear() = Eigen::AngleAxisd(0.0005 * noise(rng), Eigen::Vector3d(noise(rng), noise(rng), noise(rng)).normalized()).toRotationMatrix();
      drift.translation() = 0.01 * Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
      T = T * step;
      E = E * step * drift;
    }
    std::vector<M4> gt_f, est_f;
    for (int i = 0; i < n; ++i) {
      gt_f.push_back(gt[i].matrix().cast<float>());
      est_f.push_back(est[i].matrix().cast<float>());
    }
    const DevkitResult devkit = Devkit(gt_f, est_f);
    const KittiOdometryResult r = EvaluateKittiOdometry(gt, est);
    ASSERT_TRUE(r.ok);
    EXPECT_EQ(static_cast<int>(r.segments.size()), devkit.count);
    EXPECT_NEAR(r.t_err, devkit.t_err, 1e-4 * devkit.t_err) << draw;
    EXPECT_NEAR(r.r_err, devkit.r_err, 2e-3 * devkit.r_err) << draw;
    EXPECT_GT(r.t_err, 1e-4);
  }
}

TEST(KittiOdometryEval, ShortPathHasNoSegment) {
  std::vector<Pose> gt;
  for (int i = 0; i < 60; ++i) gt.push_back(At(0.7 * i, 0.0, 0.0));
  const KittiOdometryResult r = EvaluateKittiOdometry(gt, gt);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("41 m"), std::string::npos) << r.message;
  EXPECT_NE(r.message.find("100 m"), std::string::npos) << r.message;
  KittiOdometryOptions options;
  options.lengths = {10, 20};
  const KittiOdometryResult shorter = EvaluateKittiOdometry(gt, gt, options);
  ASSERT_TRUE(shorter.ok);
  EXPECT_EQ(shorter.t_err, 0.0);
  EXPECT_EQ(KittiLastFrameFromSegmentLength(KittiTrajectoryDistances(gt), 0, 7.0), 11);
}

}  // namespace
}  // namespace planeslam::datasets
