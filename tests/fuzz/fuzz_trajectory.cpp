// Fuzzes the TUM, KITTI and EuRoC trajectory readers.
#include <cstdint>
#include <string>

#include "fuzz_support.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/trajectory_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace ds = planeslam::datasets;
  const std::string path = planeslam::fuzz::WriteTemp(data, size, ".traj");
  for (auto format : {ds::TrajectoryFormat::kTum, ds::TrajectoryFormat::kKitti,
                      ds::TrajectoryFormat::kEuroc}) {
    try {
      const ds::Trajectory t = ds::ReadTrajectory(path, format);
      for (std::size_t i = 1; i < t.size(); ++i) {
        if (!(t.stamps[i] > t.stamps[i - 1])) __builtin_trap();  // sorted, no duplicates
      }
      for (const auto& pose : t.poses) {
        if (!pose.matrix().allFinite()) __builtin_trap();
      }
    } catch (const planeslam::IoError&) {
    }
  }
  return 0;
}
