// The street scene, its route and the rotating LiDAR: geometry checked against the brute-force
// ray intersection, the KITTI layout read back bit for bit, and determinism.
#include "planeslam/datasets/synthetic_street.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "planeslam/datasets/kitti_scan.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "planeslam/datasets/synthetic_lidar.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"
#include "planeslam/datasets/synthetic_writer.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "test_support.hpp"

namespace planeslam::datasets {
namespace {

namespace fs = std::filesystem;
constexpr double kPi = 3.14159265358979323846;

std::string Slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

SyntheticConfig Street(int frames) {
  SyntheticConfig c = SyntheticConfig::ForScene(SceneKind::kStreet);
  c.trajectory.frames = frames;
  return c;
}

TEST(StreetScene, PlaneIdsAndDeterminism) {
  const SyntheticScene a = MakeStreetScene(1), b = MakeStreetScene(1), c = MakeStreetScene(2);
  ASSERT_GT(a.planes.size(), 1000u);
  ASSERT_LT(a.planes.size(), 65535u);
  for (std::size_t k = 0; k < a.planes.size(); ++k) {
    EXPECT_EQ(a.planes[k].id, static_cast<int>(k) + 1);
    EXPECT_NEAR(a.planes[k].normal.norm(), 1.0, 1e-12);
  }
  EXPECT_FALSE(a.spheres.empty());    // tree crowns
  EXPECT_FALSE(a.cylinders.empty());  // poles and trunks
  ASSERT_EQ(a.planes.size(), b.planes.size());
  for (std::size_t k = 0; k < a.planes.size(); ++k) {
    EXPECT_EQ(a.planes[k].name, b.planes[k].name);
    EXPECT_EQ(a.planes[k].d, b.planes[k].d);
  }
  // Another seed: other buildings and cars on the same roads.
  EXPECT_NE(a.planes.size() + a.cylinders.size(), c.planes.size() + c.cylinders.size());
  // The road surface is the scene's: rays straight down from 3 m hit it at the ground height.
  for (double x : {-60.0, 0.0, 37.5, 90.0, 91.5}) {
    for (double y : {-55.0, -57.0, -59.5, 55.0}) {
      const RayHit hit = IntersectScene(a, Eigen::Vector3d(x, y, 3.0), -Eigen::Vector3d::UnitZ());
      if (!hit.hit || hit.label == 0) continue;  // a car or a tree crown
      const double z = 3.0 - hit.t;
      if (z > 0.3) continue;  // a car roof or a sign
      EXPECT_NEAR(z, StreetGroundHeight(x, y), 1e-9) << x << " " << y;
    }
  }
}

TEST(StreetRoute, LoopLengthSpeedAndScannerHeight) {
  const SyntheticConfig config = Street(0);
  const StreetRoute route(config.trajectory);
  EXPECT_GE(route.Length(), 600.0);
  EXPECT_NEAR(route.Length(), 1.15 * StreetRouteLength(1.0), 1e-9);
  const int frames = TrajectoryFrameCount(config.trajectory);
  EXPECT_EQ(frames, static_cast<int>(std::floor(route.Duration() * 10.0)) + 1);
  // Speeds between the turn speed and the top speed; the scanner 1.73 m above the plane of the
  // wheels, which inside a crossing (the crown ridges meet) lies up to camber * 1.35 m from the
  // ground right below it, plus 5 mm of suspension.
  Pose previous = route.ScannerPose(0.0);
  double travelled = 0.0;
  for (int i = 1; i < frames; ++i) {
    const Pose T = route.ScannerPose(i / 10.0);
    const double step = (T.translation() - previous.translation()).norm();
    EXPECT_GT(step, 0.45);
    EXPECT_LT(step, 1.01);
    travelled += step;
    const Eigen::Vector3d p = T.translation();
    EXPECT_NEAR(p.z() - StreetGroundHeight(p.x(), p.y()), 1.73, 0.035);
    previous = T;
  }
  EXPECT_NEAR(travelled, route.Length(), 1.0);
  // The route passes its start again: some late pose is within 1 m of the first.
  const Eigen::Vector3d start = route.ScannerPose(0.0).translation();
  double closest = 1e9;
  for (int i = frames / 2; i < frames; ++i) {
    closest = std::min(closest, (route.ScannerPose(i / 10.0).translation() - start).norm());
  }
  EXPECT_LT(closest, 1.0);
}

/// Noise-free scans agree with the brute-force intersection on every 19th ray, on a straight and
/// in a turn.
TEST(RotatingLidar, MatchesBruteForce) {
  SyntheticConfig config = Street(0);
  config.lidar.noise = false;
  config.lidar.max_incidence_deg = 90.0;
  const SyntheticSequence seq(config);
  const auto& lidar = dynamic_cast<const RotatingLidar&>(seq.sensor());
  ASSERT_EQ(lidar.Height(), 64);
  ASSERT_EQ(lidar.Width(), 2083);
  for (std::size_t index : {std::size_t{0}, std::size_t{160}}) {
    const SyntheticFrame frame = seq.Generate(index);
    const Pose T = *frame.frame.T_world_sensor_gt;
    int compared = 0;
    for (int r = 0; r < lidar.Height(); ++r) {
      for (int c = r % 19; c < lidar.Width(); c += 19) {
        const std::size_t i = static_cast<std::size_t>(r) * lidar.Width() + c;
        const RayHit hit =
            IntersectScene(seq.scene(), T.translation(), T.linear() * lidar.RayDirection(r, c));
        const bool in_range = hit.hit && hit.t >= config.lidar.min_range &&
                              hit.t <= config.lidar.max_range;
        ASSERT_EQ(frame.frame.cloud.IsValid(i), in_range) << r << " " << c;
        if (!in_range) continue;
        EXPECT_NEAR(frame.frame.cloud.points[i].cast<double>().norm(), hit.t, 1e-4 * hit.t);
        EXPECT_EQ(frame.labels.data[i], hit.label);
        ++compared;
      }
    }
    EXPECT_GT(compared, 3500);
  }
}

/// With motion distortion each firing is cast from the pose at its own time and its point is in
/// that pose's frame.
TEST(RotatingLidar, MotionDistortionCastsEachFiringFromItsPose) {
  SyntheticConfig config = Street(0);
  config.lidar.noise = false;
  config.lidar.max_incidence_deg = 90.0;
  config.lidar.motion_distortion = true;
  const SyntheticSequence seq(config);
  const auto& lidar = dynamic_cast<const RotatingLidar&>(seq.sensor());
  const std::size_t index = 150;
  const SyntheticFrame frame = seq.Generate(index);
  int compared = 0;
  double largest_shift = 0.0;
  for (int r = 0; r < lidar.Height(); r += 4) {
    for (int c = 0; c < lidar.Width(); c += 11) {
      const double dt = lidar.ColumnTimeOffset(c);
      ASSERT_LE(std::abs(dt), 0.05 + 1e-12);
      const Pose Tc = TrajectoryBodyPose(config.trajectory, seq.Timestamp(index) + dt);
      const RayHit hit =
          IntersectScene(seq.scene(), Tc.translation(), Tc.linear() * lidar.RayDirection(r, c));
      const std::size_t i = static_cast<std::size_t>(r) * lidar.Width() + c;
      const bool in_range = hit.hit && hit.t >= config.lidar.min_range &&
                            hit.t <= config.lidar.max_range;
      ASSERT_EQ(frame.frame.cloud.IsValid(i), in_range);
      if (!in_range) continue;
      EXPECT_NEAR(frame.frame.cloud.points[i].cast<double>().norm(), hit.t, 1e-4 * hit.t);
      largest_shift = std::max(largest_shift, (Tc.translation() - seq.GroundTruth(index)->translation()).norm());
      ++compared;
    }
  }
  EXPECT_GT(compared, 1000);
  EXPECT_GT(largest_shift, 0.2);  // half a scan at about 10 m/s
  // Column times: -pi/2 azimuth (right) fires a quarter turn after the reference (ahead).
  const int right = static_cast<int>(std::lround(0.75 * lidar.Width() - 0.25));
  EXPECT_NEAR(lidar.ColumnTimeOffset(right), 0.025, 1e-4);
}

/// Written in the KITTI layout and read back by the sequence factory: the same range images bit
/// for bit (every laser recovered from the point order), poses in the first scan's frame, stamps,
/// labels per return, planes.json in the poses' frame; the same seed gives the same bytes.
TEST(StreetKittiLayout, ReadsBackBitForBit) {
  const fs::path dir = test::ScratchDir();
  SyntheticConfig config = Street(3);
  config.trajectory.rate = 2.0;  // three scans spread over 10 m
  const SyntheticSequence seq(config);
  const SyntheticWriteSummary summary = WriteSyntheticSequence(seq, (dir / "a").string());
  EXPECT_EQ(summary.frames, 3u);
  for (const char* f : {"times.txt", "poses.txt", "calib.txt", "planes.json", "scanner.yaml",
                        "preview.png", "velodyne/000002.bin", "labels/000002.label"}) {
    EXPECT_TRUE(fs::is_regular_file(dir / "a" / f)) << f;
  }
  EXPECT_EQ(DetectLayout((dir / "a").string()), SequenceLayout::kKittiBin);
  SensorConfig sensor;  // the kitti profile's projection
  sensor.lidar_rows = 64;
  sensor.lidar_cols = 2083;
  sensor.lidar_row_mode = "scan_order";
  sensor.lidar_column_shift = 1;
  sensor.min_depth = 0.0;
  sensor.max_depth = 0.0;
  for (const fs::path& folder : {dir / "a", dir / "a" / "velodyne"}) {
    const auto read = OpenSequence(folder.string(), sensor);
    ASSERT_EQ(read->Size(), 3u);
    const Pose first_inv = seq.GroundTruth(0)->inverse();
    for (std::size_t i = 0; i < 3; ++i) {
      const SyntheticFrame mem = seq.Generate(i);
      EXPECT_EQ(read->Timestamp(i), mem.frame.timestamp);
      const Pose expected = first_inv * *mem.frame.T_world_sensor_gt;
      ASSERT_TRUE(read->GroundTruth(i).has_value());
      EXPECT_LT((read->GroundTruth(i)->matrix() - expected.matrix()).norm(), 1e-12);
      const std::string bin = (dir / "a" / "velodyne" / ("00000" + std::to_string(i) + ".bin")).string();
      RangeProjectionStats stats;
      const OrganizedCloud disk = ReadKittiRangeImage(bin, sensor, &stats);
      EXPECT_TRUE(stats.used_scan_order);
      EXPECT_EQ(stats.collisions, 0u);
      EXPECT_EQ(stats.shifted, 0u);
      const OrganizedCloud loaded = read->Load(i).cloud;
      ASSERT_EQ(loaded.width, mem.frame.cloud.width);
      ASSERT_EQ(loaded.height, mem.frame.cloud.height);
      std::size_t valid = 0;
      for (std::size_t k = 0; k < loaded.points.size(); ++k) {
        const bool a = loaded.IsValid(k), b = mem.frame.cloud.IsValid(k);
        ASSERT_EQ(a, b) << k;
        if (!a) continue;
        ++valid;
        ASSERT_EQ(loaded.points[k], mem.frame.cloud.points[k]) << k;
      }
      const std::string labels =
          Slurp(dir / "a" / "labels" / ("00000" + std::to_string(i) + ".label"));
      EXPECT_EQ(labels.size(), 4 * valid);
      EXPECT_EQ(ReadKittiScan(bin).size(), valid);
    }
  }
  // planes.json is in the frame of poses.txt: frame 0's labelled returns lie on their planes.
  const nlohmann::json planes = nlohmann::json::parse(Slurp(dir / "a" / "planes.json"));
  const std::vector<LidarPoint> scan = ReadKittiScan((dir / "a" / "velodyne" / "000000.bin").string());
  const std::string labels = Slurp(dir / "a" / "labels" / "000000.label");
  int on_plane = 0;
  for (std::size_t k = 0; k < scan.size(); k += 97) {
    std::uint32_t id = 0;
    std::memcpy(&id, labels.data() + 4 * k, 4);
    if (id == 0) continue;
    const auto& p = planes["planes"][id - 1];
    const Eigen::Vector3d n(p["normal"][0], p["normal"][1], p["normal"][2]);
    EXPECT_LT(std::abs(n.dot(scan[k].head<3>().cast<double>()) - p["d"].get<double>()), 0.1);
    ++on_plane;
  }
  EXPECT_GT(on_plane, 500);
  // Determinism: the same config writes the same bytes.
  WriteSyntheticSequence(seq, (dir / "b").string());
  for (const char* f : {"velodyne/000001.bin", "labels/000001.label", "poses.txt", "planes.json"}) {
    EXPECT_EQ(Slurp(dir / "a" / f), Slurp(dir / "b" / f)) << f;
  }
}

/// A randomized family: three seeds (other buildings, cars and trees), six scans each at random
/// places along the route (turns and crossings included). Every scan listed in KITTI's point
/// order projects back onto exactly its range image: all 64 lasers recovered from the order,
/// no collision. Failure budget: none.
TEST(StreetKittiLayout, EveryLaserRecoveredAcrossSeedsAndPlaces) {
  SensorConfig sensor;
  sensor.lidar_rows = 64;
  sensor.lidar_cols = 2083;
  sensor.lidar_row_mode = "scan_order";
  sensor.lidar_column_shift = 1;
  std::mt19937_64 rng(33);
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    SyntheticConfig config = Street(0);
    config.seed = seed;
    const SyntheticSequence seq(config);
    const std::vector<int> order = KittiColumnOrder(seq.sensor().Width());
    for (int k = 0; k < 6; ++k) {
      const std::size_t index = static_cast<std::size_t>(rng() % seq.Size());
      const SyntheticFrame frame = seq.Generate(index);
      const OrganizedCloud& cloud = frame.frame.cloud;
      std::vector<LidarPoint> scan;
      for (int r = 0; r < cloud.height; ++r) {
        for (int c : order) {
          const Eigen::Vector3f& p = cloud.points[static_cast<std::size_t>(r) * cloud.width + c];
          if (OrganizedCloud::IsValid(p)) scan.emplace_back(p.x(), p.y(), p.z(), 0.5f);
        }
      }
      RangeProjectionStats stats;
      const OrganizedCloud back = ProjectToRangeImage(scan, sensor, &stats);
      ASSERT_TRUE(stats.used_scan_order) << "seed " << seed << " scan " << index;
      EXPECT_EQ(stats.collisions, 0u);
      EXPECT_EQ(stats.placed, scan.size());
      for (std::size_t i = 0; i < cloud.points.size(); ++i) {
        ASSERT_EQ(back.IsValid(i), cloud.IsValid(i)) << "seed " << seed << " scan " << index;
        if (cloud.IsValid(i)) {
          ASSERT_EQ(back.points[i], cloud.points[i]);
        }
      }
    }
  }
}

TEST(StreetKittiLayout, ColumnOrderStartsLeftOfAhead) {
  for (int w : {2083, 2084, 7}) {
    const std::vector<int> order = KittiColumnOrder(w);
    ASSERT_EQ(static_cast<int>(order.size()), w);
    auto az = [w](int c) { return kPi - 2.0 * kPi * (c + 0.25) / w; };
    EXPECT_GT(az(order.front()), 0.0);
    EXPECT_LE(az(order.back()), 0.0);
    // Counter-clockwise: azimuth rises except at the one wrap from +pi to -pi.
    int wraps = 0;
    for (std::size_t k = 1; k < order.size(); ++k) wraps += az(order[k]) < az(order[k - 1]);
    EXPECT_EQ(wraps, 1);
  }
}

}  // namespace
}  // namespace planeslam::datasets
