// Config sections of the detection module: "detection" (shared thresholds), "grid" (GBRG) and
// "point" (PBRG). Sensor-tuned values: config/detection_kinect.yaml, detection_laser.yaml,
// detection_synthetic.yaml.
#include "config.hpp"
#include "detector_factory.hpp"

namespace planeslam::app {
namespace {

void VisitDetection(FieldVisitor& v, DetectionSection& c) {
  auto& p = c.params;
  v.Field("method", c.method,
          "detector: grid (GBRG), grid-fast (GBRG's grid-level pipeline, fastest), grid-paper "
          "(the paper's GBRG), point (PBRG), point-paper (the paper's PBRG)",
          DetectorMethods());
  v.Field("threshold_model", c.threshold_model,
          "constant: the paper's fixed thresholds; depth: thresholds grow with the sensor noise "
          "sigma(z) = sigma0 + sigma_z2 z^2 along the ray (depth cameras)",
          {"constant", "depth"});
  v.Field("eta_deg", p.eta_deg, "eta: max angle between region and grid normals [deg]", 0.01,
          89.99);
  v.Field("gamma", p.gamma, "gamma: max distance of a grid centre / point to the region plane [m]",
          1e-6, 10.0);
  v.Field("epsilon", p.epsilon, "epsilon: max region MSE (eq. 3) [m^2]", 1e-12, 10.0);
  v.Field("delta", p.delta, "delta: PBRG max 3D distance between range-image neighbours [m]", 1e-6,
          100.0);
  v.Field("theta", p.theta, "theta: min plane size [points] (GBRG: ceil(theta/k^2) grids)", 3,
          100000000);
  v.Field("sigma0", p.sigma0, "sensor noise at zero range, along the ray [m]", 0.0, 10.0);
  v.Field("sigma_z2", p.sigma_z2,
          "quadratic depth noise: sigma = sigma0 + sigma_z2 z^2 (Kinect 1.425e-3) [1/m]", 0.0, 1.0);
  v.Field("gamma_sigmas", p.gamma_sigmas, "depth model: gamma + this many sigma_n [1]", 0.0, 100.0);
  v.Field("delta_sigmas", p.delta_sigmas, "depth model: delta + this many sigma(z) [1]", 0.0,
          1000.0);
  v.Field("epsilon_sigmas", p.epsilon_sigmas,
          "depth model: sqrt(epsilon) + this many rms sigma_n of the region [1]", 0.0, 100.0);
  v.Field("epsilon_count_sigmas", p.epsilon_count_sigmas,
          "depth model: the epsilon factor grows by this many sqrt(2/K) for a region of K points "
          "(the spread of its MSE under the noise model) [1]",
          0.0, 100.0);
  v.Field("eta_sigmas", p.eta_sigmas,
          "depth model: eta + this many std devs of a grid's normal noise [1]", 0.0, 100.0);
  v.Field("planar_sigmas", p.planar_sigmas,
          "depth model: a grid whose rms residual is within this many sigma_n is planar [1]", 0.0,
          100.0);
  v.Field("refine_boundary", p.refine_boundary,
          "GBRG: re-assign the pixels of border grids to the best-fitting adjacent plane (off: "
          "every pixel keeps its grid's label, and the ray fit moves no pixel at a crease)");
  v.Field(
      "refine_sigmas", p.refine_sigmas,
      "refinement: a pixel joins when |n.p - d| < this many sigma_n (constant model: gamma) [1]",
      0.0, 100.0);
  v.Field("merge_regions", p.merge_regions, "merge adjacent regions that describe one surface");
  v.Field("merge_angle_deg", p.merge_angle_deg, "merging: max angle between normals [deg]", 0.0,
          89.99);
  v.Field("merge_disjoint", p.merge_disjoint,
          "merging: also merge regions that do not touch (a surface seen on both sides of an "
          "occluder)");
  v.Field("ray_fit", p.ray_fit,
          "final planes by least squares of inverse depth along the pixel rays (unbiased under "
          "ray noise); false: the paper's eigen fit");
}

std::vector<std::string> ValidateDetection(const DetectionSection& c) {
  detection::DetectionParams p = c.params;
  detection::ParseThresholdModel(c.threshold_model, p.model);
  return p.Validate();
}

PLANESLAM_REGISTER_CONFIG_SECTION(DetectionSection, "detection",
                                  "Plane detection (Xiao et al. 2011): method and thresholds "
                                  "shared by GBRG and PBRG",
                                  &VisitDetection, &ValidateDetection);

void VisitGrid(FieldVisitor& v, detection::GridParams& c) {
  v.Field("cell_size", c.cell_size,
          "grid side k [px]; 0 = the method's own (grid, grid-paper: 3 as in the paper; "
          "grid-fast: 6)",
          0, 32);
  v.Field("mu", c.mu, "min valid points of a non-sparse grid; 0 = k^2 - k + 1 (paper: 7 for 3x3)",
          0, 1024);
  v.Field("alpha", c.alpha, "linear grid when l2 <= alpha l3 (paper: 0.006)", 1e-9, 0.999999);
  v.Field("beta", c.beta, "planar grid when l1 <= beta l2 (paper: 0.4)", 1e-9, 0.999999);
  v.Field("refit_interval", c.refit_interval,
          "1 = refit the plane on every join (paper); N = every N joins; 0 = adaptive (every "
          "N/64 joins of an N-grid region, exact MSE test)",
          0, 1000000);
}

std::vector<std::string> ValidateGrid(const detection::GridParams& c) { return c.Validate(); }

PLANESLAM_REGISTER_CONFIG_SECTION(detection::GridParams, "grid",
                                  "Grid-based region growing (GBRG, paper Section III)", &VisitGrid,
                                  &ValidateGrid);

void VisitPoint(FieldVisitor& v, detection::PointParams& c) {
  v.Field("seed_neighbours", c.seed_neighbours,
          "seed: min neighbours of the 3x3 window within delta (paper: 6)", 2, 8);
  v.Field("alpha", c.alpha, "seed shape test: linear when l2 <= alpha l3", 1e-9, 0.999999);
  v.Field("beta", c.beta, "seed shape test: planar when l1 <= beta l2", 1e-9, 0.999999);
  v.Field("refit_interval", c.refit_interval,
          "1 = refit the plane for every tested point (paper); N = every N joins; 0 = adaptive "
          "(every K/64 joins, exact MSE test)",
          0, 1000000);
}

std::vector<std::string> ValidatePoint(const detection::PointParams& c) { return c.Validate(); }

PLANESLAM_REGISTER_CONFIG_SECTION(detection::PointParams, "point",
                                  "Point-based region growing (PBRG, paper Section II)",
                                  &VisitPoint, &ValidatePoint);

}  // namespace
}  // namespace planeslam::app
