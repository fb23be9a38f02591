#include "planeslam/datasets/kitti_scan.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <map>
#include <random>
#include <utility>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "test_support.hpp"

namespace planeslam::datasets {
namespace {

namespace fs = std::filesystem;

using test::ErrorOf;

void WriteScan(const fs::path& path, const std::vector<LidarPoint>& points) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(points.data()),
            static_cast<std::streamsize>(points.size() * 16));
}

constexpr double kPi = 3.14159265358979323846;

// A synthetic spinning LiDAR in KITTI's point order: ring by ring, each ring one azimuth sweep
// (counter-clockwise from -pi), all at range `range`. Elevations are uneven like the HDL-64E's.
std::vector<LidarPoint> SyntheticScan(int rings, int per_ring, double range,
                                      std::vector<double>* elevations_deg = nullptr) {
  std::vector<LidarPoint> pts;
  std::vector<double> el;
  for (int r = 0; r < rings; ++r) {
    el.push_back(r < rings / 2 ? 2.0 - r * (1.0 / 3.0)
                               : 2.0 - (rings / 2) / 3.0 - (r - rings / 2) * 0.5);
  }
  for (int r = 0; r < rings; ++r) {
    const double e = el[r] * kPi / 180.0;
    for (int k = 0; k < per_ring; ++k) {
      // KITTI order: from just left of ahead (0+) round to just right of it (0-).
      double az = (k + 0.5) * 2.0 * kPi / per_ring;
      if (az > kPi) az -= 2.0 * kPi;
      pts.emplace_back(static_cast<float>(range * std::cos(e) * std::cos(az)),
                       static_cast<float>(range * std::cos(e) * std::sin(az)),
                       static_cast<float>(range * std::sin(e)), 0.5f);
    }
  }
  if (elevations_deg) *elevations_deg = el;
  return pts;
}

TEST(KittiScan, ScanOrderRingsGiveOneRowPerLaser) {
  std::vector<double> el;
  const auto scan = SyntheticScan(64, 1000, 10.0, &el);
  SensorConfig config;
  RangeProjectionStats stats;
  const OrganizedCloud image = ProjectToRangeImage(scan, config, &stats);
  EXPECT_TRUE(stats.used_scan_order);
  EXPECT_EQ(image.width, 2083);
  EXPECT_EQ(image.height, 64);
  EXPECT_EQ(image.model, SensorModel::kSpherical);
  EXPECT_EQ(stats.placed, scan.size());  // 1000 azimuths < 2048 columns: no collision
  EXPECT_EQ(image.CountValid(), scan.size());
  // Row r holds ring r (elevations decrease down the image); the middle column looks along +x.
  for (int r = 0; r < 64; ++r) {
    std::size_t n = 0;
    for (int c = 0; c < image.width; ++c) {
      const auto& p = image.at(r, c);
      if (!OrganizedCloud::IsValid(p)) continue;
      ++n;
      EXPECT_NEAR(std::asin(p.z() / p.norm()) * 180.0 / kPi, el[r], 1e-3);
    }
    EXPECT_EQ(n, 1000u);
  }
  // Column c holds azimuth pi - 2 pi (c + 0.5) / cols: ahead (+x) in the middle, behind at the
  // ends.
  for (int c = 0; c < image.width; ++c) {
    const auto& p = image.at(10, c);
    if (!OrganizedCloud::IsValid(p)) continue;
    const double expected = kPi - 2.0 * kPi * (c + 0.5) / image.width;
    double diff = std::atan2(p.y(), p.x()) - expected;
    diff = std::remainder(diff, 2.0 * kPi);
    EXPECT_LE(std::abs(diff), kPi / image.width + 1e-6) << c;
  }
  // Uniform elevation bins cannot separate lasers 1/3 degree apart: collisions appear.
  SensorConfig uniform;
  uniform.lidar_row_mode = "elevation";
  uniform.lidar_column_shift = 0;
  RangeProjectionStats ustats;
  ProjectToRangeImage(scan, uniform, &ustats);
  EXPECT_FALSE(ustats.used_scan_order);
  EXPECT_GT(ustats.collisions, 0u);
  EXPECT_EQ(ustats.placed + ustats.collisions + ustats.outside_elevation, scan.size());
}

/// Runs `check` with the reader's AVX2 loops and with its baseline ones.
void WithEachVectorWidth(const std::function<void()>& check) {
  for (const bool avx2 : {true, false}) {
    SCOPED_TRACE(avx2 ? "AVX2 loops where available" : "baseline loops");
    internal::UseAvx2Clones(avx2);
    check();
  }
  internal::UseAvx2Clones(true);
}

