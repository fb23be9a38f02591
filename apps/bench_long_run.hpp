#pragma once
/// `planeslam bench long-run`: SLAM that stays right over long runs and against wrong loop
/// closures, on the synthetic scenes (in memory, exact ground truth): the many-lap room per noise
/// seed, the room with injected false closures, and the aliasing ring with loop closure on and
/// off. Per case: ATE, the largest error with the estimate aligned on its first 300 frames
/// (a split map shows as a jump), map planes, closures accepted / false accepted, the share of
/// the run spent optimising, and the SLAM time per frame of the last 500 frames over the first.
#include <string>
#include <vector>

#include "cli_common.hpp"

namespace planeslam::app::bench {

struct LongRunOptions {
  double laps = 15.0;                      ///< of the long room runs
  std::vector<int> seeds{1, 2, 3, 4};      ///< noise seeds of the long room runs
  std::vector<int> injected{10, 50, 200};  ///< false closures injected into the built-in room
  std::string json_path;                   ///< empty = none
  bool quiet = false;
};

/// Runs the cases, prints a table; returns the exit code.
int RunLongRunBench(const ConfigOptions& config_options, const LongRunOptions& options);

}  // namespace planeslam::app::bench
