#include "planeslam/datasets/depth_image.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "planeslam/datasets/errors.hpp"
#include "test_support.hpp"

namespace planeslam::datasets {
namespace {

PinholeIntrinsics SmallCamera() {
  PinholeIntrinsics k;
  k.width = 7;
  k.height = 5;
  k.fx = 10.0;
  k.fy = 12.0;
  k.cx = 3.2;
  k.cy = 1.9;
  return k;
}

TEST(DepthImage, FrontoParallelPlaneKnownAnswer) {
  const PinholeIntrinsics k = SmallCamera();
  Image16 depth(k.width, k.height);
  for (auto& d : depth.data) d = 10000;  // 2 m at 5000 units per metre
  const OrganizedCloud cloud = DepthToCloud(depth, k, 5000.0);
  ASSERT_EQ(cloud.width, 7);
  ASSERT_EQ(cloud.height, 5);
  EXPECT_EQ(cloud.model, SensorModel::kPinhole);
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3f p = cloud.at(v, u);
      EXPECT_FLOAT_EQ(p.z(), 2.0f);
      EXPECT_NEAR(p.x(), (u - 3.2) * 2.0 / 10.0, 1e-6);
      EXPECT_NEAR(p.y(), (v - 1.9) * 2.0 / 12.0, 1e-6);
    }
  }
}

TEST(DepthImage, ZeroAndOutOfRangeDepthAreNaN) {
  const PinholeIntrinsics k = SmallCamera();
  Image16 depth(k.width, k.height);
  depth.data[0] = 0;
  depth.data[1] = 5000;   // 1 m
  depth.data[2] = 60000;  // 12 m: beyond max_depth 10
  depth.data[3] = 1000;   // 0.2 m: below min_depth 0.3
  const OrganizedCloud cloud = DepthToCloud(depth, k, 5000.0, 0.3, 10.0);
  EXPECT_FALSE(cloud.IsValid(0));
  EXPECT_TRUE(std::isnan(cloud.points[0].x()) && std::isnan(cloud.points[0].y()));
  EXPECT_TRUE(cloud.IsValid(1));
  EXPECT_FALSE(cloud.IsValid(2));
  EXPECT_FALSE(cloud.IsValid(3));
  EXPECT_EQ(cloud.CountValid(), 1u);
}

TEST(DepthImage, MatchesDirectFormulaOnRandomImage) {
  PinholeIntrinsics k;  // TUM fr3 defaults, 640x480
  Image16 depth(k.width, k.height);
  std::mt19937 rng(42);
  std::uniform_int_distribution<int> dist(0, 65535);
  for (auto& d : depth.data) d = static_cast<std::uint16_t>(dist(rng) % 5 == 0 ? 0 : dist(rng));
  const OrganizedCloud cloud = DepthToCloud(depth, k, 5000.0);
  std::size_t valid = 0;
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const std::uint16_t raw = depth.data[static_cast<std::size_t>(v) * k.width + u];
      const Eigen::Vector3f p = cloud.at(v, u);
      if (raw == 0) {
        ASSERT_FALSE(OrganizedCloud::IsValid(p));
        continue;
      }
      ++valid;
      const double z = raw / 5000.0;
      ASSERT_NEAR(p.z(), z, 1e-6 * z);
      ASSERT_NEAR(p.x(), (u - k.cx) * z / k.fx, 1e-5 * (1 + z));
      ASSERT_NEAR(p.y(), (v - k.cy) * z / k.fy, 1e-5 * (1 + z));
    }
  }
  EXPECT_EQ(cloud.CountValid(), valid);
}

