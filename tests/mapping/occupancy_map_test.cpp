// OctoMap output: a wall seen from a known pose is occupied, the space in front free, behind it
// unknown, in the map built and in the .bt file read back by OctoMap.
#include "planeslam/mapping/occupancy_map.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <random>
#include <sstream>
#include <string>

#include "planeslam/datasets/errors.hpp"
#include "test_support.hpp"

#ifdef PLANESLAM_HAVE_OCTOMAP
#include <octomap/OcTree.h>
#endif

namespace planeslam::mapping {
namespace {

/// A 2 x 2 m wall at sensor z = `depth`, points every 1 cm, plus a NaN.
std::vector<Eigen::Vector3f> Wall(float depth) {
  std::vector<Eigen::Vector3f> pts;
  for (int i = 0; i < 200; ++i) {
    for (int j = 0; j < 200; ++j) pts.emplace_back(-1.0f + 0.01f * i, -1.0f + 0.01f * j, depth);
  }
  pts.emplace_back(Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN()));
  return pts;
}

Pose SomePose() {
  Pose T = Pose::Identity();
  T.linear() =
      Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.2, 1.0, -0.3).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(1.5, -2.0, 0.7);
  return T;
}

TEST(OccupancyMap, ConfigValidation) {
  EXPECT_TRUE(OccupancyMapConfig().Validate().empty());
  OccupancyMapConfig c;
  c.prob_hit = 0.4;
  c.resolution = 0;
  EXPECT_EQ(c.Validate().size(), 2u);
  EXPECT_THROW(OccupancyMapBuilder{c}, CheckError);
}

TEST(OccupancyMap, VoxelDownsampleKeepsOneCentroidPerVoxel) {
  const auto pts = Wall(2.0f);
  const auto down = VoxelDownsample(pts, 0.1);
  // 2 x 2 m in 10 cm voxels at one depth: 20 x 20 voxels (2.0 / 0.1 is a voxel boundary).
  EXPECT_EQ(down.size(), 400u);
  for (const auto& p : down) {
    EXPECT_NEAR(p.z(), 2.0f, 1e-5f);
    // A voxel's centroid of a 1 cm lattice lies at the voxel centre within half a spacing.
    const double cx = (std::floor(p.x() / 0.1) + 0.5) * 0.1;
    EXPECT_NEAR(p.x(), cx, 0.0051);
  }
  EXPECT_THROW(VoxelDownsample(pts, 0.0), CheckError);
}

TEST(OccupancyMap, VoxelDownsampleMatchesAReferenceOnRandomClouds) {
  // 30 clouds of scattered and clustered points on both sides of every axis, with invalid
  // points: the centroids of the voxels in (x, y, z) voxel order, each summed in input order,
  // bit for bit.
  std::mt19937 rng(3);
  for (int draw = 0; draw < 30; ++draw) {
    std::uniform_real_distribution<float> spread(-3.0f + draw, 3.0f + 2.0f * draw);
    std::normal_distribution<float> jitter(0.0f, 0.02f);
    std::vector<Eigen::Vector3f> pts;
    for (int i = 0; i < 4000; ++i) {
      Eigen::Vector3f p;
      for (int a = 0; a < 3; ++a) p(a) = spread(rng);
      const int copies = 1 + i % 5;  // clusters: several points in a voxel
      for (int c = 0; c < copies; ++c) {
        Eigen::Vector3f q = p;
        for (int a = 0; a < 3; ++a) q(a) += jitter(rng);
        pts.push_back(q);
      }
      if (i % 97 == 0) pts.push_back(Eigen::Vector3f::Constant(std::nanf("")));
    }
    const double voxel = 0.05 + 0.01 * (draw % 7);
    // Points on voxel boundaries and one float either side of them, and at the edge of the
    // voxel index range (2^20 voxels from the origin), where a product rounds unlike the
    // quotient.
    std::uniform_int_distribution<int> cell(-200, 200);
    for (int i = 0; i < 2000; ++i) {
      Eigen::Vector3f p;
      for (int a = 0; a < 3; ++a) {
        const double k = i % 50 == 0 ? std::ldexp(1.0, 20) * (cell(rng) < 0 ? -1 : 1) : cell(rng);
        p(a) = static_cast<float>(k * voxel);
        const int side = cell(rng) % 3;
        if (side != 0) p(a) = std::nextafter(p(a), side > 0 ? 1e30f : -1e30f);
      }
      pts.push_back(p);
    }
    std::map<std::array<std::int64_t, 3>, std::pair<Eigen::Vector3d, int>> reference;
    for (const Eigen::Vector3f& p : pts) {
      if (!p.allFinite()) continue;
      std::array<std::int64_t, 3> key;
      bool inside = true;
      for (int a = 0; a < 3; ++a) {
        key[a] = static_cast<std::int64_t>(std::floor(p[a] / voxel));
        inside = inside && key[a] >= -(1 << 20) && key[a] < (1 << 20);
      }
      if (!inside) continue;
      auto& [sum, count] = reference.try_emplace(key, Eigen::Vector3d::Zero(), 0).first->second;
      sum += p.cast<double>();
      ++count;
    }
    const auto down = VoxelDownsample(pts, voxel);
    ASSERT_EQ(down.size(), reference.size()) << "draw " << draw;
    std::size_t k = 0;
    for (const auto& [key, value] : reference) {
      const Eigen::Vector3f expected = (value.first / value.second).cast<float>();
      ASSERT_TRUE(down[k] == expected) << "draw " << draw << " voxel " << k;
      ++k;
    }
  }
}

