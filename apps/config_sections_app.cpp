// Config sections owned by the app layer itself.
#include "config_sections_app.hpp"

#include "config.hpp"

namespace planeslam::app {
namespace {

void VisitOutput(FieldVisitor& v, OutputConfig& c) {
  v.Field("directory", c.directory, "default output folder of 'planeslam run' when --out is not given", {});
}

PLANESLAM_REGISTER_CONFIG_SECTION(OutputConfig, "output", "Output files", &VisitOutput);

}  // namespace
}  // namespace planeslam::app
