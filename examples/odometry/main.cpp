// Plane odometry over a TUM-layout folder (depth.txt, depth/*.png, optional intrinsics.yaml):
// detects the planes of every frame, registers each frame to the previous one and prints the
// trajectory as TUM lines (t tx ty tz qx qy qz qw) and its length.
//   odometry FOLDER [MAX_FRAMES]
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>

#include "planeslam/datasets/sensor_config.hpp"
#include "planeslam/datasets/tum_sequence.hpp"
#include "planeslam/detection/grid_region_growing.hpp"
#include "planeslam/registration/plane_odometry.hpp"

namespace ds = planeslam::datasets;
namespace det = planeslam::detection;
namespace reg = planeslam::registration;

int main(int argc, char** argv) {
  if (argc != 2 && argc != 3) {
    std::fprintf(stderr, "usage: %s FOLDER [MAX_FRAMES]\n", argv[0]);
    return 2;
  }
  try {
    // Default sensor settings: the folder's intrinsics.yaml when present, else TUM freiburg3.
    const auto sequence = ds::OpenTumSequence(argv[1], ds::SensorConfig{});
    std::size_t frames = sequence->Size();
    if (argc == 3) frames = std::min(frames, static_cast<std::size_t>(std::atol(argv[2])));

    const det::GridRegionGrowing detector(det::DetectionParams{}, det::GridParams{});
    reg::PlaneOdometry odometry;
    odometry.SetIntrinsics(sequence->intrinsics());
    double length = 0.0;
    for (std::size_t i = 0; i < frames; ++i) {
      const ds::Frame frame = sequence->Load(i);
      const reg::OdometryStep step = odometry.Track(frame.timestamp, frame.cloud, detector);
      length += step.T_prev_curr.translation().norm();
      const Eigen::Vector3d t = step.T_world_sensor.translation();
      Eigen::Quaterniond q(step.T_world_sensor.rotation());
      if (q.w() < 0) q.coeffs() = -q.coeffs();
      std::printf("%.6f %.6f %.6f %.6f %.6f %.6f %.6f %.6f\n", frame.timestamp, t.x(), t.y(),
                  t.z(), q.x(), q.y(), q.z(), q.w());
    }
    std::printf("# %zu frames, path length %.4f m\n", frames, length);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
