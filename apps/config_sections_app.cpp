// Config sections owned by the app layer itself.
#include "config.hpp"

namespace planeslam::app {
namespace {

/// Where outputs go and how much is written.
struct OutputConfig {
  std::string directory = "planeslam_out";  ///< default output folder of `run`
};

void VisitOutput(FieldVisitor& v, OutputConfig& c) {
  v.Field("directory", c.directory, "default output folder of 'planeslam run' when --out is not given", {});
}

PLANESLAM_REGISTER_CONFIG_SECTION(OutputConfig, "output", "Output files", &VisitOutput);

}  // namespace
}  // namespace planeslam::app
