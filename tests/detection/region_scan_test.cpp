// The label-image border scan (ScanLabelImage, which passes over four pixels at a time) against
// a plain pixel-by-pixel reference, and MomentSums::SetSum against a copy and Add.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <random>
#include <vector>

#include "fast_moments.hpp"   // private to detection (detection/src)
#include "region_common.hpp"  // likewise
#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/detection/detection_config.hpp"

namespace planeslam::detection {
namespace {

/// The borders of a label image by the definition: every pixel pair (right, down) of two
/// different regions, both pixels listed once in the order first met, pairs sorted and unique.
internal::RegionBorders ReferenceBorders(const std::vector<std::int32_t>& labels, int width,
                                         int height) {
  internal::RegionBorders out;
  std::vector<char> listed(labels.size(), 0);
  auto list = [&](std::size_t i) {
    if (!listed[i]) out.pixels.push_back(i);
    listed[i] = 1;
  };
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * width + x;
      const std::int32_t r = labels[i];
      if (r < 0) continue;
      for (const std::size_t j : {x + 1 < width ? i + 1 : i, y + 1 < height ? i + width : i}) {
        if (j == i || labels[j] < 0 || labels[j] == r) continue;
        list(i);
        list(j);
        const auto lo = static_cast<std::uint64_t>(std::min(r, labels[j]));
        const auto hi = static_cast<std::uint64_t>(std::max(r, labels[j]));
        out.pairs.push_back(lo << 32 | hi);
      }
    }
  }
  std::sort(out.pairs.begin(), out.pairs.end());
  out.pairs.erase(std::unique(out.pairs.begin(), out.pairs.end()), out.pairs.end());
  return out;
}

// Random label images of blocks (regions with straight and ragged borders, holes of -1), of
// widths below, at and above the four-pixel step, and every remainder modulo four.
TEST(RegionScan, BordersMatchPixelByPixelReference) {
  std::mt19937 rng(35);
  const DetectionParams params;
  for (int draw = 0; draw < 300; ++draw) {
    const int width = 1 + static_cast<int>(rng() % 23), height = 1 + static_cast<int>(rng() % 9);
    const int block = 1 + static_cast<int>(rng() % 4);
    const int regions = 1 + static_cast<int>(rng() % 5);
    std::vector<std::int32_t> labels(static_cast<std::size_t>(width) * height);
    for (int y = 0; y < height; ++y) {
      for (int x = 0; x < width; ++x) {
        const std::uint32_t cell = static_cast<std::uint32_t>((y / block) * 7 + x / block);
        std::int32_t label = static_cast<std::int32_t>((cell * 2654435761u) % (regions + 1)) - 1;
        if (rng() % 10 == 0) label = static_cast<std::int32_t>(rng() % (regions + 1)) - 1;
        labels[static_cast<std::size_t>(y) * width + x] = label;
      }
    }
    datasets::OrganizedCloud cloud(width, height);
    const internal::RegionBorders got =
        internal::ScanLabelImage(cloud, labels, regions, params, nullptr);
    const internal::RegionBorders want = ReferenceBorders(labels, width, height);
    ASSERT_EQ(got.pixels, want.pixels) << "draw " << draw << ", " << width << " x " << height;
    ASSERT_EQ(got.pairs, want.pairs) << "draw " << draw << ", " << width << " x " << height;
  }
}

TEST(RegionScan, SetSumEqualsCopyAndAddBitForBit) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(-5.0, 5.0);
  MomentSums region;
  for (int i = 0; i < 50; ++i) region.Add(uni(rng), uni(rng), uni(rng) + 6.0, 1e-4 * (1 + i));
  for (int i = 0; i < 100; ++i) {
    const double x = uni(rng), y = uni(rng), z = uni(rng) + 6.0, w = 1e-5 * (i + 1);
    MomentSums copied = region;
    copied.Add(x, y, z, w);
    MomentSums summed;
    summed.SetSum(region, x, y, z, w);
    EXPECT_EQ(std::memcmp(&copied, &summed, sizeof(MomentSums)), 0) << "point " << i;
    region = summed;
  }
}

}  // namespace
}  // namespace planeslam::detection