TEST(OccupancyMap, WallIsOccupiedFrontFreeBehindUnknownAndSurvivesTheFile) {
  const auto dir = test::ScratchDir();
  const std::string path = (dir / "map.bt").string();
  OccupancyMapConfig config;
  config.resolution = 0.05;
  OccupancyMapBuilder builder(config);
  if (!OccupancyMapBuilder::available()) {
    EXPECT_THROW(builder.Write(path), IoError);
    GTEST_SKIP() << "built without OctoMap";
  }
  const Pose T = SomePose();
  builder.Insert(Wall(2.0f), T);
  const Eigen::Vector3d on_wall = T * Eigen::Vector3d(0.1, 0.1, 2.0);
  const Eigen::Vector3d in_front = T * Eigen::Vector3d(0.1, 0.1, 1.0);
  const Eigen::Vector3d behind = T * Eigen::Vector3d(0.1, 0.1, 2.5);
  EXPECT_EQ(builder.Query(on_wall), Occupancy::kOccupied);
  EXPECT_EQ(builder.Query(in_front), Occupancy::kFree);
  EXPECT_EQ(builder.Query(behind), Occupancy::kUnknown);
  const OccupancyMapStats stats = builder.Stats();
  EXPECT_EQ(stats.inserted_frames, 1u);
  EXPECT_EQ(stats.inserted_points, 40u * 40u);  // 5 cm downsampling of the 2 x 2 m wall
  // The wall is about 40 x 40 leaves (a tilted plane can cover up to ~2x as many voxels).
  EXPECT_GT(stats.occupied_leaves, 1400u);
  EXPECT_LT(stats.occupied_leaves, 4000u);
  EXPECT_GT(stats.free_leaves, 0u);

  builder.Write(path);
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    EXPECT_EQ(entry.path().filename(), "map.bt");  // no temporary file left
  }
  const OccupancyMapBuilder loaded = OccupancyMapBuilder::Load(path);
  EXPECT_DOUBLE_EQ(loaded.resolution(), 0.05);
  EXPECT_EQ(loaded.Query(on_wall), Occupancy::kOccupied);
  EXPECT_EQ(loaded.Query(in_front), Occupancy::kFree);
  EXPECT_EQ(loaded.Query(behind), Occupancy::kUnknown);
  EXPECT_EQ(loaded.Stats().occupied_leaves + loaded.Stats().free_leaves > 0, true);

