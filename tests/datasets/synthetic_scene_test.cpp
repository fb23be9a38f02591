// Synthetic scenes and trajectories: ids, geometry of the faces, loop closure by construction.
#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/synthetic_scene.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"

namespace planeslam::datasets {
namespace {

constexpr double kPi = 3.14159265358979323846;

TEST(SyntheticScene, PlaneIdsAreOneToNAndFacesLieInTheirPlanes) {
  for (SceneKind kind : {SceneKind::kRoom, SceneKind::kCorridor, SceneKind::kRubble}) {
    const SyntheticScene scene = MakeScene(kind, 7);
    ASSERT_FALSE(scene.planes.empty());
    for (std::size_t i = 0; i < scene.planes.size(); ++i) {
      const ScenePlane& p = scene.planes[i];
      EXPECT_EQ(p.id, static_cast<int>(i) + 1) << scene.name;
      EXPECT_NEAR(p.normal.norm(), 1.0, 1e-12);
      EXPECT_GT(p.Area(), 0.0);
      for (const auto& poly : p.polygons) {
        ASSERT_GE(poly.size(), 3u);
        for (const auto& c : poly) EXPECT_NEAR(p.normal.dot(c), p.d, 1e-9) << p.name;
        // Counter-clockwise about the normal and convex: every turn is to the left.
        for (std::size_t k = 0; k < poly.size(); ++k) {
          const Eigen::Vector3d e0 = poly[(k + 1) % poly.size()] - poly[k];
          const Eigen::Vector3d e1 = poly[(k + 2) % poly.size()] - poly[(k + 1) % poly.size()];
          EXPECT_GT(e0.cross(e1).dot(p.normal), 0.0) << p.name;
        }
      }
    }
  }
}

TEST(SyntheticScene, RoomHasTheDescribedShell) {
  const SyntheticScene room = MakeScene(SceneKind::kRoom);
  // Floor: 6 x 5 m plus the 0.2 x 0.9 m strip under the door recess.
  EXPECT_NEAR(room.Plane(1).Area(), 30.0 + 0.18, 1e-9);
  EXPECT_EQ(room.Plane(1).name, "floor");
  const Eigen::AlignedBox3d b = room.Bounds();
  EXPECT_NEAR(b.min().z(), 0.0, 1e-12);
  EXPECT_NEAR(b.max().z(), 2.8, 1e-12);
  EXPECT_NEAR(b.sizes().x(), 6.2, 1e-12);  // with the door recess
  EXPECT_NEAR(b.sizes().y(), 5.0, 1e-12);
  EXPECT_FALSE(room.spheres.empty());
  EXPECT_FALSE(room.cylinders.empty());
  EXPECT_THROW(room.Plane(0), CheckError);
}

TEST(SyntheticScene, RubbleDependsOnSeedOnly) {
  const SyntheticScene a = MakeScene(SceneKind::kRubble, 3), b = MakeScene(SceneKind::kRubble, 3);
  const SyntheticScene c = MakeScene(SceneKind::kRubble, 4);
  ASSERT_EQ(a.planes.size(), b.planes.size());
  for (std::size_t i = 0; i < a.planes.size(); ++i) {
    EXPECT_EQ(a.planes[i].normal, b.planes[i].normal);
    EXPECT_EQ(a.planes[i].d, b.planes[i].d);
  }
  EXPECT_NE(a.planes[1].normal, c.planes[1].normal);
  // Slabs are 0.3 .. 1.5 m: no polygon edge longer than 1.5 m.
  for (const auto& p : a.planes) {
    if (p.name.rfind("slab", 0) != 0) continue;
    for (const auto& poly : p.polygons)
      for (std::size_t k = 0; k < poly.size(); ++k)
        EXPECT_LE((poly[(k + 1) % poly.size()] - poly[k]).norm(), 1.5 + 1e-9);
  }
}

TEST(SyntheticScene, ParseSceneKindRejectsUnknownNames) {
  EXPECT_EQ(ParseSceneKind("corridor"), SceneKind::kCorridor);
  EXPECT_EQ(SceneName(ParseSceneKind("rubble")), "rubble");
  try {
    ParseSceneKind("kitchen");
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("kitchen"), std::string::npos);
  }
}

TEST(SyntheticScene, ReferenceIntersectionKnownAnswers) {
  const SyntheticScene room = MakeScene(SceneKind::kRoom);
  // Straight down from the room centre: the floor at 1.4 m.
  RayHit h = IntersectScene(room, Eigen::Vector3d(0, 0, 1.4), -Eigen::Vector3d::UnitZ());
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.t, 1.4, 1e-12);
  EXPECT_EQ(h.label, 1);
  // Through the door opening to the recessed door at x = 3.2.
  h = IntersectScene(room, Eigen::Vector3d(0, 0.8, 1.0), Eigen::Vector3d::UnitX());
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.t, 3.2, 1e-12);
  EXPECT_EQ(room.Plane(h.label).name, "door");
  // Onto the ball (label 0) from above: top of the sphere at z = 0.3.
  h = IntersectScene(room, Eigen::Vector3d(1.2, -2.0, 1.0), -Eigen::Vector3d::UnitZ());
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.t, 0.7, 1e-12);
  EXPECT_EQ(h.label, 0);
}

