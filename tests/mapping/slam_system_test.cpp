// SlamSystem in process, on hand-made planes: when a frame renews its keyframe, when a result is
// refused against the motion prior, and how frames between keyframes follow the optimised graph.
// (The plane map of the whole synthetic room loop is checked in tests/apps/room_plane_map_test.cpp,
// through the same configuration as `planeslam run`.)
#include "planeslam/mapping/slam_system.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

#include "registration/registration_test_util.hpp"

namespace planeslam::mapping {
namespace {

/// A frame of hand-made planes (ids 1, 2, ...) over an 8 x 8 image with no labelled pixels:
/// tracking needs only the planes.
detection::Segmentation PlanesOnly(std::vector<detection::Plane> planes) {
  detection::Segmentation s;
  s.width = 8;
  s.height = 8;
  s.labels.assign(64, -1);
  s.planes = std::move(planes);
  for (std::size_t k = 0; k < s.planes.size(); ++k) s.planes[k].id = static_cast<int>(k) + 1;
  return s;
}

/// A hand-made plane seen as an 8 x 8 grid of points (the map needs points): normal, offset, the
/// grid's centre in the plane's tangent basis and its spacing [m].
struct Patch {
  Eigen::Vector3d n;
  double d;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  double spacing = 0.25;
};

/// A frame of patches (plane ids 1, 2, ...), each in its own 8-column block of `cloud`.
detection::Segmentation PatchFrame(const std::vector<Patch>& patches,
                                   datasets::OrganizedCloud* cloud) {
  *cloud = datasets::OrganizedCloud(8 * static_cast<int>(patches.size()), 8);
  detection::Segmentation s;
  s.width = cloud->width;
  s.height = cloud->height;
  s.labels.assign(cloud->size(), -1);
  for (std::size_t k = 0; k < patches.size(); ++k) {
    const Patch& patch = patches[k];
    detection::Plane plane = registration::test::MakePlane(patch.n, patch.d);
    plane.id = static_cast<int>(k) + 1;
    const Eigen::Matrix<double, 3, 2> tangent = registration::TangentBasis(patch.n);
    plane.centroid = patch.n * patch.d + tangent * patch.centre;
    for (int r = 0; r < 8; ++r) {
      for (int c = 0; c < 8; ++c) {
        const Eigen::Vector3d p =
            patch.n * patch.d +
            tangent * (patch.centre +
                       patch.spacing * Eigen::Vector2d(c - 3.5, r - 3.5));
        const std::size_t pixel = static_cast<std::size_t>(r) * cloud->width + 8 * k + c;
        cloud->points[pixel] = p.cast<float>();
        s.labels[pixel] = plane.id;
        plane.moments.Add(p);
      }
    }
    s.planes.push_back(plane);
  }
  return s;
}

TEST(SlamSystem, FrameWhosePlanesAllMatchKeepsItsKeyframe) {
  // Two walls only (normals x and z), seen from a camera sliding along y by 1 cm per frame: every
  // frame matches 2 planes, fewer than keyframe_min_matches (6), but has no plane its keyframe
  // lacks, so it stays with the first keyframe. A third plane then renews the keyframe.
  SlamSystem slam(SlamConfig{}, {}, {}, {}, {}, {});
  const datasets::OrganizedCloud cloud(8, 8);  // no points: tracking needs only the planes
  auto frame = [](bool with_floor, double y) {
    std::vector<detection::Plane> planes = {
        registration::test::MakePlane(Eigen::Vector3d::UnitX(), 3.0),
        registration::test::MakePlane(Eigen::Vector3d::UnitZ(), 2.0)};
    if (with_floor) {
      planes.push_back(registration::test::MakePlane(Eigen::Vector3d::UnitY(), 1.5 - y));
    }
    return PlanesOnly(std::move(planes));
  };
  for (int i = 0; i < 10; ++i) {
    const SlamFrameResult r = slam.ProcessFrame(i / 30.0, cloud, frame(false, 0.01 * i));
    EXPECT_EQ(r.keyframe, i == 0) << "frame " << i;
    if (i > 0) {
      EXPECT_EQ(r.matches, 2) << "frame " << i;
    }
  }
  EXPECT_EQ(slam.stats().keyframes, 1u);
  const SlamFrameResult r = slam.ProcessFrame(10 / 30.0, cloud, frame(true, 0.1));
  EXPECT_TRUE(r.keyframe);
  EXPECT_EQ(slam.stats().keyframes, 2u);
}

TEST(SlamSystem, RollSetByOneSmallPlaneAgainstASmoothMotionIsNotTaken) {
  // A still camera sees two walls (normals x and z) and the floor (normal y). Then the z wall
  // leaves the view, and the floor is detected 3 deg off about the x wall's normal (as a small
  // sliver mixing in a strip of another surface does): the planes then say the camera rolled 3
  // deg in one frame, which the prior's plausible change of velocity (0.005 rad) does not
  // explain. The floor's pair is dropped; the x wall's stays and the roll comes from the prior.
  SlamSystem slam(SlamConfig{}, {}, {}, {}, {}, {});
  const datasets::OrganizedCloud cloud(8, 8);  // no points: tracking needs only the planes
  auto frame = [](bool with_z_wall, double floor_roll) {
    std::vector<detection::Plane> planes = {
        registration::test::MakePlane(Eigen::Vector3d::UnitX(), 3.0),
        registration::test::MakePlane(
            Eigen::AngleAxisd(floor_roll, Eigen::Vector3d::UnitX()) * Eigen::Vector3d::UnitY(),
            1.5)};
    if (with_z_wall) planes.push_back(registration::test::MakePlane(Eigen::Vector3d::UnitZ(), 2.0));
    return PlanesOnly(std::move(planes));
  };
  for (int i = 0; i < 10; ++i) {
    EXPECT_FALSE(slam.ProcessFrame(i / 30.0, cloud, frame(true, 0.0)).refused) << "frame " << i;
  }
  const SlamFrameResult r = slam.ProcessFrame(10 / 30.0, cloud, frame(false, 3.0 * M_PI / 180.0));
  EXPECT_FALSE(r.refused);
  EXPECT_EQ(r.matches, 1);
  EXPECT_LT(Eigen::AngleAxisd(r.T_world_sensor.linear()).angle(), 1e-3);

  // The association's own prior (0.05 rad) as the gate's would have taken the 3 deg roll.
  SlamConfig loose;
  loose.gate_translation_sigma = loose.prior_translation_sigma;
  loose.gate_rotation_sigma = loose.prior_rotation_sigma;
  SlamSystem trusting(loose, {}, {}, {}, {}, {});
  for (int i = 0; i < 10; ++i) trusting.ProcessFrame(i / 30.0, cloud, frame(true, 0.0));
  const SlamFrameResult t =
      trusting.ProcessFrame(10 / 30.0, cloud, frame(false, 3.0 * M_PI / 180.0));
  EXPECT_FALSE(t.refused);
  EXPECT_NEAR(Eigen::AngleAxisd(t.T_world_sensor.linear()).angle(), 3.0 * M_PI / 180.0, 1e-3);
}

/// Largest error of the frames' positions along y against the true ones.
double MaxErrorY(const datasets::Trajectory& estimated, const std::vector<double>& true_y) {
  double worst = 0.0;
  for (std::size_t i = 0; i < true_y.size(); ++i) {
    worst = std::max(worst, std::abs(estimated.poses[i].translation().y() - true_y[i]));
  }
  return worst;
}

TEST(SlamSystem, FramesBetweenKeyframesShareTheCorrectionOfTheirEdge) {
  // A camera slides along y past two walls (normals x and z). The floor (normal y) is in view for
  // the first 6 and the last 6 frames only; in between the camera speeds up from 1 to 1.2 cm per
  // frame while the constant-velocity prior keeps 1 cm, so the frames tracked against the first
  // keyframe fall behind by 2 mm a frame until a keyframe is made. The floor, a landmark of the
  // first and the last keyframes, lets the final optimisation correct the edges across the
  // stretch; the frames in between then take their share of that correction instead of keeping
  // the whole lag until the next keyframe.
  std::vector<double> true_y;
  double y = 0.0;
  for (int i = 0; i < 26; ++i) {
    true_y.push_back(y);
    y += i >= 5 && i < 20 ? 0.012 : 0.01;
  }
  auto run = [&](bool interpolate) {
    SlamConfig config;
    config.interpolate_frames = interpolate;
    config.keyframe_translation = 0.1;
    config.loop_closure = false;
    config.depth_map_fill = false;  // planes only: the hand-made clouds are no depth images
    SlamSystem slam(config, {}, {}, {}, {}, {});
    for (int i = 0; i < static_cast<int>(true_y.size()); ++i) {
      // Each plane is an 8 x 8 grid of points 25 cm apart around its foot point.
      std::vector<Patch> seen = {{Eigen::Vector3d::UnitX(), 3.0}, {Eigen::Vector3d::UnitZ(), 2.0}};
      if (i < 6 || i >= 20) seen.push_back({Eigen::Vector3d::UnitY(), 1.5 - true_y[i]});
      datasets::OrganizedCloud cloud;
      const detection::Segmentation s = PatchFrame(seen, &cloud);
      slam.ProcessFrame(i / 30.0, cloud, s);
    }
    slam.Finish();
    std::printf("interpolate %d: keyframes %zu, largest y error %.2f mm\n", interpolate,
                slam.stats().keyframes, 1000.0 * MaxErrorY(slam.EstimatedTrajectory(), true_y));
    return MaxErrorY(slam.EstimatedTrajectory(), true_y);
  };
  const double rigid = run(false), interpolated = run(true);
  EXPECT_LT(interpolated, 0.5 * rigid);
}

TEST(SlamSystem, PlaneDetectedOnceWhereLaterKeyframesLookedIsCulled) {
  // A camera moves back and forth by 1 cm a frame in front of three walls, a keyframe every frame.
  // The first frame also detects a patch seen at a grazing angle (a plane fitted across clutter
  // has any normal); no later keyframe, all within 2 cm of the first, detects it. The sight test
  // never counts it as looked at (it faces none of them), but keyframes at the first one's
  // viewpoint saw what it saw: the patch is culled, the walls stay.
  SlamConfig config;
  config.keyframe_translation = 0.005;
  config.loop_closure = false;
  config.depth_map_fill = false;  // planes only: the hand-made clouds are no depth images
  SlamSystem slam(config, {}, {}, {}, {}, {});
  for (int i = 0; i < 12; ++i) {
    const double y = 0.01 * (i % 4 == 3 ? 1 : i % 4);
    std::vector<Patch> seen = {{Eigen::Vector3d::UnitX(), 3.0, Eigen::Vector2d::Zero(), 0.1},
                               {Eigen::Vector3d::UnitZ(), 2.0, Eigen::Vector2d::Zero(), 0.1},
                               {Eigen::Vector3d::UnitY(), 1.5 - y, Eigen::Vector2d::Zero(), 0.1}};
    if (i == 0) seen.push_back({-Eigen::Vector3d::UnitY(), 0.1, Eigen::Vector2d(0.0, 2.0), 0.1});
    datasets::OrganizedCloud cloud;
    const detection::Segmentation s = PatchFrame(seen, &cloud);
    slam.ProcessFrame(i / 30.0, cloud, s);
  }
  slam.Finish();
  EXPECT_GE(slam.stats().keyframes, 10u);
  EXPECT_EQ(slam.stats().map_planes_culled, 1u);
  ASSERT_EQ(slam.map().planes().size(), 3u);
  for (const MapPlane& plane : slam.map().planes()) {
    EXPECT_GT(plane.d, 1.0) << "plane " << plane.id;  // a wall, not the patch (d = 0.1)
  }
}

}  // namespace
}  // namespace planeslam::mapping