#ifdef PLANESLAM_HAVE_OCTOMAP
  // And with OctoMap's own reader directly.
  octomap::OcTree tree(0.1);
  ASSERT_TRUE(tree.readBinary(path));
  EXPECT_DOUBLE_EQ(tree.getResolution(), 0.05);
  const octomap::OcTreeNode* node = tree.search(on_wall.x(), on_wall.y(), on_wall.z());
  ASSERT_NE(node, nullptr);
  EXPECT_TRUE(tree.isNodeOccupied(node));
#endif
}

#ifdef PLANESLAM_HAVE_OCTOMAP
/// Points on the walls, floor and ceiling of a box room (half-size `half` m, 3.5 m high) and in
/// the air inside it, seen from `origin`: in the sensor frame of an unrotated sensor there.
std::vector<Eigen::Vector3f> RoomScan(std::mt19937& rng, float half, int points,
                                      const Eigen::Vector3f& origin) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::uniform_int_distribution<int> face(0, 6);
  std::vector<Eigen::Vector3f> scan;
  for (int i = 0; i < points; ++i) {
    Eigen::Vector3f p(half * u(rng), half * u(rng), 1.75f * u(rng));
    const int f = face(rng);  // 0-3 walls, 4 floor, 5 ceiling, 6 clutter in the air
    if (f < 4) p[f / 2] = f % 2 == 0 ? -half : half;
    if (f == 4 || f == 5) p.z() = f == 4 ? -1.75f : 1.75f;
    scan.push_back(p - origin);
  }
  return scan;
}

std::string PrunedBinary(octomap::OcTree& tree) {
  tree.updateInnerOccupancy();
  tree.prune();
  std::ostringstream out;
  tree.writeBinaryConst(out);
  return out.str();
}

std::string FileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// OctoMap's tree with the builder's hit and miss probabilities.
octomap::OcTree ReferenceTree(const OccupancyMapConfig& config) {
  octomap::OcTree tree(config.resolution);
  tree.setProbHit(config.prob_hit);
  tree.setProbMiss(config.prob_miss);
  return tree;
}

// Runs `check` with the rays walked four at a time (AVX2, where the processor has it), then one
// at a time, and leaves the default on.
template <typename Check>
void WithEachRayWalk(Check&& check) {
  for (const bool vector_walk : {true, false}) {
    SCOPED_TRACE(vector_walk ? "vector ray walk" : "scalar ray walk");
    internal::SetVectorRayWalk(vector_walk);
    check();
  }
  internal::SetVectorRayWalk(true);
}

// The builder against OctoMap over the random scans described below.
void ExpectInsertAllMatchesOctomap() {
  const auto dir = test::ScratchDir();
  const std::string path = (dir / "map.bt").string();
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  constexpr int kDraws = 10;
  for (int draw = 0; draw < kDraws; ++draw) {
    const bool huge = draw == kDraws - 1;
    OccupancyMapConfig config;
    config.resolution = huge ? 0.005 : std::array<double, 3>{0.05, 0.1, 0.2}[draw % 3];
    config.max_range = draw % 4 == 0 ? 0.0 : 2.0 + 3.0 * (u(rng) + 1.0f);
    config.downsample_voxel = 0.0;  // octomap's insertPointCloud does not thin
    const float half = huge ? 6.0f : 1.5f + 1.5f * (u(rng) + 1.0f);
    OccupancyMapBuilder builder(config);
    octomap::OcTree reference = ReferenceTree(config);
    for (int batch = 0; batch < 2; ++batch) {
      std::vector<std::vector<Eigen::Vector3f>> scans;
      std::vector<Pose> poses;
      for (int s = 0; s < (huge ? 1 : 4); ++s) {
        const Eigen::Vector3f origin(0.5f * half * u(rng), 0.5f * half * u(rng), 0.5f * u(rng));
        scans.push_back(RoomScan(rng, half, huge ? 100 : 1000, origin));
        Pose T = Pose::Identity();
        T.translation() = origin.cast<double>();
        poses.push_back(T);
        // An unrotated pose: the world points are p + origin in float, as the builder forms them.
        octomap::Pointcloud cloud;
        for (const Eigen::Vector3f& p : scans.back()) {
          const Eigen::Vector3f w = p + origin;
          cloud.push_back(w.x(), w.y(), w.z());
        }
        reference.insertPointCloud(cloud, octomap::point3d(origin.x(), origin.y(), origin.z()),
                                   config.max_range > 0 ? config.max_range : -1.0, true, true);
      }
      std::vector<const std::vector<Eigen::Vector3f>*> pointers;
      for (const auto& scan : scans) pointers.push_back(&scan);
      builder.InsertAll(pointers, poses, 1 + draw % 2);
      builder.Write(path);  // prunes the builder's tree before the second batch
      ASSERT_EQ(FileBytes(path), PrunedBinary(reference)) << "draw " << draw << " batch " << batch;
    }
  }
}

