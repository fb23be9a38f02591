#pragma once
/// Config section "output" owned by the app layer.
#include <string>

namespace planeslam::app {

/// Where outputs go.
struct OutputConfig {
  std::string directory = "planeslam_out";  ///< default output folder of `run`
};

}  // namespace planeslam::app