// The projection trusts the approximate azimuths to 4e-6 rad (kitti_scan.cpp, kAzimuthMargin);
// they must be well within it: at most 1e-6 rad from std::atan2 anywhere, here over random
// directions at ranges from 1 mm to 100 m, directions near the octant edges, and signed zeros.
TEST(KittiScan, ApproximateAzimuthsStayWithinTheirBound) {
  WithEachVectorWidth([] {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> angle(-kPi, kPi), exponent(-3.0, 2.0), tiny(-1e-6, 1e-6);
    std::vector<LidarPoint> scan;
    for (int i = 0; i < 1000000; ++i) {
      const double a =
          i % 2 ? angle(rng) : std::round(angle(rng) / (kPi / 4)) * (kPi / 4) + tiny(rng);
      const double r = std::pow(10.0, exponent(rng));
      scan.emplace_back(static_cast<float>(r * std::cos(a)), static_cast<float>(r * std::sin(a)),
                        0.0f, 0.0f);
    }
    for (const float x : {-1.0f, -0.0f, 0.0f, 1.0f, 1e-30f, -1e-30f}) {
      for (const float y : {-1.0f, -0.0f, 0.0f, 1.0f, 1e-30f, -1e-30f}) {
        if (x != 0.0f || y != 0.0f) scan.emplace_back(x, y, 0.0f, 0.0f);
      }
    }
    std::vector<float> approximate;
    internal::ApproximateAzimuths(scan, &approximate);
    ASSERT_EQ(approximate.size(), scan.size());
    double worst = 0.0;
    for (std::size_t i = 0; i < scan.size(); ++i) {
      const double exact = std::atan2(scan[i].y(), scan[i].x());
      worst = std::max(worst, std::abs(std::remainder(approximate[i] - exact, 2.0 * kPi)));
    }
    EXPECT_LE(worst, 1e-6);
  });
}

// Points placed on column edges and half-column edges (to a few ulps either side) land in the
// columns, and lean to the sides, that std::atan2's azimuths give.
TEST(KittiScan, ColumnsAreThoseOfExactAzimuths) {
  WithEachVectorWidth([] {
    SensorConfig config;
    config.lidar_row_mode = "elevation";
    const int cols = config.lidar_cols;
    const auto exact_u = [&](const LidarPoint& p) {
      return (kPi - static_cast<double>(std::atan2(p.y(), p.x()))) / (2.0 * kPi) * cols;
    };
    const auto on_edge = [&](double u, int ulps) {
      const double az = kPi - 2.0 * kPi * u / cols;
      float y = static_cast<float>(7.0 * std::sin(az));
      for (int k = 0; k < std::abs(ulps); ++k) {
        y = std::nextafter(y, ulps > 0 ? 1.0f : -1.0f);
      }
      return LidarPoint(static_cast<float>(7.0 * std::cos(az)), y, 0.0f, 0.0f);
    };
    int straddled = 0;
    for (int ulps = -4; ulps <= 4; ++ulps) {
      // Every third column edge: each point has a column of its own.
      config.lidar_column_shift = 0;
      std::vector<LidarPoint> scan;
      std::map<std::pair<float, float>, int> expected;
      for (int edge = 3; edge < cols; edge += 3) {
        scan.push_back(on_edge(edge, ulps));
        const int col = static_cast<int>(std::floor(exact_u(scan.back())));
        expected[{scan.back().x(), scan.back().y()}] = col;
        straddled += col < edge;
      }
      const OrganizedCloud image = ProjectToRangeImage(scan, config);
      std::size_t found = 0;
      for (int c = 0; c < cols; ++c) {
        for (int r = 0; r < image.height; ++r) {
          const auto& p = image.at(r, c);
          if (!OrganizedCloud::IsValid(p)) continue;
          ++found;
          EXPECT_EQ(c, expected.at({p.x(), p.y()})) << ulps;
        }
      }
      EXPECT_EQ(found, scan.size());
      // A point on a half-column edge whose cell is taken moves to the side it leans to.
      config.lidar_column_shift = 1;
      for (const int col : {1, 500, 1041, 1042, 2000}) {
        const LidarPoint blocker = on_edge(col + 0.25, 0);
        const LidarPoint point = on_edge(col + 0.5, ulps);
        if (static_cast<int>(std::floor(exact_u(point))) != col) continue;
        const int side = exact_u(point) - col < 0.5 ? -1 : 1;
        const OrganizedCloud pair = ProjectToRangeImage({blocker, point}, config);
        const int row = [&] {
          for (int r = 0; r < pair.height; ++r) {
            if (OrganizedCloud::IsValid(pair.at(r, col))) return r;
          }
          return -1;
        }();
        ASSERT_GE(row, 0);
        EXPECT_EQ(pair.at(row, col + side).y(), point.y()) << col << " " << ulps;
      }
    }
    EXPECT_GT(straddled, 0);  // the edges were straddled: some points fell left of them
  });
}