// The builder's own ray casting and lazy updates against OctoMap's insertPointCloud (discretized,
// lazy), bit for bit in the written file: random rooms seen from random places, at several
// resolutions, with and without max_range, and half of the scans inserted after the map was
// pruned by a write. The last draw's rays span a box too large for the bitmap of free cells.
// Both ray walks: four rays at a time (AVX2, where the processor has it) and one at a time.
TEST(OccupancyMap, InsertAllMatchesOctomapsInsertPointCloudOverRandomScans) {
  WithEachRayWalk(ExpectInsertAllMatchesOctomap);
}

// Rays from a cell centre to cell centres along the lattice's diagonals step across two or three
// cell borders at exactly the same distance: which cell comes first is octomap's tie-break, and
// both walks must take it.
TEST(OccupancyMap, DiagonalRaysBreakTiesAsOctomapDoes) {
  const auto dir = test::ScratchDir();
  const std::string path = (dir / "map.bt").string();
  OccupancyMapConfig config;
  config.resolution = 0.1;
  config.max_range = 0.0;
  config.downsample_voxel = 0.0;
  const float centre = 0.05f;  // a cell centre on every axis
  const Eigen::Vector3f origin = Eigen::Vector3f::Constant(centre);
  // Ends only on the diagonals (m, m, 0), (m, 0, m), (0, m, m) and (m, m, m) with every sign, so
  // that the cells beside a diagonal are free or unknown depending on the tie-break.
  std::vector<Eigen::Vector3f> scan;
  for (const int m : {3, 7, 12}) {
    for (int signs = 0; signs < 8; ++signs) {
      const float sx = signs & 1 ? -1.0f : 1.0f, sy = signs & 2 ? -1.0f : 1.0f,
                  sz = signs & 4 ? -1.0f : 1.0f, d = 0.1f * m;
      scan.emplace_back(sx * d, sy * d, 0.0f);
      scan.emplace_back(sx * d, 0.0f, sz * d);
      scan.emplace_back(0.0f, sy * d, sz * d);
      scan.emplace_back(sx * d, sy * d, sz * d);
    }
  }
  octomap::OcTree reference = ReferenceTree(config);
  octomap::Pointcloud cloud;
  for (const Eigen::Vector3f& p : scan) {
    const Eigen::Vector3f w = p + origin;
    cloud.push_back(w.x(), w.y(), w.z());
  }
  reference.insertPointCloud(cloud, octomap::point3d(centre, centre, centre), -1.0, true, true);
  Pose T = Pose::Identity();
  T.translation() = origin.cast<double>();
  WithEachRayWalk([&] {
    OccupancyMapBuilder builder(config);
    builder.Insert(scan, T);
    builder.Write(path);
    EXPECT_EQ(FileBytes(path), PrunedBinary(reference));
  });
}

