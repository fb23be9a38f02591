// The local map's voxel hash against std::unordered_map on random keys, through growth, its
// bitmap of occupied voxels, and the voxel coordinate taken without a division.
#include "planeslam/registration/voxel_index.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <random>
#include <tuple>
#include <vector>

namespace planeslam::registration {
namespace {

TEST(LocalMapVoxelIndex, AgreesWithAStandardMapOnRandomKeys) {
  std::mt19937 rng(7);
  for (const int spread : {3, 40, 100000}) {  // dense repeats to nearly unique keys
    std::uniform_int_distribution<int> coord(-spread, spread);
    VoxelIndex index(4);  // grows many times
    std::map<std::tuple<int, int, int>, int> reference;
    for (int i = 0; i < 20000; ++i) {
      const Eigen::Vector3i key(coord(rng), coord(rng), coord(rng));
      bool inserted = false;
      const int got = index.Insert(key, &inserted);
      const auto [it, fresh] =
          reference.emplace(std::make_tuple(key.x(), key.y(), key.z()),
                            static_cast<int>(reference.size()));
      ASSERT_EQ(inserted, fresh);
      ASSERT_EQ(got, it->second);
    }
    EXPECT_EQ(index.size(), static_cast<int>(reference.size()));
    for (const auto& [key, value] : reference) {
      EXPECT_EQ(index.Find({std::get<0>(key), std::get<1>(key), std::get<2>(key)}), value);
    }
    EXPECT_EQ(index.Find({spread + 1, 0, 0}), -1);
    index.Reset(0);
    EXPECT_EQ(index.size(), 0);
    EXPECT_EQ(index.Find({0, 0, 0}), -1);
  }
}

TEST(LocalMapVoxelIndex, BitmapHasNoFalseClearsAndFewFalseSets) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> coord(-100000, 100000);
  VoxelBitmap<16> bitmap;
  std::vector<Eigen::Vector3i> set;
  for (int i = 0; i < 3000; ++i) {
    set.emplace_back(coord(rng), coord(rng), coord(rng));
    bitmap.Set(set.back());
  }
  for (const Eigen::Vector3i& key : set) ASSERT_TRUE(bitmap.MaybeSet(key));
  // Keys never set: about 3000 / 65536 = 4.6 % read as set; neighbours of set keys (what the
  // searches ask for) must not collide more than random keys do.
  int false_sets = 0, trials = 0;
  for (const Eigen::Vector3i& key : set) {
    for (const Eigen::Vector3i& step : {Eigen::Vector3i(1, 0, 0), Eigen::Vector3i(0, 1, 0),
                                        Eigen::Vector3i(0, 0, 1), Eigen::Vector3i(1, 1, 1)}) {
      ++trials;
      false_sets += bitmap.MaybeSet(key + step) ? 1 : 0;
    }
  }
  EXPECT_LT(false_sets, 0.08 * trials);
  bitmap.Clear();
  for (const Eigen::Vector3i& key : set) ASSERT_FALSE(bitmap.MaybeSet(key));
}

}  // namespace
// FloorDivToInt must be exactly FloorToInt(x / size): over random sizes and coordinates, and
// at coordinates on and one ulp either side of voxel boundaries, where the product and the
// quotient round differently most often. No failure allowed.
TEST(LocalMapVoxelIndex, FloorWithoutDivisionIsTheQuotientsFloor) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> log_size(std::log(0.001), std::log(10.0));
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_int_distribution<int> cell(-200000, 200000);
  int boundary_draws = 0, product_off = 0;
  for (int draw = 0; draw < 200000; ++draw) {
    const double size = std::exp(log_size(rng));
    const double inverse = 1.0 / size;
    const double on_boundary = cell(rng) * size;
    for (const double x : {unit(rng) * 2000.0, on_boundary, std::nextafter(on_boundary, -1e300),
                           std::nextafter(on_boundary, 1e300)}) {
      const int expected = FloorToInt(x / size);
      ASSERT_EQ(FloorDivToInt(x, size, inverse), expected)
          << "x " << x << " size " << size << " draw " << draw;
      product_off += FloorToInt(x * inverse) != expected ? 1 : 0;
    }
    ++boundary_draws;
  }
  // The boundary cases must include ones where the plain product would have been wrong.
  EXPECT_GT(product_off, 0) << boundary_draws << " draws";
}

}  // namespace planeslam::registration
