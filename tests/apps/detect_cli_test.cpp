// `planeslam detect` end to end: a ray-cast depth PNG with known planes in, files a user opens out.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <Eigen/Core>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "planeslam/datasets/image_io.hpp"
#include "cli_support.hpp"
#include "test_support.hpp"

namespace planeslam::app {
namespace {

namespace fs = std::filesystem;
using test::CliResult;
using test::Slurp;

CliResult RunDetect(const std::string& args, const fs::path& dir) {
  return test::RunCli("detect " + args, dir);
}


struct TestPlane {
  Eigen::Vector3d n;
  double d;
};

/// Floor, back wall and left wall seen by a 320x240 pinhole camera (fx = fy = 262.5), depth PNG in
/// millimetres (depth_scale 1000), plus the camera file.
std::vector<TestPlane> WriteScene(const fs::path& dir) {
  const std::vector<TestPlane> planes = {{Eigen::Vector3d(0, 1, 0), 1.0},
                                         {Eigen::Vector3d(0, 0, 1), 3.0},
                                         {Eigen::Vector3d(-1, 0, 0), 1.2}};
  const int w = 320, h = 240;
  const double f = 262.5, cx = 159.5, cy = 119.5;
  datasets::Image16 depth(w, h);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const Eigen::Vector3d ray((u - cx) / f, (v - cy) / f, 1.0);
      double best = 1e9;
      for (const auto& p : planes) {
        const double nr = p.n.dot(ray);
        if (nr > 1e-9) best = std::min(best, p.d / nr);
      }
      depth.data[v * w + u] = static_cast<std::uint16_t>(std::lround(best * 1000.0));
    }
  }
  datasets::WritePng16((dir / "depth.png").string(), depth);
  std::ofstream(dir / "camera.yaml") << "width: 320\nheight: 240\nfx: 262.5\nfy: 262.5\n"
                                        "cx: 159.5\ncy: 119.5\ndepth_scale: 1000\n";
  return planes;
}

TEST(DetectCli, WritesPlanesLabelsImagesAndPly) {
  const fs::path dir = test::ScratchDir();
  const auto planes = WriteScene(dir);
  for (const std::string method : {"grid", "point"}) {
    SCOPED_TRACE(method);
    const fs::path out = dir / ("out_" + method);
    const CliResult r =
        RunDetect((dir / "depth.png").string() + " --intrinsics " + (dir / "camera.yaml").string() +
                      " --method " + method + " --out " + out.string(),
                  dir);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.out.find("planes"), std::string::npos);
    const auto json = nlohmann::json::parse(Slurp(out / "planes.json"));
    ASSERT_TRUE(json["planes"].is_array());
    ASSERT_GE(json["planes"].size(), planes.size());
    // Every scene plane is found (mm quantisation: 1 deg, 2 cm), with a 4x4 covariance.
    for (const auto& truth : planes) {
      bool found = false;
      for (const auto& p : json["planes"]) {
        const Eigen::Vector3d n(p["normal"][0].get<double>(), p["normal"][1].get<double>(),
                                p["normal"][2].get<double>());
        if (n.dot(truth.n) > std::cos(M_PI / 180) &&
            std::abs(p["d"].get<double>() - truth.d) < 0.02)
          found = true;
        ASSERT_EQ(p["covariance"].size(), 4u);
        ASSERT_EQ(p["covariance"][0].size(), 4u);
        EXPECT_GE(p["id"].get<int>(), 1);
      }
      EXPECT_TRUE(found) << "plane n=" << truth.n.transpose() << " d=" << truth.d;
    }
    // labels.png: 16-bit, value = plane id, pixel counts = the planes' point counts.
    const datasets::Image16 labels = datasets::ReadPng16((out / "labels.png").string());
    ASSERT_EQ(labels.width, 320);
    ASSERT_EQ(labels.height, 240);
    std::map<int, long> counts;
    for (auto v : labels.data) ++counts[v];
    for (const auto& p : json["planes"]) {
      EXPECT_EQ(counts[p["id"].get<int>()], p["points"].get<long>());
    }
    EXPECT_TRUE(fs::exists(out / "labels_color.png"));
    EXPECT_EQ(fs::exists(out / "classes.png"), method == "grid");
    EXPECT_TRUE(fs::exists(out / "config.yaml"));
    // segmented.ply: a binary PLY header announcing every valid pixel, and the bytes to match.
    const std::string ply = Slurp(out / "segmented.ply");
    ASSERT_EQ(ply.rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u);
    const auto end = ply.find("end_header\n");
    ASSERT_NE(end, std::string::npos);
    EXPECT_NE(ply.find("element vertex 76800\n"), std::string::npos);
    EXPECT_EQ(ply.size() - (end + 11), 76800u * 19u);
  }
}

TEST(DetectCli, ErrorsLeaveNoOutput) {
  const fs::path dir = test::ScratchDir();
  WriteScene(dir);
  const fs::path out = dir / "out";
  CliResult r = RunDetect((dir / "missing.png").string() + " --out " + out.string(), dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("missing.png"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  r = RunDetect((dir / "depth.png").string() + " --intrinsics " + (dir / "nope.yaml").string() +
                    " --out " + out.string(),
                dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("nope.yaml"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  r = RunDetect((dir / "depth.png").string() + " --set detection.threshold_model=linear --out " +
                    out.string(),
                dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("threshold_model"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace planeslam::app
