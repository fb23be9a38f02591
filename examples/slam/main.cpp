// Plane SLAM over a TUM-layout folder (depth.txt, depth/*.png, optional intrinsics.yaml): detects
// the planes of every frame, tracks them against keyframes, keeps a plane map and a pose graph
// optimised with Ceres, then writes the trajectory (TUM) and the plane map (PLY) into OUT_DIR.
//   slam FOLDER OUT_DIR [MAX_FRAMES]
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <string>

#include "planeslam/datasets/sensor_config.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "planeslam/datasets/tum_sequence.hpp"
#include "planeslam/detection/grid_region_growing.hpp"
#include "planeslam/mapping/map_writers.hpp"
#include "planeslam/mapping/slam_system.hpp"

namespace ds = planeslam::datasets;
namespace det = planeslam::detection;
namespace reg = planeslam::registration;
namespace mapping = planeslam::mapping;

int main(int argc, char** argv) {
  if (argc != 3 && argc != 4) {
    std::fprintf(stderr, "usage: %s FOLDER OUT_DIR [MAX_FRAMES]\n", argv[0]);
    return 2;
  }
  try {
    const auto sequence = ds::OpenTumSequence(argv[1], ds::SensorConfig{});
    std::size_t frames = sequence->Size();
    if (argc == 4) frames = std::min(frames, static_cast<std::size_t>(std::atol(argv[3])));

    // Every setting at its documented default (the installed headers list them).
    const det::GridRegionGrowing detector(det::DetectionParams{}, det::GridParams{});
    mapping::SlamSystem slam(mapping::SlamConfig{}, reg::AssociationConfig{},
                             reg::RegistrationConfig{}, reg::PointToPlaneConfig{},
                             mapping::PoseGraphConfig{}, mapping::PlaneMapConfig{});
    for (std::size_t i = 0; i < frames; ++i) {
      const ds::Frame frame = sequence->Load(i);
      slam.ProcessFrame(frame.timestamp, frame.cloud, detector.Detect(frame.cloud));
    }
    const mapping::PoseGraphResult optimisation = slam.Finish();

    const std::string out = argv[2];
    std::filesystem::create_directories(out);
    ds::WriteTumTrajectory(out + "/trajectory_tum.txt", slam.EstimatedTrajectory());
    mapping::WritePlaneMapPly(out + "/plane_map.ply", mapping::MakeMapRecords(slam.map()));
    std::printf("# %zu frames, %zu keyframes, %zu map planes, final cost %.6g (%s)\n", frames,
                slam.stats().keyframes, slam.map().size(), optimisation.final_cost,
                optimisation.termination.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
