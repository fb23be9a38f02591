// Sensor profiles chosen from the data: `run`, `bench` and `detect` apply the config files that
// suit what they are given, exactly as if the user had passed them with -c, and say so; --sensor
// picks one by name or turns the guess off; -c and --set still override.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "cli_support.hpp"
#include "planeslam/datasets/image_io.hpp"
#include "test_support.hpp"

namespace planeslam::test {
namespace {

namespace fs = std::filesystem;

std::string Config(const std::string& name) {
  return std::string(PLANESLAM_SOURCE_DIR) + "/config/" + name;
}

/// The effective configuration `planeslam ARGS --print-config` prints.
std::string PrintConfig(const std::string& args, const fs::path& dir) {
  const CliResult r = RunCli(args + " --print-config", dir);
  EXPECT_EQ(r.exit_code, 0) << args << "\n" << r.err;
  return r.out;
}

/// Three frames of a wall 2 m away in the ICL-NUIM layout: associations.txt, depth/N.png,
/// groundtruth.txt indexed by N.
fs::path MakeIclFolder(const fs::path& dir) {
  const fs::path folder = dir / "living_room";
  fs::create_directories(folder / "depth");
  datasets::Image16 depth(640, 480);
  std::fill(depth.data.begin(), depth.data.end(), 10000);  // 2 m at 5000 units per metre
  std::ofstream associations(folder / "associations.txt");
  std::ofstream gt(folder / "groundtruth.txt");
  for (int n = 0; n < 3; ++n) {
    datasets::WritePng16((folder / "depth" / (std::to_string(n) + ".png")).string(), depth);
    associations << n << " depth/" << n << ".png " << n << " rgb/" << n << ".png\n";
    gt << n << " 0 0 " << 0.01 * n << " 0 0 0 1\n";
  }
  return folder;
}

TEST(SensorProfiles, IclNuimLayoutGetsIclCameraAndKinectDetection) {
  const fs::path dir = ScratchDir();
  const fs::path folder = MakeIclFolder(dir);
  const CliResult r = RunCli("run " + folder.string() + " --print-config", dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("ICL-NUIM layout"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("config/icl_nuim.yaml, config/detection_kinect.yaml"), std::string::npos)
      << r.err;
  EXPECT_EQ(r.out,
            PrintConfig("run " + folder.string() + " --sensor none -c " + Config("icl_nuim.yaml") +
                            " -c " + Config("detection_kinect.yaml"),
                        dir));
  const CliResult run = RunCli(
      "run " + folder.string() + " -q --set octomap.enabled=false --out " + (dir / "out").string(),
      dir);
  EXPECT_EQ(run.exit_code, 0) << run.err;
}

TEST(SensorProfiles, TumFolderGetsTheReadmeConfigs) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path dir = ScratchDir();
  const std::string tum = (DataDir() / "tum_fr3_structure_notexture_far").string();
  const std::string readme =
      " --sensor none -c " + Config("tum_fr3.yaml") + " -c " + Config("detection_kinect.yaml");
  for (const std::string command : {"run ", "bench odometry "}) {
    SCOPED_TRACE(command);
    EXPECT_EQ(PrintConfig(command + tum, dir), PrintConfig(command + tum + readme, dir));
  }
  // A depth image inside the folder gets the folder's profile.
  const std::string png = tum + "/depth/1341836537.655691.png --out x";
  EXPECT_EQ(PrintConfig("detect " + png, dir), PrintConfig("detect " + png + readme, dir));
  const CliResult r = RunCli("run " + tum + " --print-config", dir);
  EXPECT_NE(r.err.find("TUM RGB-D fr3 layout"), std::string::npos) << r.err;
  // -c and --set still override the profile.
  EXPECT_NE(
      PrintConfig("run " + tum + " --set run.decimation=1", dir).find("  decimation: 1      "),
      std::string::npos);
}

TEST(SensorProfiles, SensorOptionNamesAProfileOrTurnsTheGuessOff) {
  const fs::path dir = ScratchDir();
  const fs::path folder = MakeIclFolder(dir);
  EXPECT_EQ(PrintConfig("run " + folder.string() + " --sensor none", dir), PrintConfig("run", dir));
  EXPECT_EQ(
      PrintConfig("run " + folder.string() + " --sensor laser", dir),
      PrintConfig("run -c " + Config("laser_scan.yaml") + " -c " + Config("detection_laser.yaml"),
                  dir));
  const CliResult bad = RunCli("run " + folder.string() + " --sensor kinect2 --print-config", dir);
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("--sensor: unknown profile 'kinect2'"), std::string::npos) << bad.err;
}

TEST(SensorProfiles, SimulatedRoomGetsTheSimulatorsDetectionProfile) {
  const fs::path dir = ScratchDir();
  const fs::path room = dir / "room";
  ASSERT_EQ(RunCli("simulate room --frames 2 -q --out " + room.string(), dir).exit_code, 0);
  const CliResult r = RunCli("run " + room.string() + " --print-config", dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("planeslam simulate output (config.yaml: scene room"), std::string::npos)
      << r.err;
  EXPECT_EQ(r.out, PrintConfig("run " + room.string() + " --sensor none -c " +
                                   Config("detection_synthetic.yaml"),
                               dir));
  // One of its depth images, named from inside the folder as from outside: the same profile and
  // the folder's camera.
  std::string image;
  for (const auto& entry : fs::directory_iterator(room / "depth")) {
    image = entry.path().filename().string();
  }
  ASSERT_FALSE(image.empty());
  for (const auto& [png, cwd] : {std::pair{(room / "depth" / image).string(), fs::path()},
                                 std::pair{"depth/" + image, room}}) {
    const fs::path out = dir / ("det" + std::to_string(cwd.empty()));
    const CliResult d = RunCli("detect " + png + " -q --out " + out.string(), dir, cwd);
    ASSERT_EQ(d.exit_code, 0) << png << ": " << d.err;
    EXPECT_NE(d.err.find("image of a dataset folder: planeslam simulate output"), std::string::npos)
        << d.err;
    EXPECT_NE(d.err.find("(the image's dataset folder)"), std::string::npos) << d.err;
  }
}

TEST(SensorProfiles, KittiAndLaserFoldersGetTheirConfigs) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path dir = ScratchDir();
  const std::string kitti = (DataDir() / "kitti_velodyne").string();
  EXPECT_EQ(PrintConfig("run " + kitti, dir),
            PrintConfig("run " + kitti + " --sensor none -c " + Config("kitti_hdl64.yaml"), dir));
  const std::string laser = (DataDir() / "laser_scans").string();
  EXPECT_EQ(PrintConfig("run " + laser, dir),
            PrintConfig("run " + laser + " --sensor none -c " + Config("laser_scan.yaml") + " -c " +
                            Config("detection_laser.yaml"),
                        dir));
  // Kinect-sized organized PCDs are not taken for a laser.
  const CliResult r =
      RunCli("run " + (DataDir() / "organized_pcd").string() + " --print-config", dir);
  EXPECT_NE(r.err.find("no sensor profile"), std::string::npos) << r.err;
}

