// SlamSystem in process on the first 60 frames of the synthetic room (noise on): the large map
// planes are the scene's planes (normal within 1 deg, offset within 3 cm) and none is mapped twice.
#include <gtest/gtest.h>

#include <cmath>
#include <map>

#include "planeslam/datasets/synthetic_sequence.hpp"
#include "planeslam/detection/grid_region_growing.hpp"
#include "planeslam/mapping/slam_system.hpp"

namespace planeslam::mapping {
namespace {

TEST(SlamSystem, SyntheticRoomLargeMapPlanesAreSceneplanesOnce) {
  datasets::SyntheticSequence sequence(
      datasets::SyntheticConfig::ForScene(datasets::SceneKind::kRoom));
  detection::GridParams grid;
  grid.cell_size = 3;
  grid.mu = 0;
  const detection::GridRegionGrowing detector(detection::DetectionParams{}, grid);
  SlamSystem slam(SlamConfig{}, {}, {}, {}, {}, {});
  slam.SetInitialPose(*sequence.GroundTruth(0));
  const std::size_t frames = std::min<std::size_t>(60, sequence.Size());
  for (std::size_t i = 0; i < frames; ++i) {
    const datasets::Frame frame = sequence.Load(i);
    slam.ProcessFrame(frame.timestamp, frame.cloud, detector.Detect(frame.cloud));
  }
  slam.Finish();
  std::map<int, int> mapped;  // scene plane id -> large map planes matched to it
  int large = 0;
  for (const MapPlaneOutline& outline : slam.map().Outlines()) {
    if (outline.polygon.area < 1.0) continue;  // issue 8: planes of at least 1 m^2
    ++large;
    const MapPlane* plane = slam.map().Find(outline.id);
    ASSERT_NE(plane, nullptr);
    int best = 0;
    double best_angle = 180.0;
    for (const datasets::ScenePlane& truth : sequence.scene().planes) {
      // Orientation conventions differ (observer side vs seen side): compare up to sign.
      const double c = plane->normal.dot(truth.normal);
      const double angle = std::acos(std::min(1.0, std::abs(c))) * 180.0 / M_PI;
      const double offset = std::abs(c > 0 ? plane->d - truth.d : plane->d + truth.d);
      if (offset < 0.03 && angle < best_angle) {
        best_angle = angle;
        best = truth.id;
      }
    }
    EXPECT_NE(best, 0) << "map plane " << outline.id << " matches no scene plane";
    EXPECT_LT(best_angle, 1.0) << "map plane " << outline.id;
    if (best != 0) ++mapped[best];
  }
  EXPECT_GE(large, 3);
  for (const auto& [id, count] : mapped) EXPECT_EQ(count, 1) << "scene plane " << id;
}

}  // namespace
}  // namespace planeslam::mapping
