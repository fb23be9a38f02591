#include "planeslam/datasets/plane_repeatability.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

namespace planeslam::datasets {
namespace {

constexpr double kDeg = M_PI / 180.0;

Pose MakePose(double yaw_deg, double pitch_deg, const Eigen::Vector3d& t) {
  Pose T = Pose::Identity();
  T.linear() = (Eigen::AngleAxisd(yaw_deg * kDeg, Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(pitch_deg * kDeg, Eigen::Vector3d::UnitY()))
                   .toRotationMatrix();
  T.translation() = t;
  return T;
}

RepeatabilityPlane MakePlane(const Eigen::Vector3d& n, double d, std::int64_t count) {
  RepeatabilityPlane p;
  p.normal = n.normalized();
  p.d = d;
  p.point_count = count;
  return p;
}

TEST(PlaneRepeatability, TransformKeepsPointsOnThePlane) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    const RepeatabilityPlane pj =
        MakePlane(Eigen::Vector3d(u(rng), u(rng), u(rng)), 0.5 + std::abs(u(rng)), 100);
    const Pose T_i_j = MakePose(90 * u(rng), 30 * u(rng), Eigen::Vector3d(u(rng), u(rng), u(rng)));
    const RepeatabilityPlane pi = TransformPlane(pj, T_i_j);
    EXPECT_GE(pi.d, 0.0);
    EXPECT_NEAR(pi.normal.norm(), 1.0, 1e-12);
    // Three points on plane j, mapped with T_i_j, lie on plane i.
    const Eigen::Vector3d base = pj.normal * pj.d;
    const Eigen::Vector3d e1 = pj.normal.unitOrthogonal();
    const Eigen::Vector3d e2 = pj.normal.cross(e1);
    for (const Eigen::Vector3d& q :
         std::vector<Eigen::Vector3d>{base, base + 2.0 * e1, base - 3.0 * e2}) {
      EXPECT_NEAR(pi.normal.dot(T_i_j * q), pi.d, 1e-12);
    }
    // Round trip.
    const RepeatabilityPlane back = TransformPlane(pi, T_i_j.inverse());
    EXPECT_NEAR((back.normal - pj.normal).norm(), 0.0, 1e-12);
    EXPECT_NEAR(back.d, pj.d, 1e-12);
  }
}

TEST(PlaneRepeatability, MatchesPerturbedPlanesSeenFromAnotherPose) {
  // A room seen from frame i: floor, two walls, a small box top.
  const std::vector<RepeatabilityPlane> room_i = {
      MakePlane({0, 1, 0}, 1.2, 40000), MakePlane({0, 0, 1}, 3.0, 60000),
      MakePlane({1, 0, 0}, 1.5, 8000), MakePlane({0, 1, 0.02}, 0.4, 1500)};
  const Pose T_i_j = MakePose(10.0, 5.0, Eigen::Vector3d(0.1, -0.05, 0.3));
  // Frame j sees the same planes (exactly, then perturbed by known amounts) in shuffled order plus
  // one plane with no counterpart.
  std::vector<RepeatabilityPlane> room_j;
  const std::vector<int> order = {2, 0, 3, 1};
  const std::vector<double> tilt_deg = {1.0, 0.5, 0.0, 2.0};  // indexed by frame-i plane
  const std::vector<double> shift_m = {0.01, 0.02, 0.0, 0.005};
  for (const int idx : order) {
    // Perturb in frame i (tilt about an axis orthogonal to the normal, shift along it), then
    // express in frame j: mapping back with T_i_j must recover exactly this perturbation.
    RepeatabilityPlane p = room_i[idx];
    p.normal = Eigen::AngleAxisd(tilt_deg[idx] * kDeg, p.normal.unitOrthogonal()) * p.normal;
    p.d += shift_m[idx];
    room_j.push_back(TransformPlane(p, T_i_j.inverse()));
  }
  room_j.push_back(MakePlane({0.7, 0.7, 0}, 5.0, 20000));

  const RepeatabilityResult r = MatchPlanes(room_i, room_j, T_i_j);
  ASSERT_EQ(r.matches.size(), 4u);
  for (const PlanePairMatch& m : r.matches) {
    EXPECT_EQ(order[static_cast<std::size_t>(m.index_j)], m.index_i);
    EXPECT_NEAR(m.angle_deg, tilt_deg[static_cast<std::size_t>(m.index_i)], 1e-9);
    EXPECT_NEAR(m.offset_m, shift_m[static_cast<std::size_t>(m.index_i)], 1e-9);
    EXPECT_EQ(m.large, room_i[static_cast<std::size_t>(m.index_i)].point_count >= 5000);
  }
  EXPECT_EQ(r.large_planes, 3);
  EXPECT_EQ(r.large_matched, 3);
  EXPECT_DOUBLE_EQ(r.MatchingFraction(), 1.0);

  // Without the relative pose, 10 deg of yaw and 30 cm of motion put every pair outside the gates.
  const RepeatabilityResult wrong = MatchPlanes(room_i, room_j, Pose::Identity());
  EXPECT_LT(wrong.large_matched, 3);
}

TEST(PlaneRepeatability, GatesAndNearestPartner) {
  const std::vector<RepeatabilityPlane> pi = {MakePlane({0, 0, 1}, 2.0, 10000)};
  // Two candidates in the gates: the one closer in angle + offset wins; one outside the offset gate.
  const std::vector<RepeatabilityPlane> pj = {
      MakePlane(Eigen::AngleAxisd(4 * kDeg, Eigen::Vector3d::UnitX()) * Eigen::Vector3d::UnitZ(),
                2.03, 10000),
      MakePlane(Eigen::AngleAxisd(1 * kDeg, Eigen::Vector3d::UnitX()) * Eigen::Vector3d::UnitZ(),
                2.01, 10000),
      MakePlane({0, 0, 1}, 2.2, 10000)};
  const RepeatabilityResult r = MatchPlanes(pi, pj, Pose::Identity());
  ASSERT_EQ(r.matches.size(), 1u);
  EXPECT_EQ(r.matches[0].index_j, 1);
  EXPECT_NEAR(r.matches[0].angle_deg, 1.0, 1e-9);
  EXPECT_NEAR(r.matches[0].offset_m, 0.01, 1e-9);

  RepeatabilityOptions tight;
  tight.max_angle_deg = 0.5;
  const RepeatabilityResult none = MatchPlanes(pi, pj, Pose::Identity(), tight);
  EXPECT_TRUE(none.matches.empty());
  EXPECT_EQ(none.large_planes, 1);
  EXPECT_DOUBLE_EQ(none.MatchingFraction(), 0.0);
}

TEST(PlaneRepeatability, SummaryMediansPoolLargePairs) {
  RepeatabilityResult a, b;
  a.matches = {{0, 0, 1.0, 0.01, true}, {1, 1, 9.0, 0.09, false}};  // small pair ignored
  a.large_planes = 2;
  a.large_matched = 1;
  b.matches = {{0, 0, 2.0, 0.02, true}, {1, 1, 4.0, 0.04, true}};
  b.large_planes = 2;
  b.large_matched = 2;
  RepeatabilitySummary s;
  EXPECT_DOUBLE_EQ(s.MedianAngleDeg(), -1.0);
  s.Add(a);
  s.Add(b);
  EXPECT_EQ(s.frame_pairs, 2);
  EXPECT_DOUBLE_EQ(s.MedianAngleDeg(), 2.0);
  EXPECT_DOUBLE_EQ(s.MedianOffset(), 0.02);
  EXPECT_DOUBLE_EQ(s.MatchingFraction(), 0.75);
  s.Add(b);  // even count: mean of the two middle values (1, 2, 2, 4, 4 -> 2; add one more)
  RepeatabilityResult c;
  c.matches = {{0, 0, 10.0, 0.1, true}};
  s.Add(c);  // 1, 2, 2, 4, 4, 10 -> (2 + 4) / 2
  EXPECT_DOUBLE_EQ(s.MedianAngleDeg(), 3.0);
}

}  // namespace
}  // namespace planeslam::datasets
