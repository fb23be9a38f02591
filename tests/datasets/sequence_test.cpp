#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "planeslam/datasets/tum_sequence.hpp"
#include "test_support.hpp"

namespace planeslam::datasets {
namespace {

namespace fs = std::filesystem;

void WriteText(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

using test::ErrorOf;

// ---------------------------------------------------------------------------------------------
// Real TUM fr3 data.

fs::path TumDir() { return test::DataDir() / "tum_fr3_structure_notexture_far"; }

TEST(TumSequence, FirstFrameMatchesDirectDecode) {
  PLANESLAM_REQUIRE_DATA();
  const auto seq = OpenSequence(TumDir().string(), SensorConfig{});
  ASSERT_EQ(seq->Size(), 252u);
  const Frame frame = seq->Load(0);
  EXPECT_EQ(frame.cloud.width, 640);
  EXPECT_EQ(frame.cloud.height, 480);
  EXPECT_DOUBLE_EQ(frame.timestamp, 1341836537.655691);
  // Count the measurements of the PNG independently of the back-projection.
  const Image16 raw = ReadPng16((TumDir() / "depth" / "1341836537.655691.png").string());
  std::size_t nonzero = 0;
  for (auto d : raw.data) nonzero += d != 0 ? 1 : 0;
  EXPECT_GT(nonzero, 100000u);
  EXPECT_EQ(frame.cloud.CountValid(), nonzero);
  // Depth is value / 5000 and the intrinsics come from intrinsics.yaml (fr3).
  for (std::size_t i = 0; i < raw.data.size(); i += 997) {
    if (raw.data[i] == 0) continue;
    EXPECT_NEAR(frame.cloud.points[i].z(), raw.data[i] / 5000.0, 1e-6);
    const int u = static_cast<int>(i % 640), v = static_cast<int>(i / 640);
    EXPECT_NEAR(frame.cloud.points[i].x(), (u - 320.1) * raw.data[i] / 5000.0 / 535.4, 1e-5);
    EXPECT_NEAR(frame.cloud.points[i].y(), (v - 247.6) * raw.data[i] / 5000.0 / 539.2, 1e-5);
  }
}

TEST(TumSequence, DecimatedLoadIsDecimateOfTheFullLoad) {
  PLANESLAM_REQUIRE_DATA();
  const auto seq = OpenSequence(TumDir().string(), SensorConfig{});
  for (std::size_t index : {std::size_t{0}, std::size_t{131}, std::size_t{251}}) {
    const Frame full = seq->Load(index);
    EXPECT_EQ(full.decimation, 1);
    for (int factor : {2, 3}) {
      const Frame frame = seq->LoadDecimated(index, factor);
      const OrganizedCloud expected = Decimate(full.cloud, factor);
      EXPECT_EQ(frame.decimation, factor);
      EXPECT_EQ(frame.timestamp, full.timestamp);
      EXPECT_EQ(frame.source, full.source);
      ASSERT_EQ(frame.cloud.width, expected.width);
      ASSERT_EQ(frame.cloud.height, expected.height);
      ASSERT_EQ(frame.T_world_sensor_gt.has_value(), full.T_world_sensor_gt.has_value());
      EXPECT_EQ(std::memcmp(frame.cloud.points.data(), expected.points.data(),
                            expected.points.size() * sizeof(Eigen::Vector3f)),
                0)
          << "frame " << index << " factor " << factor;
    }
  }
}

TEST(TumSequence, AllFramesAndGroundTruthAssociations) {
  PLANESLAM_REQUIRE_DATA();
  const auto seq = OpenTumSequence(TumDir().string(), SensorConfig{});
  ASSERT_EQ(seq->Size(), 252u);
  EXPECT_EQ(seq->GroundTruthCount(), 248u);  // README: 248 frames have a pose within 20 ms
  for (std::size_t i = 1; i < seq->Size(); ++i) {
    ASSERT_GT(seq->Timestamp(i), seq->Timestamp(i - 1));
  }
  // Loading agrees with the metadata and every frame decodes.
  for (std::size_t i = 0; i < seq->Size(); i += 25) {
    const Frame f = seq->Load(i);
    EXPECT_EQ(f.index, i);
    EXPECT_DOUBLE_EQ(f.timestamp, seq->Timestamp(i));
    EXPECT_EQ(f.T_world_sensor_gt.has_value(), seq->GroundTruth(i).has_value());
    EXPECT_GT(f.cloud.CountValid(), 50000u);
  }
  // A tighter association tolerance can only lose frames.
  SensorConfig tight;
  tight.gt_max_time_difference = 0.005;
  EXPECT_LT(OpenTumSequence(TumDir().string(), tight)->GroundTruthCount(), 248u);
}

// ---------------------------------------------------------------------------------------------
// Synthetic TUM folders.

// A 4x3 camera, frames at the given stamps, all depth 1 m, and ground truth at `gt_stamps`
// (translation x = stamp).
fs::path MakeTumFolder(const fs::path& dir, const std::vector<std::string>& stamps,
                       const std::vector<double>& gt_stamps) {
  fs::create_directories(dir / "depth");
  std::string list = "# depth maps\n# timestamp filename\n";
  Image16 depth(4, 3);
  for (auto& d : depth.data) d = 5000;
  for (const auto& s : stamps) {
    WritePng16((dir / "depth" / (s + ".png")).string(), depth);
    list += s + " depth/" + s + ".png\n";
  }
  WriteText(dir / "depth.txt", list);
  std::string gt = "# timestamp tx ty tz qx qy qz qw\n";
  for (double t : gt_stamps) {
    gt += std::to_string(t) + " " + std::to_string(t) + " 0 0 0 0 0 1\n";
  }
  if (!gt_stamps.empty()) WriteText(dir / "groundtruth.txt", gt);
  WriteText(dir / "intrinsics.yaml",
            "# tiny\nwidth: 4\nheight: 3\nfx: 5\nfy: 5\ncx: 1.5\ncy: 1\ndepth_scale: 5000\n");
  return dir;
}

TEST(TumSequence, NearestStampAssociationWithinTolerance) {
  const auto dir = MakeTumFolder(test::ScratchDir(), {"10.000", "10.100", "10.200"},
                                 {9.99, 10.01, 10.125, 10.26});
  const auto seq = OpenSequence(dir.string(), SensorConfig{});
  ASSERT_EQ(seq->Size(), 3u);
  // 10.000: nearest 9.99 and 10.01 both 0.01 away (either is within 20 ms).
  ASSERT_TRUE(seq->GroundTruth(0).has_value());
  EXPECT_NEAR(std::abs(seq->GroundTruth(0)->translation().x() - 10.0), 0.01, 1e-9);
  // 10.100: nearest 10.125 is 25 ms away -> none.
  EXPECT_FALSE(seq->GroundTruth(1).has_value());
  // 10.200: nearest 10.26 (60 ms) -> none; 10.125 is 75 ms.
  EXPECT_FALSE(seq->GroundTruth(2).has_value());
  SensorConfig loose;
  loose.gt_max_time_difference = 0.03;
  const auto seq2 = OpenSequence(dir.string(), loose);
  ASSERT_TRUE(seq2->GroundTruth(1).has_value());
  EXPECT_DOUBLE_EQ(seq2->GroundTruth(1)->translation().x(), 10.125);
  const Frame f = seq2->Load(1);
  EXPECT_EQ(f.cloud.width, 4);
  EXPECT_EQ(f.cloud.CountValid(), 12u);
  EXPECT_FLOAT_EQ(f.cloud.at(0, 0).x(), -1.5f / 5.0f);
}

// A missing file is a bad frame: the sequence opens, the other frames load, and loading that one
// names the list and line.
TEST(TumSequence, MissingListedFileNamesFileAndLine) {
  const auto dir = MakeTumFolder(test::ScratchDir(), {"1.0", "2.0", "3.0"}, {});
  fs::remove(dir / "depth" / "2.0.png");
  const auto seq = OpenSequence(dir.string(), SensorConfig{});
  ASSERT_EQ(seq->Size(), 3u);
  EXPECT_NO_THROW(seq->Load(0));
  EXPECT_NO_THROW(seq->Load(2));
  const std::string msg = ErrorOf([&] { seq->Load(1); });
  EXPECT_EQ(msg, (dir / "depth.txt").string() + ":4: names 'depth/2.0.png' which does not exist");
}

TEST(TumSequence, UnsortedAndDuplicateStampsAreRefused) {
  const auto dir = MakeTumFolder(test::ScratchDir(), {"1.0", "2.0"}, {});
  WriteText(dir / "depth.txt", "2.0 depth/2.0.png\n1.0 depth/1.0.png\n");
  EXPECT_EQ(ErrorOf([&] { OpenSequence(dir.string(), SensorConfig{}); }),
            (dir / "depth.txt").string() + ":2: unsorted timestamp 1.0 (previous line 1)");
  WriteText(dir / "depth.txt", "1.0 depth/1.0.png\n# c\n1.0 depth/2.0.png\n");
  EXPECT_EQ(ErrorOf([&] { OpenSequence(dir.string(), SensorConfig{}); }),
            (dir / "depth.txt").string() + ":3: duplicate timestamp 1.0 (previous line 1)");
  WriteText(dir / "depth.txt", "1.0 depth/1.0.png extra\n");
  EXPECT_EQ(ErrorOf([&] { OpenSequence(dir.string(), SensorConfig{}); }),
            (dir / "depth.txt").string() + ":1: expected 2 columns, got 3");
}

TEST(TumSequence, TruncatedPngInSequenceIsIoErrorOnLoad) {
  const auto dir = MakeTumFolder(test::ScratchDir(), {"1.0", "2.0"}, {});
  const fs::path png = dir / "depth" / "2.0.png";
  fs::resize_file(png, fs::file_size(png) / 2);
  const auto seq = OpenSequence(dir.string(), SensorConfig{});
  EXPECT_NO_THROW(seq->Load(0));
  const std::string msg = ErrorOf([&] { seq->Load(1); });
  EXPECT_EQ(msg.rfind(png.string() + ": ", 0), 0u) << msg;
}

TEST(TumSequence, IntrinsicsFileIsStrict) {
  const auto dir = MakeTumFolder(test::ScratchDir(), {"1.0"}, {});
  const std::string yaml = (dir / "intrinsics.yaml").string();
  WriteText(dir / "intrinsics.yaml", "width: 4\nheight: 3\nfx: 5\nfy: 5\ncx: 1\ncy: 1\n");
  EXPECT_EQ(ErrorOf([&] { OpenSequence(dir.string(), SensorConfig{}); }),
            yaml + ": missing key 'depth_scale'");
  WriteText(dir / "intrinsics.yaml",
            "width: 4\nheight: 3\nfx: 5\nfy: 5\ncx: 1\ncy: 1\ndepth_scale: 1\nk1: 0\n");
  EXPECT_NE(ErrorOf([&] {
              OpenSequence(dir.string(), SensorConfig{});
            }).find(yaml + ":8: unknown key 'k1'"),
            std::string::npos);
  WriteText(dir / "intrinsics.yaml",
            "width: 4\nheight: 3\nfx: five\nfy: 5\ncx: 1\ncy: 1\ndepth_scale: 1\n");
  EXPECT_EQ(ErrorOf([&] { OpenSequence(dir.string(), SensorConfig{}); }),
            yaml + ":3: key 'fx': expected a number, got 'five'");
  // With intrinsics_source "config" the file is not read at all.
  SensorConfig config;
  config.intrinsics_source = "config";
  config.intrinsics.width = 4;
  config.intrinsics.height = 3;
  EXPECT_EQ(OpenSequence(dir.string(), config)->Load(0).cloud.CountValid(), 12u);
}

// ---------------------------------------------------------------------------------------------
// ICL-NUIM layout, synthesized: a tilted world plane seen from two poses through ICL's camera,
// whose ground truth is expressed for a y-up camera frame (image row v maps to -y).

struct IclScene {
  Eigen::Vector3d n = Eigen::Vector3d(0.2, 0.9, -0.3).normalized();  // world plane n.p = d
  double d = -1.5;
  std::vector<Pose> poses;
};

fs::path MakeIclFolder(const fs::path& dir, IclScene* scene) {
  fs::create_directories(dir / "depth");
  const double fx = 481.2, fy = 480.0, cx = 319.5, cy = 239.5;
  Pose a = Pose::Identity();
  a.translation() = Eigen::Vector3d(0.1, -0.2, 0.3);
  a.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 0.5).normalized()).toRotationMatrix();
  Pose b = Pose::Identity();
  b.translation() = Eigen::Vector3d(0.5, 0.1, -0.2);
  b.linear() = Eigen::AngleAxisd(-0.4, Eigen::Vector3d(0.3, 1, -1).normalized()).toRotationMatrix();
  scene->poses = {a, b};
  std::string assoc, gt;
  for (int k = 0; k < 2; ++k) {
    const Pose& T = scene->poses[k];
    Image16 depth(640, 480);
    for (int v = 0; v < 480; ++v) {
      for (int u = 0; u < 640; ++u) {
        // ICL camera frame: x right, y up (hence the minus), z forward.
        const Eigen::Vector3d ray((u - cx) / fx, -(v - cy) / fy, 1.0);
        const double denom = scene->n.dot(T.linear() * ray);
        const double z = (scene->d - scene->n.dot(T.translation())) / denom;
        if (z > 0.3 && z < 10.0)
          depth.data[v * 640 + u] = static_cast<std::uint16_t>(std::lround(z * 5000));
      }
    }
    WritePng16((dir / "depth" / (std::to_string(k) + ".png")).string(), depth);
    assoc += std::to_string(k) + " depth/" + std::to_string(k) + ".png " + std::to_string(k) +
             " rgb/" + std::to_string(k) + ".png\n";
    const Eigen::Quaterniond q(T.linear());
    char line[256];
    std::snprintf(line, sizeof(line), "%d %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", k,
                  T.translation().x(), T.translation().y(), T.translation().z(), q.x(), q.y(),
                  q.z(), q.w());
    gt += line;
  }
  WriteText(dir / "associations.txt", assoc);
  WriteText(dir / "groundtruth.txt", gt);
  return dir;
}

// Largest |n.p - d| over the valid points of a frame mapped to the world by its ground truth.
double WorldPlaneResidual(const Frame& f, const IclScene& scene) {
  double worst = 0;
  std::size_t n = 0;
  for (const auto& p : f.cloud.points) {
    if (!OrganizedCloud::IsValid(p)) continue;
    const Eigen::Vector3d w = *f.T_world_sensor_gt * p.cast<double>();
    worst = std::max(worst, std::abs(scene.n.dot(w) - scene.d));
    ++n;
  }
  EXPECT_GT(n, 100000u);
  return worst;
}

TEST(IclSequence, GroundTruthAgreesWithBackProjectedDepth) {
  IclScene scene;
  const auto dir = MakeIclFolder(test::ScratchDir(), &scene);
  const auto seq = OpenSequence(dir.string(), SensorConfig{});
  ASSERT_EQ(seq->Size(), 2u);
  for (std::size_t k = 0; k < 2; ++k) {
    const Frame f = seq->Load(k);
    EXPECT_DOUBLE_EQ(f.timestamp, static_cast<double>(k));
    ASSERT_TRUE(f.T_world_sensor_gt.has_value());
    EXPECT_TRUE(f.T_world_sensor_gt->isApprox(scene.poses[k], 1e-6));
    // Depth is quantised to 0.2 mm; the plane is at most ~4 m away.
    EXPECT_LT(WorldPlaneResidual(f, scene), 2e-3) << "frame " << k;
  }
  // Without the flip (fy = +480) the same poses put the two frames' clouds off the plane.
  SensorConfig unflipped;
  unflipped.intrinsics_source = "config";
  unflipped.intrinsics = {640, 480, 481.2, 480.0, 319.5, 239.5};
  const auto wrong = OpenSequence(dir.string(), unflipped);
  EXPECT_GT(WorldPlaneResidual(wrong->Load(0), scene), 0.1);
  // The same folder through the config: flip_y reproduces the automatic choice.
  unflipped.flip_y = true;
  EXPECT_LT(WorldPlaneResidual(OpenSequence(dir.string(), unflipped)->Load(1), scene), 2e-3);
}

TEST(IclSequence, IntrinsicsFileWithFlip) {
  IclScene scene;
  const auto dir = MakeIclFolder(test::ScratchDir(), &scene);
  WriteText(dir / "intrinsics.yaml",
            "width: 640\nheight: 480\nfx: 481.2\nfy: 480\ncx: 319.5\ncy: 239.5\n"
            "depth_scale: 5000\nflip_y: true\n");
  const auto seq = OpenIclSequence(dir.string(), SensorConfig{});
  EXPECT_DOUBLE_EQ(seq->intrinsics().fy, -480.0);
  EXPECT_LT(WorldPlaneResidual(seq->Load(0), scene), 2e-3);
  // ICL's own .K file writes fy negative; that spelling works too.
  WriteText(dir / "intrinsics.yaml",
            "width: 640\nheight: 480\nfx: 481.2\nfy: -480\ncx: 319.5\ncy: 239.5\n"
            "depth_scale: 5000\n");
  EXPECT_LT(WorldPlaneResidual(OpenIclSequence(dir.string(), SensorConfig{})->Load(1), scene),
            2e-3);
}

TEST(IclSequence, MissingDepthNamesLine) {
  IclScene scene;
  const auto dir = MakeIclFolder(test::ScratchDir(), &scene);
  fs::remove(dir / "depth" / "1.png");
  const auto seq = OpenSequence(dir.string(), SensorConfig{});
  EXPECT_EQ(ErrorOf([&] { seq->Load(1); }),
            (dir / "associations.txt").string() + ":2: names 'depth/1.png' which does not exist");
}

TEST(SequenceFactory, MissingAndEmptyFolders) {
  const auto dir = test::ScratchDir();
  EXPECT_EQ(ErrorOf([&] { OpenSequence((dir / "nope").string(), SensorConfig{}); }),
            (dir / "nope").string() + ": no such folder");
  EXPECT_EQ(ErrorOf([&] { OpenSequence(dir.string(), SensorConfig{}); }),
            dir.string() + ": folder is empty");
  WriteText(dir / "readme.txt", "x");
  EXPECT_NE(ErrorOf([&] { OpenSequence(dir.string(), SensorConfig{}); }).find("no known layout"),
            std::string::npos);
  EXPECT_EQ(ErrorOf([&] { LoadSingleFrame((dir / "nope.png").string(), SensorConfig{}); }),
            (dir / "nope.png").string() + ": no such file");
}

TEST(SequenceFactory, SingleFramesOfEveryKind) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path data = test::DataDir();
  // A TUM fr3 depth PNG with the default (fr3) intrinsics.
  const Frame tum = LoadSingleFrame(
      (data / "depth_frames" / "tum_fr3_long_office_1341848230.910894.png").string(),
      SensorConfig{});
  EXPECT_EQ(tum.cloud.width, 640);
  EXPECT_EQ(tum.cloud.model, SensorModel::kPinhole);
  EXPECT_GT(tum.cloud.CountValid(), 100000u);
  // ICL-NUIM's frame with its camera: rows above the centre get y > 0 (y-up camera).
  SensorConfig icl;
  icl.intrinsics = {640, 480, 481.2, 480.0, 319.5, 239.5};
  icl.flip_y = true;
  const Frame f = LoadSingleFrame((data / "depth_frames" / "icl_living_room_0.png").string(), icl);
  std::size_t checked = 0;
  for (int u = 0; u < 640; u += 16) {
    const auto& p = f.cloud.at(10, u);
    if (!OrganizedCloud::IsValid(p)) continue;
    EXPECT_GT(p.y(), 0.0f);
    ++checked;
  }
  EXPECT_GT(checked, 10u);
  // The tunnel PNG is in millimetres.
  SensorConfig mm;
  mm.depth_scale = 1000.0;
  const Frame tunnel =
      LoadSingleFrame((data / "depth_frames" / "cape_tunnel_depth_mm.png").string(), mm);
  EXPECT_GT(tunnel.cloud.CountValid(), 10000u);
  // An organized PCD and a KITTI scan.
  const Frame pcd =
      LoadSingleFrame((data / "organized_pcd" / "office1.pcd").string(), SensorConfig{});
  EXPECT_EQ(pcd.cloud.width, 640);
  EXPECT_EQ(pcd.cloud.height, 480);
  const Frame bin =
      LoadSingleFrame((data / "kitti_velodyne" / "000000.bin").string(), SensorConfig{});
  EXPECT_EQ(bin.cloud.height, 64);
  EXPECT_EQ(bin.cloud.model, SensorModel::kSpherical);
  // Unknown extension.
  EXPECT_NE(ErrorOf([&] {
              LoadSingleFrame((data / "README.md").string(), SensorConfig{});
            }).find("unknown file type '.md'"),
            std::string::npos);
}

TEST(SequenceFactory, InvalidConfigIsConfigError) {
  SensorConfig bad;
  bad.depth_scale = 0;
  bad.lidar_rows = 0;
  EXPECT_EQ(bad.Validate().size(), 2u);
  const auto dir = MakeTumFolder(test::ScratchDir(), {"1.0"}, {});
  EXPECT_THROW(OpenSequence(dir.string(), bad), ConfigError);
}

TEST(SequenceFactory, EmptyFrameListIsIoError) {
  const auto dir = test::ScratchDir();
  WriteText(dir / "depth.txt", "# nothing\n");
  EXPECT_EQ(ErrorOf([&] { OpenSequence(dir.string(), SensorConfig{}); }),
            (dir / "depth.txt").string() + ": lists no frames");
}

}  // namespace
}  // namespace planeslam::datasets
