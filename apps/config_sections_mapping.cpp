// Config sections of the mapping module (see config_sections_mapping.hpp).
#include "config_sections_mapping.hpp"

namespace planeslam::app {
namespace {

void VisitPoseGraph(FieldVisitor& v, mapping::PoseGraphConfig& c) {
  v.Field("max_iterations", c.max_iterations,
          "[iterations] Levenberg-Marquardt iterations at most (Ceres' pose_graph_3d example: 200)",
          0, 100000);
  v.Field("function_tolerance", c.function_tolerance,
          "[-] stop when the relative cost decrease is below this (Ceres default 1e-6)", 0.0, 1.0);
  v.Field("gradient_tolerance", c.gradient_tolerance,
          "[-] stop when the relative gradient is below this (Ceres default 1e-10)", 0.0, 1.0);
  v.Field("parameter_tolerance", c.parameter_tolerance,
          "[-] stop when the relative step is below this (Ceres default 1e-8)", 0.0, 1.0);
  v.Field("loop_closure_loss", c.loop_closure_loss,
          "robust loss on loop-closure edges only (odometry stays least squares)",
          {"none", "huber", "cauchy"});
  v.Field("loop_closure_loss_scale", c.loop_closure_loss_scale,
          "[-] loss scale in whitened residual units: quadratic below it; 3.55 = sqrt of the 95% "
          "chi-square quantile with 6 degrees of freedom",
          1e-9, 1e9);
  v.Field("num_threads", c.num_threads, "[threads] Ceres threads for Jacobian evaluation", 1, 256);
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

// ------------------------------------------------------------------------------------------------
// Sections "plane_map" and "octomap" (owned by the plane map / OctoMap code: mapping/plane_map.hpp,
// mapping/occupancy_map.hpp).
#include "planeslam/mapping/occupancy_map.hpp"
#include "planeslam/mapping/plane_map.hpp"

namespace planeslam::app {
namespace {

void VisitPlaneMap(FieldVisitor& v, mapping::PlaneMapConfig& c) {
  v.Field("max_normal_angle_deg", c.max_normal_angle_deg,
          "[deg] largest angle between an observed plane's normal and a map plane's to associate",
          0.0, 90.0);
  v.Field("max_offset", c.max_offset,
          "[m] largest distance of an observed plane's centroid from a map plane to associate", 0.0,
          100.0);
  v.Field("max_offset_range_coeff", c.max_offset_range_coeff,
          "[1/m] the offset gate grows by this times the squared range of the observed plane's "
          "centroid (depth noise; 0.0043 = 3 sigma of the Kinect model 1.425e-3 z^2)",
          0.0, 1.0);
  v.Field("max_gap", c.max_gap,
          "[m] largest gap between an observed plane's extent and a map plane's (spatial overlap "
          "test: coplanar surfaces farther apart stay separate planes)",
          0.0, 100.0);
  v.Field("min_touch_points", c.min_touch_points,
          "[samples] observed samples within max_gap of a map plane needed to call them touching",
          1, 1000000);
  v.Field("merge_max_normal_angle_deg", c.merge_max_normal_angle_deg,
          "[deg] largest angle between two map planes to merge them into one", 0.0, 90.0);
  v.Field("merge_max_offset", c.merge_max_offset,
          "[m] largest distance of each map plane's centroid from the other to merge them", 0.0,
          100.0);
  v.Field("merge_across_gaps", c.merge_across_gaps,
          "in the finished map, merge map planes within the merge thresholds even when their "
          "extents are apart (one plane seen in separate parts; the outline keeps each part)");
  v.Field("refit_merge_across_gaps_offset", c.refit_merge_across_gaps_offset,
          "[m] during SLAM, map planes whose extents are apart merge (one landmark) when each "
          "centroid lies within this of the other plane; 0 = only touching planes merge",
          0.0, 100.0);
  v.Field("min_observation_points", c.min_observation_points,
          "[points] detected planes with fewer points are not added to the map", 3, 100000000);
  v.Field("sample_cell_size", c.sample_cell_size,
          "[m] grid cell of the points kept per observation for outlines and overlap tests", 1e-4,
          100.0);
  v.Field("max_samples_per_observation", c.max_samples_per_observation,
          "[samples] memory bound per observation: the sample cell doubles until below this", 16,
          100000000);
  v.Field("sample_pixel_stride", c.sample_pixel_stride,
          "[px] every n-th row and column of depth-camera frames feeds the samples (LiDAR range "
          "images: always every pixel)",
          1, 64);
  v.Field("polygon_cell_size", c.polygon.cell_size,
          "[m] grid cell of the outline (concave hull); 0 = automatic from the sample density", 0.0,
          100.0);
  v.Field("polygon_simplify_tolerance", c.polygon.simplify_tolerance,
          "[m] Douglas-Peucker tolerance of the outline; 0 = one cell, < 0 = none", -1.0, 100.0);
}

std::vector<std::string> ValidatePlaneMap(const mapping::PlaneMapConfig& c) { return c.Validate(); }

PLANESLAM_REGISTER_CONFIG_SECTION(mapping::PlaneMapConfig, "plane_map",
                                  "Global plane map: association of detected planes, merging, "
                                  "outlines (plane_map.ply/.obj/.json)",
                                  &VisitPlaneMap, &ValidatePlaneMap);

void VisitOctomap(FieldVisitor& v, mapping::OccupancyMapConfig& c) {
  v.Field("enabled", c.enabled,
          "build an OctoMap from the keyframes and write octomap.bt (needs a build with OctoMap)");
  v.Field("resolution", c.resolution, "[m] leaf voxel edge", 1e-3, 100.0);
  v.Field("max_range", c.max_range,
          "[m] rays longer than this only clear free space up to it; <= 0 = unlimited", -1.0, 1e6);
  v.Field("downsample_voxel", c.downsample_voxel,
          "[m] voxel grid applied to each frame before ray casting; 0 = off", 0.0, 100.0);
  v.Field("prob_hit", c.prob_hit, "[probability] occupancy update of a ray's end voxel (> 0.5)",
          0.5, 1.0);
  v.Field("prob_miss", c.prob_miss,
          "[probability] occupancy update of the voxels a ray traverses (< 0.5)", 0.0, 0.5);
}

std::vector<std::string> ValidateOctomap(const mapping::OccupancyMapConfig& c) {
  return c.Validate();
}

PLANESLAM_REGISTER_CONFIG_SECTION(mapping::OccupancyMapConfig, "octomap",
                                  "OctoMap output (octomap.bt, binary maximum-likelihood OcTree)",
                                  &VisitOctomap, &ValidateOctomap);

}  // namespace
}  // namespace planeslam::app
