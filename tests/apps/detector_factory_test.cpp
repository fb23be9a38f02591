// The detector factory: methods and the minimum plane size of detectors for decimated clouds.
#include "detector_factory.hpp"

#include <gtest/gtest.h>

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
  for (const std::string method : {"grid3", "point"}) {
    EXPECT_TRUE(MakeDetector(method, config)->Detect(cloud).planes.empty()) << method;
    const detection::Segmentation seg = MakeDetector(method, config, 2)->Detect(cloud);
    ASSERT_EQ(seg.planes.size(), 1u) << method;
    EXPECT_GT(seg.planes[0].normal.z(), 0.999) << method;
  }
  EXPECT_THROW(MakeDetector("grid3", config, 0), CheckError);
}

}  // namespace
}  // namespace planeslam::app