TEST(KittiScan, CollisionsKeepTheNearerPoint) {
  std::vector<LidarPoint> scan = {LidarPoint(10, 0, 0, 0), LidarPoint(5, -0.0001f, 0, 0),
                                  LidarPoint(0, 0, 0, 0), LidarPoint(std::nanf(""), 1, 1, 0)};
  SensorConfig config;
  config.lidar_row_mode = "elevation";
  config.lidar_column_shift = 0;
  RangeProjectionStats stats;
  const OrganizedCloud image = ProjectToRangeImage(scan, config, &stats);
  EXPECT_EQ(stats.invalid, 2u);
  EXPECT_EQ(stats.collisions, 1u);
  EXPECT_EQ(stats.placed, 1u);
  ASSERT_EQ(image.CountValid(), 1u);
  for (const auto& p : image.points) {
    if (OrganizedCloud::IsValid(p)) {
      EXPECT_FLOAT_EQ(p.x(), 5.0f);
    }
  }
}

TEST(KittiScan, RealScansProjectAlmostEveryPoint) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path dir = test::DataDir() / "kitti_velodyne";
  const auto seq = OpenSequence(dir.string(), SensorConfig{});
  ASSERT_EQ(seq->Size(), 6u);
  EXPECT_DOUBLE_EQ(seq->Timestamp(3), 3.0);
  for (std::size_t i = 0; i < seq->Size(); ++i) {
    const std::string path = (dir / fs::path(seq->Load(i).source).filename()).string();
    const auto scan = ReadKittiScan(path);
    for (const char* mode : {"scan_order", "elevation"}) {
      SensorConfig config;
      config.lidar_row_mode = mode;
      RangeProjectionStats stats;
      const OrganizedCloud image = ProjectToRangeImage(scan, config, &stats);
      std::printf(
          "%s %-10s points %zu placed %zu (%.2f%%) shifted %zu collisions %zu outside %zu "
          "invalid %zu rings %s\n",
          fs::path(path).filename().c_str(), mode, stats.points, stats.placed,
          100.0 * stats.PlacedFraction(), stats.shifted, stats.collisions, stats.outside_elevation,
          stats.invalid, stats.used_scan_order ? "yes" : "no");
      EXPECT_EQ(image.CountValid(), stats.placed);
      if (std::string(mode) == "scan_order") {
        EXPECT_TRUE(stats.used_scan_order);
        EXPECT_GE(stats.PlacedFraction(), 0.95);
        // Within a ring a point moves at most lidar_column_shift columns from its azimuth.
        for (int r = 0; r < image.height; ++r) {
          for (int c = 0; c < image.width; ++c) {
            const auto& p = image.at(r, c);
            if (!OrganizedCloud::IsValid(p)) continue;
            const double u = (kPi - std::atan2(p.y(), p.x())) / (2.0 * kPi) * image.width;
            const double d = std::remainder(u - (c + 0.5), image.width);
            ASSERT_LE(std::abs(d), config.lidar_column_shift + 0.5 + 1e-3);
          }
        }
      }
    }
  }
}