double RotationAngle(const Pose& a, const Pose& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle();
}

TEST(SyntheticTrajectory, LoopIsSmoothAndReturnsNearItsStart) {
  for (SceneKind kind : {SceneKind::kRoom, SceneKind::kRubble}) {
    SyntheticConfig config = SyntheticConfig::ForScene(kind);
    SyntheticSequence seq(config);
    const auto& tc = config.trajectory;
    const std::size_t n = seq.Size();
    ASSERT_EQ(static_cast<int>(n), TrajectoryFrameCount(tc));
    // Laps * circumference / speed * rate frames.
    EXPECT_NEAR(static_cast<double>(n), tc.laps * 2 * kPi * tc.radius / tc.speed * tc.rate, 1.0);
    const double step = tc.speed / tc.rate;
    for (std::size_t i = 1; i < n; ++i) {
      const Pose a = *seq.GroundTruth(i - 1), b = *seq.GroundTruth(i);
      EXPECT_LE((a.translation() - b.translation()).norm(), 2.0 * step);
      EXPECT_LE(RotationAngle(a, b), 2.0 * kPi / 180.0);  // <= 60 deg/s at 30 Hz
      EXPECT_GT(seq.Timestamp(i), seq.Timestamp(i - 1));
    }
    // After one lap the path passes the start again (xy exactly, height and view a little off).
    const Pose start = *seq.GroundTruth(0);
    double best = 1e9;
    std::size_t best_i = 0;
    for (std::size_t i = n / 2; i < n; ++i) {
      const double dxy = (seq.GroundTruth(i)->translation() - start.translation()).head<2>().norm();
      if (dxy < best) {
        best = dxy;
        best_i = i;
      }
    }
    EXPECT_LT(best, step);
    EXPECT_LT(std::abs(seq.GroundTruth(best_i)->translation().z() - start.translation().z()), 0.3);
    EXPECT_LT(RotationAngle(*seq.GroundTruth(best_i), start), 35.0 * kPi / 180.0);
    EXPECT_GT(RotationAngle(*seq.GroundTruth(best_i), start), 0.0);
  }
}

TEST(SyntheticTrajectory, PinholePoseIsTheOpticalFrame) {
  SyntheticConfig config = SyntheticConfig::ForScene(SceneKind::kCorridor);
  config.trajectory.yaw_amplitude_deg = 0.0;
  config.trajectory.pitch_deg = 0.0;
  config.trajectory.pitch_amplitude_deg = 0.0;
  config.trajectory.roll_amplitude_deg = 0.0;
  SyntheticSequence seq(config);
  const Pose T = *seq.GroundTruth(0);
  // Optical z (forward) along the corridor (+x), optical y (down) along -z.
  EXPECT_NEAR((T.linear().col(2) - Eigen::Vector3d::UnitX()).norm(), 0.0, 1e-12);
  EXPECT_NEAR((T.linear().col(1) + Eigen::Vector3d::UnitZ()).norm(), 0.0, 1e-12);
  EXPECT_NEAR(T.linear().determinant(), 1.0, 1e-12);
  // The run is straight along +x.
  const Pose last = *seq.GroundTruth(seq.Size() - 1);
  EXPECT_NEAR(last.translation().x() - T.translation().x(), config.trajectory.length,
              config.trajectory.speed / config.trajectory.rate);
}

}  // namespace
}  // namespace planeslam::datasets