// A single depth image: intrinsics.yaml beside it, else a sensor section the user set; where
// nothing tells the camera, one line naming the option and no output.
TEST(SensorProfiles, DetectSaysWhichIntrinsicsOrRefuses) {
  const fs::path dir = ScratchDir();
  fs::create_directories(dir / "frame");
  datasets::Image16 depth(320, 240);
  std::fill(depth.data.begin(), depth.data.end(), 2000);  // 2 m in millimetres
  const std::string png = (dir / "frame" / "d.png").string();
  datasets::WritePng16(png, depth);
  const fs::path out = dir / "out";
  CliResult r = RunCli("detect " + png + " --out " + out.string(), dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find(png + ": cannot tell which camera took this 320x240 16-bit depth image: "
                             "give --intrinsics FILE"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(out));

  std::ofstream(dir / "frame" / "intrinsics.yaml")
      << "width: 320\nheight: 240\nfx: 262.5\nfy: 262.5\ncx: 159.5\ncy: 119.5\n"
         "depth_scale: 1000\n";
  r = RunCli("detect " + png + " --out " + out.string(), dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("intrinsics fx 262.5 fy 262.5 cx 159.5 cy 119.5, depth_scale 1000, from " +
                       (dir / "frame" / "intrinsics.yaml").string() + " (beside the image)"),
            std::string::npos)
      << r.err;

  fs::remove(dir / "frame" / "intrinsics.yaml");
  r = RunCli("detect " + png + " --set sensor.width=320 --set sensor.height=240 --set " +
                 "sensor.depth_scale=1000 --out " + (dir / "out2").string(),
             dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("from the sensor section (-c/--set)"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace planeslam::test