TEST(KittiScan, BadFilesAreIoErrors) {
  const auto dir = test::ScratchDir();
  {
    std::ofstream out(dir / "000000.bin", std::ios::binary);
    out << std::string(20, 'x');
  }
  EXPECT_EQ(ErrorOf([&] { ReadKittiScan((dir / "000000.bin").string()); }),
            (dir / "000000.bin").string() +
                ": truncated or not a KITTI scan: size 20 bytes is not a multiple of 16 (float32 "
                "x y z reflectance per point)");
  { std::ofstream out(dir / "000000.bin", std::ios::binary); }
  EXPECT_EQ(ErrorOf([&] { ReadKittiScan((dir / "000000.bin").string()); }),
            (dir / "000000.bin").string() + ": empty scan (0 bytes)");
  // A whole scan cut short in the middle of a point.
  const auto scan = SyntheticScan(4, 10, 5.0);
  WriteScan(dir / "000001.bin", scan);
  std::string whole;
  {
    std::ifstream in(dir / "000001.bin", std::ios::binary);
    whole.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  { std::ofstream(dir / "000001.bin", std::ios::binary) << whole.substr(0, whole.size() - 7); }
  EXPECT_NE(ErrorOf([&] { ReadKittiScan((dir / "000001.bin").string()); })
                .find("000001.bin: truncated or not a KITTI scan: size 633 bytes"),
            std::string::npos);
  // NaN and infinite coordinates.
  for (float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    auto broken = scan;
    broken[7].y() = bad;
    WriteScan(dir / "000002.bin", broken);
    EXPECT_EQ(ErrorOf([&] { ReadKittiScan((dir / "000002.bin").string()); }),
              (dir / "000002.bin").string() +
                  ": point 7 of 40 has a NaN or infinite coordinate (corrupt scan)");
  }
  // Points without a return.
  WriteScan(dir / "000003.bin", std::vector<LidarPoint>(5, LidarPoint::Zero()));
  EXPECT_EQ(ErrorOf([&] { ReadKittiScan((dir / "000003.bin").string()); }),
            (dir / "000003.bin").string() + ": empty scan: all 5 points are at the origin");
  EXPECT_EQ(ErrorOf([&] { ReadKittiScan((dir / "nope.bin").string()); }),
            (dir / "nope.bin").string() + ": no such file");
}

TEST(KittiScan, PosesByFrameNumberAndCalibration) {
  const auto dir = test::ScratchDir();
  const auto scan = SyntheticScan(64, 100, 5.0);
  WriteScan(dir / "000001.bin", scan);
  WriteScan(dir / "000003.bin", scan);
  // Pose N translates by (N, 0, 0) in camera coordinates.
  std::string poses;
  for (int n = 0; n < 4; ++n) poses += "1 0 0 " + std::to_string(n) + " 0 1 0 0 0 0 1 0\n";
  { std::ofstream(dir / "poses.txt") << poses; }
  auto seq = OpenSequence(dir.string(), SensorConfig{});
  ASSERT_EQ(seq->Size(), 2u);
  ASSERT_TRUE(seq->GroundTruth(1).has_value());
  EXPECT_DOUBLE_EQ(seq->GroundTruth(1)->translation().x(), 3.0);
  EXPECT_DOUBLE_EQ(seq->GroundTruth(0)->translation().x(), 1.0);
  // Camera x is velodyne -y under KITTI's Tr (velodyne x forward = camera z).
  {
    std::ofstream(dir / "calib.txt")
        << "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nTr: 0 -1 0 0 0 0 -1 0 1 0 0 0\n";
  }
  seq = OpenSequence(dir.string(), SensorConfig{});
  EXPECT_NEAR(seq->GroundTruth(1)->translation().y(), -3.0, 1e-12);
  EXPECT_NEAR(seq->GroundTruth(1)->translation().x(), 0.0, 1e-12);
  // Too few poses for a scan's frame number.
  WriteScan(dir / "000009.bin", scan);
  EXPECT_EQ(ErrorOf([&] { OpenSequence(dir.string(), SensorConfig{}); }),
            (dir / "poses.txt").string() + ": has 4 poses, scan 000009.bin needs pose 9");
}

// KITTI's own tree: dataset/sequences/07/{velodyne/, times.txt, calib.txt} with the ground truth
// in dataset/poses/07.txt. The sequence folder and its velodyne/ both open it, with the camera
// poses turned into Velodyne poses (Tr^-1 P Tr) and the stamps of times.txt.
TEST(KittiScan, KittiOdometryTreeFindsPosesTimesAndCalibration) {
  const auto root = test::ScratchDir() / "dataset";
  const auto seq_dir = root / "sequences" / "07";
  fs::create_directories(seq_dir / "velodyne");
  fs::create_directories(root / "poses");
  const auto scan = SyntheticScan(64, 100, 5.0);
  for (const char* name : {"000000.bin", "000001.bin", "000002.bin"}) {
    WriteScan(seq_dir / "velodyne" / name, scan);
  }
  { std::ofstream(seq_dir / "times.txt") << "0.000000e+00\n1.036000e-01\n2.072000e-01\n"; }
  // Tr: velodyne x forward = camera z, velodyne y left = camera -x, velodyne z up = camera -y.
  { std::ofstream(seq_dir / "calib.txt") << "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nTr: 0 -1 0 0 0 0 -1 0 1 0 0 0\n"; }
  std::string poses;
  for (int n = 0; n < 3; ++n) poses += "1 0 0 0 0 1 0 0 0 0 1 " + std::to_string(2 * n) + "\n";
  { std::ofstream(root / "poses" / "07.txt") << poses; }
  EXPECT_EQ(DetectLayout(seq_dir.string()), SequenceLayout::kKittiBin);
  for (const fs::path& folder : {seq_dir, seq_dir / "velodyne"}) {
    const auto seq = OpenSequence(folder.string(), SensorConfig{});
    ASSERT_EQ(seq->Size(), 3u);
    EXPECT_EQ(seq->Name(), "07");
    EXPECT_DOUBLE_EQ(seq->Timestamp(2), 0.2072);
    ASSERT_TRUE(seq->GroundTruth(2).has_value());
    // 4 m along camera z is 4 m forward along velodyne x.
    EXPECT_NEAR(seq->GroundTruth(2)->translation().x(), 4.0, 1e-12);
    EXPECT_NEAR(seq->GroundTruth(2)->translation().norm(), 4.0, 1e-12);
  }
}

}  // namespace
}  // namespace planeslam::datasets
