// `planeslam simulate SCENE --out DIR`: a synthetic sequence with exact ground truth, written in
// the TUM layout (pinhole), as an organized PCD folder (spherical) or in the KITTI odometry layout
// (rotating LiDAR), see synthetic_writer.hpp.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>

#include "exit_codes.hpp"
#include "cli_common.hpp"
#include "command_registry.hpp"
#include "config_sections_synthetic.hpp"
#include "interrupt.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/synthetic_writer.hpp"

namespace planeslam::app {
namespace {

namespace ds = planeslam::datasets;

std::string HumanBytes(std::size_t bytes) {
  char buffer[64];
  if (bytes >= 10u * 1024 * 1024) {
    std::snprintf(buffer, sizeof(buffer), "%.1f MB", bytes / (1024.0 * 1024.0));
  } else {
    std::snprintf(buffer, sizeof(buffer), "%.1f kB", bytes / 1024.0);
  }
  return buffer;
}

class SimulateCommand : public Command {
 public:
  std::string Name() const override { return "simulate"; }
  std::string Summary() const override {
    return "Synthetic sequence (room, corridor, rubble, street) with exact poses, plane labels and "
           "planes";
  }
  int Order() const override { return 40; }

  void Setup(CLI::App& sub) override {
    sub.add_option("scene", scene_,
                   "room (office-like), corridor (degenerate), rubble (unstructured), street "
                   "(urban block, 64-beam LiDAR)")
        ->required()
        ->check(CLI::IsMember({"room", "corridor", "rubble", "street"}));
    sub.add_option("-o,--out", out_, "output folder (created)")->required();
    sub.add_option("--frames", frames_, "number of frames (default: the scene's whole path)")
        ->check(CLI::Range(1, 1000000));
    sub.add_option("--sensor", sensor_,
                   "pinhole (depth camera, TUM layout), spherical (scanner, PCD) or lidar "
                   "(rotating 64-beam, KITTI layout); default: the scene's (street: lidar, else "
                   "pinhole)")
        ->check(CLI::IsMember({"pinhole", "spherical", "lidar"}));
    noise_opt_ = sub.add_flag("--noise,!--no-noise", noise_,
                              "sensor noise on/off (default: simulation.noise, on)");
    sub.add_option("--seed", seed_, "seed of the rubble and street layouts and the noise")
        ->check(CLI::Range(0, 2147483647));
    AddConfigOptions(sub, options_);
    sub.footer(
        "Examples:\n"
        "  planeslam simulate room --out room             TUM-layout depth sequence + ground truth\n"
        "  planeslam simulate corridor --out c --frames 100 --no-noise\n"
        "  planeslam simulate rubble --out r --sensor spherical --seed 7\n"
        "  planeslam simulate room --out r --config config/sim_room.yaml --set simulation.rate=15\n"
        "  planeslam simulate street --out street --set simulation.laps=0.3\n"
        "Writes depth/*.png + depth.txt + intrinsics.yaml (pinhole) or *.pcd + scanner.yaml\n"
        "(spherical), labels/*.png (plane id per pixel), groundtruth.txt, planes.json, preview.png\n"
        "and config.yaml. The LiDAR (street) writes the KITTI odometry layout: velodyne/*.bin,\n"
        "labels/*.label (plane id per return), times.txt, poses.txt (scanner poses in the first\n"
        "scan's frame, KITTI 3x4), calib.txt, scanner.yaml, planes.json, preview.png, config.yaml.");
  }

  int Run() override {
    Config config = LoadConfig(options_);
    auto& sim = config.Get<SimulationConfig>("simulation");
    sim.scene = scene_;
    if (frames_ > 0) sim.frames = frames_;
    if (!sensor_.empty()) sim.sensor = sensor_;
    if (noise_opt_->count() > 0) sim.noise = noise_;
    if (seed_ >= 0) sim.seed = seed_;
    if (MaybePrintConfig(options_, config)) return 0;

    const auto sequence = MakeSyntheticSequence(scene_, config);
    sim.sensor = sequence->config().sensor;  // config.yaml names the sensor used
    sim.rate = sequence->config().trajectory.rate;
    EnsureDirectory(out_);
    ds::WriteFileAtomic((std::filesystem::path(out_) / "config.yaml").string(), config.ToYaml());
    InstallInterruptHandlers();
    ProgressBar bar("simulate " + scene_, sequence->Size(), options_.quiet);
    const auto t0 = std::chrono::steady_clock::now();
    const ds::SyntheticWriteSummary summary =
        ds::WriteSyntheticSequence(*sequence, out_, [&bar](std::size_t done) {
          bar.Update(done);
          return !StopRequested();
        });
    bar.Finish();
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!options_.quiet) {
      const auto& c = sequence->config();
      std::cout << "scene      " << scene_ << " (" << sequence->scene().planes.size()
                << " planes, " << sequence->scene().spheres.size() << " spheres, "
                << sequence->scene().cylinders.size() << " cylinders), seed " << c.seed << "\n"
                << "sensor     " << c.sensor << " " << sequence->sensor().Width() << "x"
                << sequence->sensor().Height() << ", noise " << (sim.noise ? "on" : "off") << "\n"
                << "frames     " << summary.frames << (summary.frames < sequence->Size()
                                                          ? " (interrupted)" : "")
                << " at " << c.trajectory.rate << " Hz\n"
                << "written    " << summary.files + 1 << " files, " << HumanBytes(summary.bytes)
                << " in " << out_ << "\n";
      char line[128];
      std::snprintf(line, sizeof(line), "time       %.2f s (%.1f ms/frame incl. file encoding)\n",
                    seconds, 1000.0 * seconds / std::max<std::size_t>(1, summary.frames));
      std::cout << line << "preview    " << summary.preview_path << "\n";
    }
    return summary.frames < sequence->Size() ? kExitInterrupted : kExitSuccess;
  }

 private:

  std::string scene_;
  std::string out_;
  int frames_ = 0;
  std::string sensor_;
  bool noise_ = true;
  CLI::Option* noise_opt_ = nullptr;
  int seed_ = -1;
  ConfigOptions options_;
};

PLANESLAM_REGISTER_COMMAND(SimulateCommand);

}  // namespace
}  // namespace planeslam::app
