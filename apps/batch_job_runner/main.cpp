// planeslam-batch-job DIR NAME [--time-limit SECONDS] -- PLANESLAM run ARGS...
// One job of `planeslam batch` (batch_job.hpp), as GNU parallel and the Slurm script run it. It is
// `planeslam batch job` without the rest of the executable: it starts in about a millisecond where
// loading planeslam's libraries takes a tenth of a second, which adds up over many short jobs.
#include <cstdlib>
#include <exception>
#include <iostream>
#include <string>
#include <vector>

#include "batch_job.hpp"
#include "exit_codes.hpp"

int main(int argc, char** argv) {
  namespace app = planeslam::app;
  std::vector<std::string> args(argv + 1, argv + argc);
  double time_limit_s = 0.0;
  std::vector<std::string> positional, command;
  for (std::size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "--") {
      command.assign(args.begin() + static_cast<std::ptrdiff_t>(i) + 1, args.end());
      break;
    }
    if (args[i] == "--time-limit" && i + 1 < args.size()) {
      time_limit_s = std::atof(args[++i].c_str());
    } else {
      positional.push_back(args[i]);
    }
  }
  if (positional.size() != 2 || command.size() < 2) {
    std::cerr << "usage: planeslam-batch-job DIR SEQUENCE/VARIANT [--time-limit SECONDS] -- "
                 "PLANESLAM run ARGS...\n";
    return app::kExitError;
  }
  try {
    return app::RunBatchJob(positional[0], positional[1], time_limit_s, command);
  } catch (const std::exception& e) {
    std::cerr << "planeslam-batch-job: error: " << positional[1] << ": " << e.what() << "\n";
    return app::kExitError;
  }
}
