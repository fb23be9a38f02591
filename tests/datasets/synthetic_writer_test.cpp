// Synthetic sequences on disk: read back through the TUM / PCD readers with exact ground truth,
// labels and planes.json, and byte-identical files for identical seeds.
#include "planeslam/datasets/synthetic_writer.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/pcd_io.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "planeslam/datasets/tum_sequence.hpp"
#include "test_support.hpp"

namespace planeslam::datasets {
namespace {

namespace fs = std::filesystem;

std::string Slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

SyntheticConfig Small(SceneKind kind, const std::string& sensor, int frames) {
  SyntheticConfig c = SyntheticConfig::ForScene(kind);
  c.sensor = sensor;
  c.trajectory.frames = frames;
  c.trajectory.rate = 3.0;  // few frames spread along the path
  return c;
}

TEST(SyntheticWriter, TumLayoutReadsBackWithExactGroundTruth) {
  const fs::path dir = test::ScratchDir();
  const SyntheticSequence seq(Small(SceneKind::kRoom, "pinhole", 4));
  std::size_t calls = 0;
  const SyntheticWriteSummary summary =
      WriteSyntheticSequence(seq, dir.string(), [&calls](std::size_t done) {
        EXPECT_EQ(done, ++calls);
        return true;
      });
  EXPECT_EQ(summary.frames, 4u);
  EXPECT_EQ(summary.files, 4u * 2 + 5);  // depth + labels per frame; list, K, gt, planes, preview
  EXPECT_GT(summary.bytes, 0u);
  EXPECT_TRUE(fs::exists(dir / "preview.png"));

  EXPECT_EQ(DetectLayout(dir.string()), SequenceLayout::kTum);
  const auto tum = OpenTumSequence(dir.string(), SensorConfig{});
  ASSERT_EQ(tum->Size(), seq.Size());
  EXPECT_EQ(tum->GroundTruthCount(), seq.Size());
  EXPECT_EQ(tum->intrinsics().fx, seq.config().pinhole.intrinsics.fx);
  EXPECT_EQ(tum->intrinsics().cy, seq.config().pinhole.intrinsics.cy);
  for (std::size_t i = 0; i < seq.Size(); ++i) {
    const SyntheticFrame mem = seq.Generate(i);
    const Frame disk = tum->Load(i);
    EXPECT_EQ(disk.timestamp, mem.frame.timestamp);
    ASSERT_TRUE(disk.T_world_sensor_gt.has_value());
    // Round-trip digits: the pose is exact up to the quaternion conversion.
    EXPECT_LT((disk.T_world_sensor_gt->matrix() - mem.frame.T_world_sensor_gt->matrix())
                  .cwiseAbs()
                  .maxCoeff(),
              1e-15);
    ASSERT_EQ(disk.cloud.size(), mem.frame.cloud.size());
    for (std::size_t k = 0; k < disk.cloud.size(); ++k) {
      const Eigen::Vector3f& a = disk.cloud.points[k];
      const Eigen::Vector3f& b = mem.frame.cloud.points[k];
      ASSERT_EQ(OrganizedCloud::IsValid(a), OrganizedCloud::IsValid(b)) << k;
      if (!OrganizedCloud::IsValid(a)) continue;
      // Depth PNG quantisation: 1/5000 m, half a step either way.
      ASSERT_NEAR(a.z(), b.z(), 0.5 / 5000.0 + 1e-6) << k;
    }
    const Image16 labels =
        ReadPng16((dir / "labels" / (StampName(mem.frame.timestamp) + ".png")).string());
    EXPECT_EQ(labels.data, mem.labels.data);
  }
  // planes.json holds every plane with n.p = d on its corners.
  const nlohmann::json planes = nlohmann::json::parse(Slurp(dir / "planes.json"));
  ASSERT_EQ(planes["planes"].size(), seq.scene().planes.size());
  for (const auto& p : planes["planes"]) {
    const Eigen::Vector3d n(p["normal"][0], p["normal"][1], p["normal"][2]);
    const double d = p["d"];
    EXPECT_EQ(d, seq.scene().Plane(p["id"]).d);
    for (const auto& poly : p["polygons"])
      for (const auto& c : poly) EXPECT_NEAR(n.dot(Eigen::Vector3d(c[0], c[1], c[2])), d, 1e-9);
  }
  EXPECT_EQ(planes["planes"][0]["name"], "floor");
  EXPECT_DOUBLE_EQ(planes["planes"][0]["area"].get<double>(), seq.scene().Plane(1).Area());
}

TEST(SyntheticWriter, IdenticalSeedsGiveIdenticalBytes) {
  const fs::path root = test::ScratchDir();
  auto write = [&](const std::string& name, std::uint64_t seed) {
    SyntheticConfig c = Small(SceneKind::kRubble, "pinhole", 2);
    c.seed = seed;
    WriteSyntheticSequence(SyntheticSequence(c), (root / name).string());
    return root / name;
  };
  const fs::path a = write("a", 5), b = write("b", 5), c = write("c", 6);
  std::size_t compared = 0;
  for (const auto& entry : fs::recursive_directory_iterator(a)) {
    if (!entry.is_regular_file()) continue;
    const fs::path rel = fs::relative(entry.path(), a);
    EXPECT_EQ(Slurp(entry.path()), Slurp(b / rel)) << rel;
    ++compared;
  }
  EXPECT_EQ(compared, 2u * 2 + 5);
  // Another seed: another rubble and other noise.
  EXPECT_NE(Slurp(a / "planes.json"), Slurp(c / "planes.json"));
  EXPECT_NE(Slurp(a / "depth" / "0.000000.png"), Slurp(c / "depth" / "0.000000.png"));
}

TEST(SyntheticWriter, SphericalScansAreOrganizedPcd) {
  const fs::path dir = test::ScratchDir();
  const SyntheticSequence seq(Small(SceneKind::kRoom, "spherical", 2));
  WriteSyntheticSequence(seq, dir.string());
  EXPECT_TRUE(fs::exists(dir / "scanner.yaml"));
  EXPECT_FALSE(fs::exists(dir / "depth.txt"));
  EXPECT_EQ(DetectLayout(dir.string()), SequenceLayout::kPcdFolder);
  for (std::size_t i = 0; i < seq.Size(); ++i) {
    const SyntheticFrame mem = seq.Generate(i);
    const std::string stem = StampName(mem.frame.timestamp);
    const OrganizedCloud disk =
        ReadPcd((dir / (stem + ".pcd")).string(), 1.0, SensorModel::kSpherical);
    ASSERT_EQ(disk.width, mem.frame.cloud.width);
    ASSERT_EQ(disk.height, mem.frame.cloud.height);
    for (std::size_t k = 0; k < disk.size(); ++k) {
      ASSERT_EQ(OrganizedCloud::IsValid(disk.points[k]),
                OrganizedCloud::IsValid(mem.frame.cloud.points[k]));
      if (OrganizedCloud::IsValid(disk.points[k])) {
        ASSERT_EQ(disk.points[k], mem.frame.cloud.points[k]);
      }
    }
    EXPECT_EQ(ReadPng16((dir / "labels" / (stem + ".png")).string()).data, mem.labels.data);
  }
  SensorConfig config;
  config.pcd_model = "spherical";
  const auto opened = OpenSequence(dir.string(), config);
  ASSERT_EQ(opened->Size(), seq.Size());
  EXPECT_EQ(opened->Timestamp(1), seq.Timestamp(1));
  EXPECT_EQ(opened->Load(1).cloud.model, SensorModel::kSpherical);
  // The ground truth written beside the scans comes back with them.
  for (std::size_t i = 0; i < seq.Size(); ++i) {
    const auto gt = opened->GroundTruth(i);
    ASSERT_TRUE(gt.has_value()) << i;
    EXPECT_TRUE(gt->isApprox(seq.Generate(i).frame.T_world_sensor_gt.value(), 1e-9)) << i;
  }
}

TEST(SyntheticWriter, PreviewShowsDepthAndLabels) {
  const SyntheticSequence seq(Small(SceneKind::kRoom, "pinhole", 1));
  const SyntheticFrame f = seq.Generate(0);
  const ImageRgb8 preview = MakeSyntheticPreview(f, 8.0);
  ASSERT_EQ(preview.width, 2 * f.frame.cloud.width);
  ASSERT_EQ(preview.height, f.frame.cloud.height);
  const int w = f.frame.cloud.width;
  for (int r = 0; r < preview.height; r += 7) {
    for (int c = 0; c < w; c += 5) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      const std::uint8_t* grey = &preview.data[3 * (static_cast<std::size_t>(r) * 2 * w + c)];
      const std::uint8_t* colour = grey + 3 * w;
      std::uint8_t expected[3] = {0, 0, 0};
      if (OrganizedCloud::IsValid(f.frame.cloud.points[i])) {
        const auto label_rgb = LabelColour(f.labels.data[i]);
        std::copy(label_rgb.begin(), label_rgb.end(), expected);
        EXPECT_GT(grey[0], 0);
        EXPECT_TRUE(grey[0] == grey[1] && grey[1] == grey[2]);
      } else {
        EXPECT_EQ(grey[0], 0);
      }
      EXPECT_TRUE(std::equal(expected, expected + 3, colour)) << r << "," << c;
    }
  }
}

}  // namespace
}  // namespace planeslam::datasets
