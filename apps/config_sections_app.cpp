// Config sections owned by the app layer itself.
#include "config_sections_app.hpp"

#include "config.hpp"

namespace planeslam::app {
namespace {

void VisitOutput(FieldVisitor& v, OutputConfig& c) {
  v.Field("directory", c.directory, "default output folder of 'planeslam run' when --out is not given", {});
}

void VisitReport(FieldVisitor& v, ReportConfig& c) {
  v.Field("enabled", c.enabled,
          "write report.html (3-D plane map, trajectory, plots, summary) beside the outputs of "
          "'run' and 'detect'");
  v.Field("cloud_points", c.cloud_points,
          "most points of the keyframe cloud shown in the report (voxel-thinned to fit); 0 = none",
          0, 2000000);
}

PLANESLAM_REGISTER_CONFIG_SECTION(OutputConfig, "output", "Output files", &VisitOutput);
PLANESLAM_REGISTER_CONFIG_SECTION(ReportConfig, "report", "HTML report", &VisitReport);

}  // namespace
}  // namespace planeslam::app