// A cell that misses have driven to the lower clamping bound is skipped by later misses until a
// hit raises it: the hit and the misses after it must count as in OctoMap.
TEST(OccupancyMap, ClampedFreeCellsFollowLaterHitsAsOctomapDoes) {
  const auto dir = test::ScratchDir();
  const std::string path = (dir / "map.bt").string();
  OccupancyMapConfig config;
  config.max_range = 0.0;
  config.downsample_voxel = 0.0;
  OccupancyMapBuilder builder(config);
  octomap::OcTree reference = ReferenceTree(config);
  std::vector<Eigen::Vector3f> wall = Wall(2.0f);
  wall.pop_back();  // the NaN: octomap's insertPointCloud takes finite points
  const std::vector<Eigen::Vector3f> in_front = {Eigen::Vector3f(0.1f, 0.1f, 1.0f)};
  const auto insert = [&](const std::vector<Eigen::Vector3f>& scan) {
    builder.Insert(scan, Pose::Identity());
    octomap::Pointcloud cloud;
    for (const Eigen::Vector3f& p : scan) cloud.push_back(p.x(), p.y(), p.z());
    reference.insertPointCloud(cloud, octomap::point3d(0, 0, 0), -1.0, true, true);
  };
  // The cells in front reach the lower bound; three hits make one of them occupied, and two
  // misses free again (log-odds -2, +0.54, -0.27: the file holds only the classification).
  for (int k = 0; k < 6; ++k) insert(wall);
  for (int k = 0; k < 3; ++k) insert(in_front);
  EXPECT_EQ(builder.Query(Eigen::Vector3d(0.1, 0.1, 1.0)), Occupancy::kOccupied);
  for (int k = 0; k < 2; ++k) insert(wall);
  builder.Write(path);
  EXPECT_EQ(FileBytes(path), PrunedBinary(reference));
  EXPECT_EQ(builder.Query(Eigen::Vector3d(0.1, 0.1, 1.0)), Occupancy::kFree);
}
#endif

TEST(OccupancyMap, RaysBeyondMaxRangeOnlyClearUpToIt) {
  if (!OccupancyMapBuilder::available()) GTEST_SKIP() << "built without OctoMap";
  OccupancyMapConfig config;
  config.max_range = 3.0;
  OccupancyMapBuilder builder(config);
  builder.Insert(Wall(4.0f), Pose::Identity());
  EXPECT_EQ(builder.Query(Eigen::Vector3d(0.1, 0.1, 4.0)), Occupancy::kUnknown);
  EXPECT_EQ(builder.Query(Eigen::Vector3d(0.1, 0.1, 2.5)), Occupancy::kFree);
  EXPECT_EQ(builder.Query(Eigen::Vector3d(0.1, 0.1, 3.5)), Occupancy::kUnknown);
  EXPECT_EQ(builder.Stats().occupied_leaves, 0u);
}

TEST(OccupancyMap, OrganizedCloudInsertSkipsInvalidPixels) {
  if (!OccupancyMapBuilder::available()) GTEST_SKIP() << "built without OctoMap";
  // A 100 x 100 cloud of the wall at z = 2, every other row invalid (NaN).
  datasets::OrganizedCloud cloud(100, 100);
  for (int r = 0; r < 100; r += 2) {
    for (int c = 0; c < 100; ++c)
      cloud.at(r, c) = Eigen::Vector3f(-1.0f + 0.02f * c, -1.0f + 0.02f * r, 2.0f);
  }
  OccupancyMapBuilder builder;
  builder.Insert(cloud, SomePose());
  // 5 cm voxels over the 2 x 2 m wall: 40 x 40 voxels (rows every 4 cm still reach every voxel
  // row).
  EXPECT_EQ(builder.Stats().inserted_points, 40u * 40u);
  EXPECT_EQ(builder.Query(SomePose() * Eigen::Vector3d(0.1, 0.1, 2.0)), Occupancy::kOccupied);
}

TEST(OccupancyMap, LoadRejectsOtherFiles) {
  if (!OccupancyMapBuilder::available()) GTEST_SKIP() << "built without OctoMap";
  const auto dir = test::ScratchDir();
  const std::string path = (dir / "not.bt").string();
  std::ofstream(path) << "ply\nformat ascii 1.0\n";
  EXPECT_THROW(OccupancyMapBuilder::Load(path), IoError);
  EXPECT_THROW(OccupancyMapBuilder::Load((dir / "missing.bt").string()), IoError);
}

}  // namespace
}  // namespace planeslam::mapping
