// Config sections of the mapping module (see config_sections_mapping.hpp).
#include "config_sections_mapping.hpp"

namespace planeslam::app {
namespace {

void VisitPoseGraph(FieldVisitor& v, mapping::PoseGraphConfig& c) {
  v.Field("max_iterations", c.max_iterations,
          "Levenberg-Marquardt iterations at most (Ceres' pose_graph_3d example: 200)", 0, 100000);
  v.Field("function_tolerance", c.function_tolerance,
          "stop when the relative cost decrease is below this (Ceres default 1e-6)", 0.0, 1.0);
  v.Field("gradient_tolerance", c.gradient_tolerance,
          "stop when the relative gradient is below this (Ceres default 1e-10)", 0.0, 1.0);
  v.Field("parameter_tolerance", c.parameter_tolerance,
          "stop when the relative step is below this (Ceres default 1e-8)", 0.0, 1.0);
  v.Field("loop_closure_loss", c.loop_closure_loss,
          "robust loss on loop-closure edges only (odometry stays least squares)",
          {"none", "huber", "cauchy"});
  v.Field("loop_closure_loss_scale", c.loop_closure_loss_scale,
          "loss scale in whitened residual units: quadratic below it; 3.55 = sqrt of the 95% "
          "chi-square quantile with 6 degrees of freedom",
          1e-9, 1e9);
  v.Field("num_threads", c.num_threads, "Ceres threads for Jacobian evaluation", 1, 256);
}

std::vector<std::string> ValidatePoseGraph(const mapping::PoseGraphConfig& c) {
  return c.Validate();
}

PLANESLAM_REGISTER_CONFIG_SECTION(mapping::PoseGraphConfig, "pose_graph",
                                  "Pose graph optimisation (Ceres, Levenberg-Marquardt, sparse "
                                  "normal Cholesky; first or FIX poses held constant)",
                                  &VisitPoseGraph, &ValidatePoseGraph);

}  // namespace
}  // namespace planeslam::app
