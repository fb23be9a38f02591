// The detector factory: methods and the minimum plane size of detectors for decimated clouds.
#include "detector_factory.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "config.hpp"
#include "planeslam/datasets/errors.hpp"

namespace planeslam::app {
namespace {

TEST(DetectorFactory, ThetaCountsFullResolutionPixelsOnDecimatedClouds) {
  // A wall filling a 20 x 15 cloud: 300 points, below detection.theta = 400. As the cloud of a
  // frame decimated by 2 it stands for 1200 full-resolution pixels, above it.
  datasets::OrganizedCloud cloud(20, 15);
  for (int y = 0; y < cloud.height; ++y) {
    for (int x = 0; x < cloud.width; ++x) {
      cloud.at(y, x) = Eigen::Vector3f(0.01f * (x - 10), 0.01f * (y - 7), 1.5f);
    }
  }
  Config config;
  config.Set("detection.theta=400");
  for (const std::string method : {"grid", "point"}) {
    EXPECT_TRUE(MakeDetector(method, config)->Detect(cloud).planes.empty()) << method;
    const detection::Segmentation seg = MakeDetector(method, config, 2)->Detect(cloud);
    ASSERT_EQ(seg.planes.size(), 1u) << method;
    EXPECT_GT(seg.planes[0].normal.z(), 0.999) << method;
  }
  EXPECT_THROW(MakeDetector("grid", config, 0), CheckError);
}

TEST(DetectorFactory, EveryMethodOnDegenerateClouds) {
  // No crash, one label per pixel, labels that name the planes, each plane's point count equal
  // to its labelled pixels: on clouds smaller than a grid, without a valid point, with holes, and
  // with a single plane (no border between planes at all).
  auto plane_with_holes = [](int w, int h, bool holes) {
    datasets::OrganizedCloud cloud(w, h);
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        // Holes: one pixel in 11, so that every grid of up to 6x6 keeps the points it needs
        // (31 of 36).
        const bool hole = holes && (x * 7 + y * 3) % 11 == 0;
        cloud.at(y, x) = hole ? Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN())
                              : Eigen::Vector3f(0.004f * (x - w / 2), 0.004f * (y - h / 2), 2.0f);
      }
    }
    return cloud;
  };
  std::vector<datasets::OrganizedCloud> clouds = {
      datasets::OrganizedCloud(0, 0),   datasets::OrganizedCloud(1, 1),
      datasets::OrganizedCloud(40, 30), plane_with_holes(3, 2, false),
      plane_with_holes(7, 6, false),    plane_with_holes(41, 31, false),
      plane_with_holes(41, 31, true)};
  Config config;
  config.Set("detection.theta=20");
  for (const std::string& method : DetectorMethods()) {
    for (const auto& cloud : clouds) {
      const std::string what =
          method + " " + std::to_string(cloud.width) + "x" + std::to_string(cloud.height);
      const detection::Segmentation seg = MakeDetector(method, config)->Detect(cloud);
      ASSERT_EQ(seg.labels.size(), cloud.points.size()) << what;
      std::vector<std::int64_t> counts(seg.planes.size() + 1, 0);
      for (const int l : seg.labels) {
        ASSERT_GE(l, -1) << what;
        ASSERT_LE(l, static_cast<int>(seg.planes.size())) << what;
        if (l >= 1) ++counts[static_cast<std::size_t>(l)];
      }
      for (const auto& p : seg.planes) {
        EXPECT_EQ(counts[static_cast<std::size_t>(p.id)], p.point_count) << what;
        EXPECT_NEAR(p.normal.norm(), 1.0, 1e-9) << what;
      }
      if (cloud.width == 41) {  // the one plane, 2 m in front of the sensor, is found
        ASSERT_EQ(seg.planes.size(), 1u) << what;
        EXPECT_GT(seg.planes[0].normal.z(), 0.9999) << what;
        EXPECT_NEAR(seg.planes[0].d, 2.0, 1e-4) << what;
      }
    }
  }
}

}  // namespace
}  // namespace planeslam::app
