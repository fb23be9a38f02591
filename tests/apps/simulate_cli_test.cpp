// `planeslam simulate` end to end: the folder reads back through the TUM reader with ground truth
// for every frame, options reach the generator, and errors are one line with exit code 2.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "config_sections_synthetic.hpp"
#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "planeslam/datasets/synthetic_writer.hpp"
#include "cli_support.hpp"
#include "test_support.hpp"

namespace planeslam::app {
namespace {

namespace fs = std::filesystem;

using test::CliResult;
using test::Slurp;

CliResult RunSimulate(const std::string& args, const fs::path& dir) {
  return test::RunCli("simulate " + args, dir);
}

/// Width and height from a PNG's IHDR chunk (big-endian at bytes 16..23).
std::pair<int, int> PngSize(const fs::path& path) {
  const std::string b = Slurp(path);
  if (b.size() < 24) return {0, 0};
  auto be = [&b](std::size_t o) {
    return (static_cast<unsigned char>(b[o]) << 24) | (static_cast<unsigned char>(b[o + 1]) << 16) |
           (static_cast<unsigned char>(b[o + 2]) << 8) | static_cast<unsigned char>(b[o + 3]);
  };
  return {static_cast<int>(be(16)), static_cast<int>(be(20))};
}

/// The simulation sections of a saved config.yaml applied to a default Config (the file also
/// holds sections of commands this test executable does not link).
Config LoadSimulationSections(const fs::path& path) {
  Config config;
  const YAML::Node root = YAML::LoadFile(path.string());
  for (const char* section : {"simulation", "simulation_pinhole", "simulation_spherical"}) {
    for (const auto& kv : root[section]) {
      config.Set(std::string(section) + "." + kv.first.as<std::string>() + "=" +
                 kv.second.as<std::string>());
    }
  }
  return config;
}

TEST(SimulateCli, RoomReadsBackAsTumSequenceWithGroundTruth) {
  const fs::path dir = test::ScratchDir();
  const fs::path out = dir / "room";
  const CliResult r = RunSimulate("room --out " + out.string() + " --frames 5", dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("frames     5"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("preview.png"), std::string::npos) << r.out;

  EXPECT_EQ(datasets::DetectLayout(out.string()), datasets::SequenceLayout::kTum);
  const auto seq = datasets::OpenSequence(out.string(), datasets::SensorConfig{});
  ASSERT_EQ(seq->Size(), 5u);
  // The same sequence in memory from the same (default) config.
  const auto mem = MakeSyntheticSequence("room", Config());
  for (std::size_t i = 0; i < seq->Size(); ++i) {
    const auto gt = seq->GroundTruth(i);
    ASSERT_TRUE(gt.has_value()) << i;
    EXPECT_LT((gt->matrix() - mem->GroundTruth(i)->matrix()).cwiseAbs().maxCoeff(), 1e-15);
    const datasets::Frame f = seq->Load(i);
    EXPECT_GT(f.cloud.CountValid(), f.cloud.size() / 2);
  }
  const auto preview = PngSize(out / "preview.png");
  EXPECT_EQ(preview.first, 2 * 640);
  EXPECT_EQ(preview.second, 480);
  EXPECT_EQ(datasets::ReadPng16((out / "labels" / "0.000000.png").string()).data,
            mem->Labels(0).data);
  // The effective config is saved with the data and reproduces it.
  const Config saved = LoadSimulationSections(out / "config.yaml");
  EXPECT_EQ(saved.Get<SimulationConfig>("simulation").frames, 5);
  EXPECT_EQ(saved.Get<SimulationConfig>("simulation").scene, "room");
}

TEST(SimulateCli, OptionsReachTheGenerator) {
  const fs::path dir = test::ScratchDir();
  const fs::path out = dir / "c";
  const CliResult r =
      RunSimulate("corridor --out " + out.string() + " --frames 3 --no-noise --seed 9 --quiet "
                  "--set simulation.rate=10",
                  dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(r.out.empty()) << r.out;  // --quiet
  const Config saved = LoadSimulationSections(out / "config.yaml");
  const auto& sim = saved.Get<SimulationConfig>("simulation");
  EXPECT_FALSE(sim.noise);
  EXPECT_EQ(sim.seed, 9);
  EXPECT_EQ(sim.rate, 10.0);
  // Frames at 10 Hz; without noise the depth PNG holds the exact depth to 1/5000 m.
  EXPECT_NE(Slurp(out / "depth.txt").find("0.100000 depth/0.100000.png"), std::string::npos);
  const auto mem = MakeSyntheticSequence("", saved);
  const datasets::SyntheticFrame f = mem->Generate(2);
  const datasets::Image16 depth = datasets::ReadPng16((out / "depth" / "0.200000.png").string());
  for (std::size_t i = 0; i < depth.data.size(); ++i) {
    if (depth.data[i] == 0) continue;
    ASSERT_NEAR(depth.data[i] / 5000.0, f.true_range[i], 0.5 / 5000.0 + 1e-6) << i;
  }
}

TEST(SimulateCli, SphericalWritesOrganizedPcd) {
  const fs::path dir = test::ScratchDir();
  const fs::path out = dir / "s";
  const CliResult r = RunSimulate(
      "rubble --out " + out.string() + " --frames 2 --sensor spherical --quiet "
      "--set simulation_spherical.azimuth_resolution_deg=2 "
      "--set simulation_spherical.elevation_resolution_deg=2",
      dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(out / "0.000000.pcd"));
  EXPECT_TRUE(fs::exists(out / "scanner.yaml"));
  EXPECT_EQ(PngSize(out / "preview.png").first, 2 * 180);
  EXPECT_EQ(PngSize(out / "preview.png").second, 46);
}

TEST(SimulateCli, BadInputIsOneLineAndExitCode) {
  const fs::path dir = test::ScratchDir();
  CliResult r = RunSimulate("kitchen --out " + (dir / "k").string(), dir);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_FALSE(fs::exists(dir / "k"));
  r = RunSimulate("room --out " + (dir / "x").string() +
                      " --set simulation_pinhole.min_depth=9 --set simulation_pinhole.max_depth=8",
                  dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("min_depth must be below max_depth"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_FALSE(fs::exists(dir / "x"));
}

TEST(SimulateCli, ConfigFilesLoad) {
  for (const char* name : {"sim_room.yaml", "sim_corridor.yaml", "sim_rubble.yaml"}) {
    Config config;
    config.LoadFile((fs::path(PLANESLAM_SOURCE_DIR) / "config" / name).string());
    const auto seq = MakeSyntheticSequence("", config);
    const std::string scene = config.Get<SimulationConfig>("simulation").scene;
    EXPECT_EQ(seq->Name(), "synthetic_" + scene);
    // Each file documents its frame count; it matches the generator.
    const std::string text = Slurp(fs::path(PLANESLAM_SOURCE_DIR) / "config" / name);
    EXPECT_NE(text.find(std::to_string(seq->Size()) + " frames"), std::string::npos) << name;
  }
}

}  // namespace
}  // namespace planeslam::app
