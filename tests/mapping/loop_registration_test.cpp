// The loop search's two registrations on a family of street corners (ground, a flat roof or sill
// above it, two facades, two reveals across the street) whose trajectory estimate has drifted
// by the roof's height: the anchored registration pairs the ground with the roof and confirms
// the drift; the unanchored one finds the true relative pose and rivals it. Without the drift
// the two agree and nothing is refused.
#include "planeslam/mapping/loop_registration.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "planeslam/registration/geometry.hpp"

namespace planeslam::mapping {
namespace {

constexpr double kNormalSigma = 0.002;  // [rad] each keyframe's detection noise
constexpr double kOffsetSigma = 0.005;  // [m]
constexpr double kChi2 = 22.46;         // slam.loop_consistency_chi2

struct WorldPlane {
  Eigen::Vector3d normal;
  double d;
  Eigen::Vector3d centroid;  // a point of the plane where the sensor sees it
  std::int64_t points;
};

Pose YawPose(double x, double y, double z, double yaw) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

/// The plane as detected from a sensor at T_world_sensor, with noise its covariance states.
detection::Plane Detect(const WorldPlane& w, const Pose& T_world_sensor, std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  const Pose T_sensor_world = T_world_sensor.inverse();
  const registration::PlaneParams q = registration::TransformPlane(T_sensor_world, w.normal, w.d);
  detection::Plane p;
  const double gx = g(rng), gy = g(rng), gz = g(rng), gd = g(rng);
  const Eigen::Vector3d tilt = kNormalSigma * Eigen::Vector3d(gx, gy, gz);
  p.normal = (q.normal + tilt - q.normal.dot(tilt) * q.normal).normalized();
  p.d = q.d + kOffsetSigma * gd;
  if (p.d < 0) {
    p.normal = -p.normal;
    p.d = -p.d;
  }
  p.centroid = T_sensor_world * w.centroid;
  p.point_count = w.points;
  p.covariance.topLeftCorner<3, 3>() =
      kNormalSigma * kNormalSigma * (Eigen::Matrix3d::Identity() - p.normal * p.normal.transpose());
  p.covariance(3, 3) = kOffsetSigma * kOffsetSigma;
  return p;
}

struct Corner {
  std::vector<detection::Plane> old_planes, current_planes;
  Pose T_old_current;  // the truth
  double roof_height = 0.0;
};

Corner MakeCorner(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double h = 0.8 + 0.4 * u(rng);     // roof or sill above the ground [m]
  const double left = 4.0 + 4.0 * u(rng);  // facades
  const double right = 4.0 + 4.0 * u(rng);
  const double ahead = 4.0 + 4.0 * u(rng);  // reveals
  const double behind = 4.0 + 4.0 * u(rng);
  const std::vector<WorldPlane> world = {
      {Eigen::Vector3d::UnitZ(), 0.0, {5.0, 0.0, 0.0}, 20000},
      {Eigen::Vector3d::UnitZ(), h, {3.0, -2.0, h}, 1500},
      {Eigen::Vector3d::UnitY(), left, {2.0, left, 3.0}, 8000},
      {-Eigen::Vector3d::UnitY(), right, {2.0, -right, 3.0}, 8000},
      {Eigen::Vector3d::UnitX(), ahead, {ahead, left - 0.2, 1.5}, 800},
      {-Eigen::Vector3d::UnitX(), behind, {-behind, 0.2 - right, 1.5}, 800}};
  const double sensor_height = 1.73;
  const double yaw = 0.6 * u(rng) - 0.3;
  const double dx = 2.0 * u(rng) - 1.0, dy = 0.6 * u(rng) - 0.3, dyaw = 0.1 * u(rng) - 0.05;
  const Pose T_world_old = YawPose(0.0, 0.0, sensor_height, yaw);
  const Pose T_world_current = YawPose(dx, dy, sensor_height, yaw + dyaw);
  Corner c;
  for (const WorldPlane& w : world) c.old_planes.push_back(Detect(w, T_world_old, rng));
  for (const WorldPlane& w : world) c.current_planes.push_back(Detect(w, T_world_current, rng));
  c.T_old_current = T_world_old.inverse() * T_world_current;
  c.roof_height = h;
  return c;
}

/// The truth with a few centimetres and milliradians of estimation noise, lowered by `drop`.
Pose Estimate(const Corner& c, double drop, std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Pose T = c.T_old_current;
  const double x = g(rng), y = g(rng), z = g(rng), yaw = g(rng);
  T.translation() += 0.02 * Eigen::Vector3d(x, y, z) - drop * Eigen::Vector3d::UnitZ();
  T.linear() = Eigen::AngleAxisd(0.005 * yaw, Eigen::Vector3d::UnitZ()) * T.linear();
  return T;
}

double TranslationError(const registration::RegistrationResult& r, const Pose& truth) {
  return (r.T_prev_curr.translation() - truth.translation()).norm();
}

TEST(LoopRegistration, UnanchoredSolutionRivalsAnAnchorOnTheDrift) {
  std::mt19937 rng(2027);
  const LoopRegistrationConfig config;
  const int draws = 50;
  int aliased = 0, rivalled = 0, unanchored_true = 0;
  for (int k = 0; k < draws; ++k) {
    SCOPED_TRACE("draw " + std::to_string(k));
    const Corner c = MakeCorner(rng);
    const Pose estimate = Estimate(c, c.roof_height, rng);
    const auto anchored =
        AnchoredLoopRegistration(c.old_planes, c.current_planes, estimate, config);
    const auto unanchored =
        UnanchoredLoopRegistration(c.old_planes, c.current_planes, estimate, config);
    ASSERT_TRUE(anchored.converged);
    const bool wrong = TranslationError(anchored, c.T_old_current) > 0.1;
    aliased += wrong ? 1 : 0;
    unanchored_true += TranslationError(unanchored, c.T_old_current) < 0.02 ? 1 : 0;
    const bool rival = UnanchoredRivalsAnchored(anchored, unanchored, kChi2);
    rivalled += rival ? 1 : 0;
    // Budget 0: an anchored solution off the truth is never left unrivalled.
    EXPECT_TRUE(!wrong || rival);
  }
  // The hazard is real: the drift makes the anchored search confirm it in (nearly) every draw,
  // while the unanchored one finds the truth.
  EXPECT_GE(aliased, draws - 2);
  EXPECT_GE(unanchored_true, draws - 2);
  EXPECT_GE(rivalled, aliased);
}

TEST(LoopRegistration, WithoutDriftTheTwoAgree) {
  std::mt19937 rng(2028);
  const LoopRegistrationConfig config;
  const int draws = 50;
  int rivalled = 0;
  for (int k = 0; k < draws; ++k) {
    SCOPED_TRACE("draw " + std::to_string(k));
    const Corner c = MakeCorner(rng);
    const Pose estimate = Estimate(c, 0.0, rng);
    const auto anchored =
        AnchoredLoopRegistration(c.old_planes, c.current_planes, estimate, config);
    const auto unanchored =
        UnanchoredLoopRegistration(c.old_planes, c.current_planes, estimate, config);
    ASSERT_TRUE(anchored.converged);
    EXPECT_LT(TranslationError(anchored, c.T_old_current), 0.02);
    rivalled += UnanchoredRivalsAnchored(anchored, unanchored, kChi2) ? 1 : 0;
  }
  // The chi-square threshold is the 99.9 % quantile: at most one refusal in 50 by chance.
  EXPECT_LE(rivalled, 1);
}

}  // namespace
}  // namespace planeslam::mapping
