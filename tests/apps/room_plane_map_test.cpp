// The plane map of `planeslam run` on the built-in synthetic room (default config, the whole loop,
// noise on), against the scene: every scene plane of at least 1 m^2 that the frames saw over 1 m^2
// is mapped exactly once, its normal within 1 deg, its outline's area within 15 % of the area seen;
// every map plane of at least 1 m^2 is a scene plane. Runs the same pipeline as `planeslam run` in
// process (the ground-truth labels of each frame give the area seen).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <vector>

#include "config.hpp"
#include "config_sections_slam.hpp"
#include "config_sections_synthetic.hpp"
#include "detector_factory.hpp"
#include "mapping/covered_cells.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"

namespace planeslam::test {
namespace {

/// A map plane matched to the scene plane it lies on.
struct Match {
  int scene_id = 0;          ///< 0: none within the offset and angle gates
  double angle_deg = 180.0;  ///< between the normals, up to sign
  double offset = 0.0;       ///< [m]
};

Match MatchScenePlane(const mapping::MapPlane& plane, const datasets::SyntheticScene& scene) {
  Match best;
  for (const datasets::ScenePlane& truth : scene.planes) {
    // Orientation conventions differ (observer side vs seen side): compare up to sign.
    const double c = plane.normal.dot(truth.normal);
    const double angle = std::acos(std::min(1.0, std::abs(c))) * 180.0 / M_PI;
    const double offset = std::abs(c > 0 ? plane.d - truth.d : plane.d + truth.d);
    if (offset < 0.05 && angle < 10.0 && angle < best.angle_deg) {
      best = {truth.id, angle, offset};
    }
  }
  return best;
}

TEST(RoomPlaneMap, EveryLargeScenePlaneIsMappedOnceWithItsVisibleArea) {
  app::Config config;
  const auto sequence = app::MakeSyntheticSequence("room", config);
  const auto detector =
      app::MakeDetector(config.Get<app::DetectionSection>("detection").method, config);
  const std::unique_ptr<mapping::SlamSystem> slam_system = app::MakeSlamSystem(config);
  mapping::SlamSystem& slam = *slam_system;
  slam.SetInitialPose(*sequence->GroundTruth(0));
  // Ground truth of what was seen: every pixel labelled with a scene plane, at its true position,
  // in 2 cm cells of the plane's own 2D coordinates.
  const double cell = 0.02;
  std::map<int, CellSet> seen;
  std::map<int, std::pair<Eigen::Vector3d, Eigen::Vector3d>> plane_axes;  // (u, v) per id
  for (const datasets::ScenePlane& truth : sequence->scene().planes) {
    const Eigen::Vector3d u = truth.normal.unitOrthogonal();
    plane_axes[truth.id] = {u, truth.normal.cross(u)};
  }
  for (std::size_t i = 0; i < sequence->Size(); ++i) {
    const datasets::SyntheticFrame generated = sequence->Generate(i);
    const datasets::Frame& frame = generated.frame;
    slam.ProcessFrame(frame.timestamp, frame.cloud, detector->Detect(frame.cloud));
    const Pose T = *frame.T_world_sensor_gt;
    for (std::size_t k = 0; k < frame.cloud.points.size(); ++k) {
      const int id = generated.labels.data[k];
      if (id == 0 || !datasets::OrganizedCloud::IsValid(frame.cloud.points[k])) continue;
      const Eigen::Vector3d p = T * frame.cloud.points[k].cast<double>();
      const auto& [u, v] = plane_axes.at(id);
      seen[id].insert({static_cast<int>(std::floor(u.dot(p) / cell)),
                       static_cast<int>(std::floor(v.dot(p) / cell))});
    }
  }
  slam.Finish();

  // Each map plane on a scene plane, with its match and its outline's area.
  struct OnScenePlane {
    int map_id;
    Match match;
    double area;
  };
  std::map<int, std::vector<OnScenePlane>> mapped;  // by scene plane id
  for (const mapping::MapPlaneOutline& outline : slam.map().Outlines()) {
    const mapping::MapPlane* plane = slam.map().Find(outline.id);
    ASSERT_NE(plane, nullptr);
    const Match match = MatchScenePlane(*plane, sequence->scene());
    std::printf("map plane %3d: %6.3f m^2, %zu observations, scene plane %d (%.2f deg, %.1f mm)\n",
                outline.id, outline.region.area, plane->observations.size(), match.scene_id,
                match.angle_deg, 1e3 * match.offset);
    // A plane without an outline (seen too little for one) is not drawn in the map's meshes.
    if (match.scene_id != 0 && outline.region.valid()) {
      mapped[match.scene_id].push_back({outline.id, match, outline.region.area});
    }
    if (outline.region.area >= 1.0) {
      EXPECT_NE(match.scene_id, 0) << "map plane " << outline.id << " matches no scene plane";
    }
  }
  int large = 0;
  for (const datasets::ScenePlane& truth : sequence->scene().planes) {
    // Issue 8: planes of at least 1 m^2; of those, the ones the frames saw over 1 m^2 (the camera
    // looks at the walls: the ceiling is not seen at all). Area() is the exact area: counting 2 cm
    // cells overstates a small plane's (the 0.96 m^2 whiteboard covers 1.04 m^2 of cells).
    const double visible = FilledArea(seen[truth.id], cell);
    if (truth.Area() < 1.0 || visible < 1.0) continue;
    ++large;
    const auto& on_it = mapped[truth.id];
    std::printf("scene plane %d (%s): visible %.3f m^2, %zu map planes\n", truth.id,
                truth.name.c_str(), visible, on_it.size());
    ASSERT_EQ(on_it.size(), 1u) << "scene plane " << truth.name;
    const auto& [map_id, match, area] = on_it.front();
    EXPECT_LT(match.angle_deg, 1.0) << "scene plane " << truth.name;
    std::printf("  map plane %d: %.3f m^2 (%+.1f %%), %.2f deg, %.1f mm\n", map_id, area,
                100.0 * (area - visible) / visible, match.angle_deg, 1e3 * match.offset);
    EXPECT_NEAR(area, visible, 0.15 * visible) << "scene plane " << truth.name;
  }
  EXPECT_GE(large, 6);
}

}  // namespace
}  // namespace planeslam::test
