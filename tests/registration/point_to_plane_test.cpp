// Point-to-plane fallback along the directions the planes leave open (a corridor's axis).
#include "planeslam/registration/point_to_plane.hpp"

#include <gtest/gtest.h>

#include <random>

#include "registration/corridor_scene.hpp"

namespace planeslam::registration {
namespace {

using test::CorridorPlanesInCamera;
using test::LookAlongX;
using test::MakeCorridor;
using test::RayCast;
using test::SmallCamera;

struct CorridorCase {
  Pose T_world_prev, T_world_curr, T_prev_curr;
  datasets::OrganizedCloud prev_cloud, curr_cloud;
  std::vector<detection::Plane> prev_planes, curr_planes;
  MotionPrior prior;
  Eigen::Vector3d axis_prev;  ///< corridor axis in the previous camera frame
};

/// The camera moves 0.2 m down the corridor (with a little sideways motion and rotation); the
/// prior is the true motion with its along-axis part off by `prior_error` [m].
CorridorCase MakeCase(bool with_features, double prior_error, std::mt19937& rng) {
  CorridorCase c;
  const test::CorridorScene scene = MakeCorridor(with_features);
  c.T_world_prev = Pose::Identity();
  c.T_world_prev.linear() = LookAlongX() * ExpSO3(Eigen::Vector3d(0.02, -0.03, 0.01));
  c.T_world_prev.translation() << 0.0, 0.1, 0.05;
  c.T_prev_curr = Pose::Identity();
  c.T_prev_curr.linear() = ExpSO3(Eigen::Vector3d(-0.01, 0.02, 0.015));
  c.T_prev_curr.translation() << 0.03, -0.02, 0.2;
  c.T_world_curr = c.T_world_prev * c.T_prev_curr;
  const datasets::PinholeIntrinsics k = SmallCamera();
  c.prev_cloud = RayCast(scene, k, c.T_world_prev, 0.001, rng);
  c.curr_cloud = RayCast(scene, k, c.T_world_curr, 0.001, rng);
  c.prev_planes = CorridorPlanesInCamera(scene, c.T_world_prev);
  c.curr_planes = CorridorPlanesInCamera(scene, c.T_world_curr);
  c.axis_prev = c.T_world_prev.linear().transpose() * Eigen::Vector3d::UnitX();
  c.prior.T_prev_curr = c.T_prev_curr;
  c.prior.T_prev_curr.translation() += prior_error * c.axis_prev;
  c.prior.covariance = (Vector6d() << 0.1, 0.1, 0.1, 0.05, 0.05, 0.05)
                           .finished()
                           .array()
                           .square()
                           .matrix()
                           .asDiagonal();
  return c;
}

std::vector<PlaneMatch> IdentityMatches(int n) {
  std::vector<PlaneMatch> m;
  for (int i = 0; i < n; ++i) m.push_back({i, i, false});
  return m;
}

TEST(PointToPlane, EstimatesPinholeIntrinsicsFromTheGrid) {
  std::mt19937 rng(1);
  const datasets::PinholeIntrinsics k = SmallCamera();
  const auto cloud = RayCast(MakeCorridor(true), k, Pose(LookAlongX()), 0.0, rng);
  const auto est = EstimatePinholeIntrinsics(cloud);
  ASSERT_TRUE(est.has_value());
  EXPECT_NEAR(est->fx, k.fx, 1e-3);
  EXPECT_NEAR(est->fy, k.fy, 1e-3);
  EXPECT_NEAR(est->cx, k.cx, 1e-3);
  EXPECT_NEAR(est->cy, k.cy, 1e-3);
  EXPECT_EQ(est->width, k.width);

  datasets::OrganizedCloud spherical = cloud;
  spherical.model = datasets::SensorModel::kSpherical;
  EXPECT_FALSE(EstimatePinholeIntrinsics(spherical).has_value());
  datasets::OrganizedCloud scrambled = cloud;
  std::shuffle(scrambled.points.begin(), scrambled.points.end(), rng);
  EXPECT_FALSE(EstimatePinholeIntrinsics(scrambled).has_value());
  EXPECT_FALSE(EstimatePinholeIntrinsics(datasets::OrganizedCloud()).has_value());
}

TEST(PointToPlane, RecoversTheCorridorAxisFromCrossStructure) {
  std::mt19937 rng(42);
  const CorridorCase c = MakeCase(/*with_features=*/true, /*prior_error=*/-0.12, rng);
  RegistrationResult r = RegisterPlanes(c.prev_planes, c.curr_planes, IdentityMatches(4), c.prior);
  ASSERT_TRUE(r.degenerate);
  ASSERT_EQ(r.degenerate_directions.size(), 1u);
  EXPECT_NEAR(std::abs(r.degenerate_directions[0].head<3>().dot(c.axis_prev)), 1.0, 1e-9);
  // Before the fallback the along-axis translation is the prior's (off by 12 cm).
  EXPECT_NEAR((r.T_prev_curr.translation() - c.T_prev_curr.translation()).dot(c.axis_prev), -0.12,
              1e-9);

  const auto k = EstimatePinholeIntrinsics(c.prev_cloud);
  ASSERT_TRUE(k.has_value());
  PointToPlaneConfig config;
  config.pixel_stride = 1;  // the test camera has 1/16 of a VGA image's pixels
  ASSERT_TRUE(FillDegenerateWithPointToPlane(c.prev_cloud, *k, c.curr_cloud, config, &r));
  EXPECT_TRUE(r.used_icp);
  EXPECT_FALSE(r.used_prior);
  EXPECT_TRUE(r.degenerate);  // still describes the planes
  const Eigen::Vector3d err = r.T_prev_curr.translation() - c.T_prev_curr.translation();
  EXPECT_LT(std::abs(err.dot(c.axis_prev)), 0.005);
  EXPECT_LT(err.norm(), 0.005);
  EXPECT_LT(test::RotationError(r.T_prev_curr, c.T_prev_curr), 1e-6);
  // The covariance along the axis now comes from the points: far below the prior's 0.1^2.
  Vector6d a = Vector6d::Zero();
  a.head<3>() = c.axis_prev;
  const double var_axis = a.dot(r.covariance * a);
  EXPECT_GT(var_axis, 0.0);
  EXPECT_LT(var_axis, 0.02 * 0.02);
  EXPECT_TRUE(r.covariance.allFinite());
}

TEST(PointToPlane, ACorrectionThePriorRulesOutIsRefused) {
  // Same corridor, but the prior claims 2 cm certainty along the axis while being 12 cm off: the
  // points' answer lies 6 sigma away, which is treated as a wrong convergence.
  std::mt19937 rng(42);
  CorridorCase c = MakeCase(/*with_features=*/true, /*prior_error=*/-0.12, rng);
  c.prior.covariance.topLeftCorner<3, 3>() = Eigen::Matrix3d::Identity() * 0.02 * 0.02;
  RegistrationResult r = RegisterPlanes(c.prev_planes, c.curr_planes, IdentityMatches(4), c.prior);
  const RegistrationResult before = r;
  const auto k = EstimatePinholeIntrinsics(c.prev_cloud);
  ASSERT_TRUE(k.has_value());
  PointToPlaneConfig config;
  config.pixel_stride = 1;
  EXPECT_FALSE(FillDegenerateWithPointToPlane(c.prev_cloud, *k, c.curr_cloud, config, &r));
  EXPECT_TRUE(r.used_prior);
  EXPECT_FALSE(r.used_icp);
  EXPECT_TRUE(r.T_prev_curr.isApprox(before.T_prev_curr));
}

TEST(PointToPlane, BareCorridorKeepsThePriorAndSaysSo) {
  std::mt19937 rng(43);
  const CorridorCase c = MakeCase(/*with_features=*/false, /*prior_error=*/0.08, rng);
  RegistrationResult r = RegisterPlanes(c.prev_planes, c.curr_planes, IdentityMatches(4), c.prior);
  ASSERT_EQ(r.degenerate_directions.size(), 1u);
  const RegistrationResult before = r;
  const auto k = EstimatePinholeIntrinsics(c.prev_cloud);
  ASSERT_TRUE(k.has_value());
  PointToPlaneConfig config;
  config.pixel_stride = 1;
  EXPECT_FALSE(FillDegenerateWithPointToPlane(c.prev_cloud, *k, c.curr_cloud, config, &r));
  EXPECT_TRUE(r.used_prior);
  EXPECT_FALSE(r.used_icp);
  EXPECT_TRUE(r.T_prev_curr.isApprox(before.T_prev_curr));
  EXPECT_NEAR((r.T_prev_curr.translation() - c.prior.T_prev_curr.translation()).dot(c.axis_prev),
              0.0, 1e-9);
}

TEST(PointToPlane, AlignmentAlongAllDirectionsConvergesNearTheTruth) {
  // With cross structure the point-to-plane part alone (all six directions) also converges from
  // a perturbed start: a check of its Jacobian and association.
  std::mt19937 rng(44);
  const CorridorCase c = MakeCase(true, 0.0, rng);
  Pose start = c.T_prev_curr;
  start.translation() += Eigen::Vector3d(0.03, -0.02, 0.05);
  start.linear() = ExpSO3(Eigen::Vector3d(0.01, -0.01, 0.02)) * start.linear();
  PointToPlaneConfig config;
  config.pixel_stride = 1;
  const auto k = EstimatePinholeIntrinsics(c.prev_cloud);
  ASSERT_TRUE(k.has_value());
  const PointToPlaneResult a = AlignPointToPlane(
      c.prev_cloud, *k, c.curr_cloud, start, Matrix6d::Identity(), Matrix6d::Identity(), config);
  ASSERT_TRUE(a.valid);
  EXPECT_LT(test::TranslationError(a.T_prev_curr, c.T_prev_curr), 0.01);
  EXPECT_LT(test::RotationError(a.T_prev_curr, c.T_prev_curr), 0.005);
}

TEST(PointToPlane, EmptyCloudsAreNotAnError) {
  RegistrationResult r = RegisterPlanes({}, {}, {}, MotionPrior());
  const datasets::OrganizedCloud empty;
  EXPECT_FALSE(FillDegenerateWithPointToPlane(empty, SmallCamera(), empty, {}, &r));
  EXPECT_TRUE(r.used_prior);
  EXPECT_TRUE(r.T_prev_curr.matrix().allFinite());
}

}  // namespace
}  // namespace planeslam::registration
