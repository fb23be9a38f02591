#include "planeslam/datasets/organized_cloud.hpp"

#include <gtest/gtest.h>

#include "planeslam/datasets/depth_image.hpp"
#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {
namespace {

TEST(OrganizedCloudDecimate, KeepsEveryFactorthRowAndColumnIncludingTheLastPartialOnes) {
  OrganizedCloud cloud(7, 5, SensorModel::kSpherical);
  for (int y = 0; y < cloud.height; ++y) {
    for (int x = 0; x < cloud.width; ++x) cloud.at(y, x) = Eigen::Vector3f(x, y, 1.0f);
  }
  const OrganizedCloud half = Decimate(cloud, 2);
  ASSERT_EQ(half.width, 4);   // columns 0, 2, 4, 6
  ASSERT_EQ(half.height, 3);  // rows 0, 2, 4
  EXPECT_EQ(half.model, SensorModel::kSpherical);
  for (int y = 0; y < half.height; ++y) {
    for (int x = 0; x < half.width; ++x) {
      EXPECT_EQ(half.at(y, x), Eigen::Vector3f(2 * x, 2 * y, 1.0f)) << x << "," << y;
    }
  }
  const OrganizedCloud same = Decimate(cloud, 1);
  EXPECT_EQ(same.width, 7);
  EXPECT_EQ(same.points, cloud.points);
  EXPECT_THROW(Decimate(cloud, 0), CheckError);
  EXPECT_THROW(Decimate(cloud, 17), CheckError);
}

TEST(OrganizedCloudDecimate, DecimatedIntrinsicsBackProjectTheKeptPixelsToTheSamePoints) {
  PinholeIntrinsics k;  // TUM fr3
  Image16 depth(k.width, k.height);
  auto pixel = [](Image16& image, int u, int v) -> std::uint16_t& {
    return image.data[static_cast<std::size_t>(v) * image.width + u];
  };
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u)
      pixel(depth, u, v) = static_cast<std::uint16_t>(5000 + 7 * u + 3 * v);
  }
  pixel(depth, 9, 21) = 0;  // a kept pixel without depth stays invalid
  const int f = 3;
  Image16 small((k.width + f - 1) / f, (k.height + f - 1) / f);
  for (int v = 0; v < small.height; ++v) {
    for (int u = 0; u < small.width; ++u) pixel(small, u, v) = pixel(depth, f * u, f * v);
  }
  const OrganizedCloud decimated = Decimate(DepthToCloud(depth, k, 5000.0), f);
  const PinholeIntrinsics ks = DecimateIntrinsics(k, f);
  EXPECT_EQ(ks.width, small.width);
  EXPECT_EQ(ks.height, small.height);
  const OrganizedCloud direct = DepthToCloud(small, ks, 5000.0);
  ASSERT_EQ(decimated.size(), direct.size());
  EXPECT_FALSE(direct.IsValid(7 * static_cast<std::size_t>(small.width) + 3));
  for (std::size_t i = 0; i < direct.size(); ++i) {
    ASSERT_EQ(decimated.IsValid(i), direct.IsValid(i)) << i;
    if (direct.IsValid(i)) {
      EXPECT_LT((decimated.points[i] - direct.points[i]).norm(), 1e-5f) << i;
    }
  }
}

}  // namespace
}  // namespace planeslam::datasets
