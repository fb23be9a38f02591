// The organized PCDs planeslam writes (`planeslam simulate --sensor spherical`, datasets::WritePcd)
// open in PCL's own reader with their grid, their missing points and their colours.
#include <gtest/gtest.h>
#include <pcl/common/io.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "planeslam/datasets/pcd_io.hpp"
#include "test_support.hpp"

namespace planeslam::datasets {
namespace {

TEST(PcdFiles, OrganizedCloudWithHolesAndColoursOpensInPcl) {
  // 5 x 3 grid, point (row, col) = (col, row, 2 + 0.25 col) except two missing points.
  OrganizedCloud cloud(5, 3, SensorModel::kSpherical);
  std::vector<std::uint32_t> rgb(cloud.size());
  for (int row = 0; row < cloud.height; ++row) {
    for (int col = 0; col < cloud.width; ++col) {
      cloud.at(row, col) = Eigen::Vector3f(static_cast<float>(col), static_cast<float>(row),
                                           2.0f + 0.25f * static_cast<float>(col));
      rgb[static_cast<std::size_t>(row) * cloud.width + col] =
          0x010203u * static_cast<std::uint32_t>(row * cloud.width + col + 1);
    }
  }
  cloud.at(1, 2) = Eigen::Vector3f::Constant(std::nanf(""));
  cloud.at(2, 4) = Eigen::Vector3f::Constant(std::nanf(""));
  const auto dir = test::ScratchDir();
  for (const bool with_rgb : {false, true}) {
    const std::string path = (dir / (with_rgb ? "rgb.pcd" : "xyz.pcd")).string();
    WritePcd(path, cloud, with_rgb ? &rgb : nullptr);
    pcl::PointCloud<pcl::PointXYZRGB> read;
    if (with_rgb) {
      ASSERT_EQ(pcl::io::loadPCDFile(path, read), 0) << path;
    } else {  // read as x y z only (no "missing rgb" notice)
      pcl::PointCloud<pcl::PointXYZ> xyz;
      ASSERT_EQ(pcl::io::loadPCDFile(path, xyz), 0) << path;
      pcl::copyPointCloud(xyz, read);
    }
    ASSERT_EQ(read.width, 5u);
    ASSERT_EQ(read.height, 3u);
    EXPECT_FALSE(read.is_dense);  // missing points keep their place in the grid
    for (int row = 0; row < cloud.height; ++row) {
      for (int col = 0; col < cloud.width; ++col) {
        const pcl::PointXYZRGB& p = read.at(col, row);
        const Eigen::Vector3f& q = cloud.at(row, col);
        if (!std::isfinite(q.z())) {
          EXPECT_FALSE(std::isfinite(p.z)) << row << " " << col;
          continue;
        }
        EXPECT_EQ(p.x, q.x());
        EXPECT_EQ(p.y, q.y());
        EXPECT_EQ(p.z, q.z());
        if (with_rgb) {
          const std::uint32_t c = rgb[static_cast<std::size_t>(row) * cloud.width + col];
          EXPECT_EQ(p.r, (c >> 16) & 0xff);
          EXPECT_EQ(p.g, (c >> 8) & 0xff);
          EXPECT_EQ(p.b, c & 0xff);
        }
      }
    }
  }
}

}  // namespace
}  // namespace planeslam::datasets
