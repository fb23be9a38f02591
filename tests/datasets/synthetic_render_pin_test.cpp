// The rendered frames of the built-in scenes are pinned bit for bit: a change to the ray caster
// that is meant to be faster only must leave every depth, label and true range as it was.
#include <gtest/gtest.h>

#include <cstdint>
#include <string>

#include "planeslam/datasets/synthetic_sequence.hpp"

namespace planeslam::datasets {
namespace {

std::uint64_t Fnv1a(const void* data, std::size_t size, std::uint64_t h) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < size; ++i) {
    h ^= bytes[i];
    h *= 1099511628211ULL;
  }
  return h;
}

/// FNV-1a over every 20th frame's points, labels, true ranges and intensities.
std::uint64_t RenderHash(SceneKind scene) {
  const SyntheticSequence sequence(SyntheticConfig::ForScene(scene));
  std::uint64_t h = 1469598103934665603ULL;
  for (std::size_t i = 0; i < sequence.Size(); i += 20) {
    const SyntheticFrame f = sequence.Generate(i);
    const auto& points = f.frame.cloud.points;
    h = Fnv1a(points.data(), points.size() * sizeof(points[0]), h);
    h = Fnv1a(f.labels.data.data(), f.labels.data.size() * sizeof(std::uint16_t), h);
    h = Fnv1a(f.true_range.data(), f.true_range.size() * sizeof(float), h);
    h = Fnv1a(f.intensity.data(), f.intensity.size() * sizeof(float), h);
  }
  return h;
}

// Pinned values: IEEE double arithmetic without FMA contraction (x86-64 baseline), the same with
// GCC and Clang. Room: polygons; corridor: long polygons; rubble: disks, spheres and cylinders.
TEST(SyntheticRenderPin, BuiltInScenesRenderBitForBitAsPinned) {
  EXPECT_EQ(RenderHash(SceneKind::kRoom), 0xe6b55d258d579b85ULL);
  EXPECT_EQ(RenderHash(SceneKind::kCorridor), 0x0f2287df55ae9e72ULL);
  EXPECT_EQ(RenderHash(SceneKind::kRubble), 0xcf0a17b607847c51ULL);
}

}  // namespace
}  // namespace planeslam::datasets