TEST(DepthImage, NegativeFyMirrorsY) {
  PinholeIntrinsics k = SmallCamera();
  Image16 depth(k.width, k.height);
  for (auto& d : depth.data) d = 7000;
  const OrganizedCloud up = DepthToCloud(depth, k, 5000.0);
  k.fy = -k.fy;
  const OrganizedCloud down = DepthToCloud(depth, k, 5000.0);
  for (std::size_t i = 0; i < up.size(); ++i) {
    EXPECT_FLOAT_EQ(up.points[i].x(), down.points[i].x());
    EXPECT_FLOAT_EQ(up.points[i].y(), -down.points[i].y());
    EXPECT_FLOAT_EQ(up.points[i].z(), down.points[i].z());
  }
}

TEST(DepthImage, SizeMismatchIsIoErrorNamingSource) {
  const PinholeIntrinsics k = SmallCamera();
  Image16 depth(8, 5);
  DepthProjector projector(k, 5000.0);
  try {
    projector.Project(depth, "frame.png");
    FAIL() << "expected IoError";
  } catch (const IoError& e) {
    EXPECT_EQ(std::string(e.what()),
              "frame.png: depth image is 8x5 but the intrinsics are for 7x5");
  }
}

// Bit patterns equal, NaN included (a NaN point compares unequal to itself).
bool SamePoint(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  return std::memcmp(a.data(), b.data(), sizeof(float) * 3) == 0;
}

TEST(DepthImage, DecimatedProjectionIsDecimateOfTheFullOne) {
  // A randomized family: sizes that are and are not multiples of the factor, every factor the
  // run accepts, depths with holes and out-of-range values, a flipped y axis now and then.
  std::mt19937 rng(35);
  for (int draw = 0; draw < 60; ++draw) {
    PinholeIntrinsics k;
    k.width = std::uniform_int_distribution<int>(1, 41)(rng);
    k.height = std::uniform_int_distribution<int>(1, 33)(rng);
    k.fx = std::uniform_real_distribution<double>(5.0, 600.0)(rng);
    k.fy = std::uniform_real_distribution<double>(5.0, 600.0)(rng) * (draw % 5 == 0 ? -1 : 1);
    k.cx = std::uniform_real_distribution<double>(0.0, k.width)(rng);
    k.cy = std::uniform_real_distribution<double>(0.0, k.height)(rng);
    const DepthProjector projector(k, 5000.0, 0.3, draw % 2 ? 8.0 : 0.0);
    Image16 depth(k.width, k.height);
    std::uniform_int_distribution<int> raw(0, 65535);
    for (auto& d : depth.data) d = static_cast<std::uint16_t>(rng() % 4 == 0 ? 0 : raw(rng));
    OrganizedCloud full;
    projector.Project(depth, &full);
    for (int factor = 1; factor <= 16; ++factor) {
      const OrganizedCloud expected = Decimate(full, factor);
      OrganizedCloud cloud;
      projector.Project(depth.data.data(), depth.width, depth.height, &cloud, "d.png", factor);
      ASSERT_EQ(cloud.width, expected.width) << "draw " << draw << " factor " << factor;
      ASSERT_EQ(cloud.height, expected.height) << "draw " << draw << " factor " << factor;
      EXPECT_EQ(cloud.model, SensorModel::kPinhole);
      for (std::size_t i = 0; i < cloud.points.size(); ++i) {
        ASSERT_TRUE(SamePoint(cloud.points[i], expected.points[i]))
            << "draw " << draw << " factor " << factor << " point " << i;
      }
    }
  }
}

TEST(DepthImage, ReadsPngWrittenToDisk) {
  const auto dir = test::ScratchDir();
  const PinholeIntrinsics k = SmallCamera();
  Image16 depth(k.width, k.height);
  for (std::size_t i = 0; i < depth.data.size(); ++i)
    depth.data[i] = static_cast<std::uint16_t>(i * 100);
  const std::string path = (dir / "d.png").string();
  WritePng16(path, depth);
  const OrganizedCloud cloud = ReadDepthCloud(path, k, 1000.0);
  EXPECT_EQ(cloud.CountValid(), depth.data.size() - 1);
  EXPECT_FLOAT_EQ(cloud.points[5].z(), 0.5f);
}

}  // namespace
}  // namespace planeslam::datasets
