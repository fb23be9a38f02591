// Config sections of the synthetic generator (see config_sections_synthetic.hpp).
#include "config_sections_synthetic.hpp"

#include <cmath>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::app {
namespace {

namespace ds = planeslam::datasets;

void VisitSimulation(FieldVisitor& v, SimulationConfig& c) {
  v.Field("scene", c.scene,
          "synthetic world: room (office), corridor (degenerate), rubble, street (LiDAR)",
          {"room", "corridor", "rubble", "street"});
  v.Field("seed", c.seed, "seed of the rubble and street layouts and the sensor noise [-]", 0,
          2147483647);
  v.Field("sensor", c.sensor,
          "pinhole depth camera, spherical scanner, lidar (rotating, KITTI layout) or auto (the "
          "scene's: lidar for the street, else pinhole)",
          {"auto", "pinhole", "spherical", "lidar"});
  v.Field("noise", c.noise, "sensor noise on (false: exact ranges)");
  v.Field("frames", c.frames, "number of frames [frames]; 0 = the scene's whole path", 0, 1000000);
  v.Field("rate", c.rate, "frame rate [Hz]; 0 = the scene's (30, street 10)", 0.0, 1000.0);
  v.Field("speed", c.speed, "camera speed along the path [m/s]; 0 = scene default", 0.0, 100.0);
  v.Field("laps", c.laps,
          "room/rubble/street: turns around the centre (street: the block) when frames = 0 "
          "[turns]; 0 = default",
          0.0, 100.0);
  v.Field("length", c.length, "corridor: run length when frames = 0 [m]; 0 = default (10 m)",
          0.0, 25.0);
}

void VisitPinhole(FieldVisitor& v, ds::PinholeSimConfig& c) {
  v.Field("width", c.intrinsics.width, "image width [px]", 1, 8192);
  v.Field("height", c.intrinsics.height, "image height [px]", 1, 8192);
  v.Field("fx", c.intrinsics.fx, "focal length x [px] (TUM fr3 535.4)", 1.0, 1e5);
  v.Field("fy", c.intrinsics.fy, "focal length y [px] (TUM fr3 539.2)", 1.0, 1e5);
  v.Field("cx", c.intrinsics.cx, "principal point x [px]", -1e5, 1e5);
  v.Field("cy", c.intrinsics.cy, "principal point y [px]", -1e5, 1e5);
  v.Field("min_depth", c.min_depth, "closer returns are dropped [m]", 0.0, 100.0);
  v.Field("max_depth", c.max_depth, "farther returns are dropped [m] (depth PNG holds <= 13.1 m)",
          0.01, 1000.0);
  v.Field("noise_k", c.noise_k,
          "depth noise sigma(z) = noise_k * z^2 [1/m] (Kinect v1, Khoshelham & Elberink 2012)",
          0.0, 1.0);
  v.Field("noise_truncation", c.noise_truncation, "noise is a normal truncated here [sigma]", 0.5,
          10.0);
  v.Field("quantize_disparity", c.quantize_disparity,
          "round disparity f*b/z to 1/disparity_subpixel px (Kinect v1 depth steps)");
  v.Field("baseline", c.baseline, "projector-camera baseline for quantisation [m]", 1e-3, 10.0);
  v.Field("disparity_subpixel", c.disparity_subpixel, "disparity steps per pixel [1]", 1.0, 1024.0);
  v.Field("max_incidence_deg", c.max_incidence_deg,
          "returns at a larger angle between ray and surface normal are dropped [deg]", 0.0, 90.0);
  v.Field("edge_dropout", c.edge_dropout, "drop both pixels of a depth discontinuity");
  v.Field("edge_jump", c.edge_jump, "relative depth jump between 4-neighbours that is an edge [1]",
          0.0, 10.0);
  v.Field("dropout_rate", c.dropout_rate, "probability of losing any pixel at random [1]", 0.0, 1.0);
}

std::vector<std::string> ValidatePinhole(const ds::PinholeSimConfig& c) {
  if (c.min_depth >= c.max_depth) return {"min_depth must be below max_depth"};
  return {};
}

void VisitSpherical(FieldVisitor& v, ds::SphericalSimConfig& c) {
  v.Field("azimuth_fov_deg", c.azimuth_fov_deg, "horizontal field of view [deg]", 1.0, 360.0);
  v.Field("azimuth_resolution_deg", c.azimuth_resolution_deg, "[deg/column]", 0.01, 45.0);
  v.Field("elevation_min_deg", c.elevation_min_deg, "lowest row's elevation [deg]", -90.0, 90.0);
  v.Field("elevation_max_deg", c.elevation_max_deg, "top row's elevation [deg]", -90.0, 90.0);
  v.Field("elevation_resolution_deg", c.elevation_resolution_deg, "[deg/row]", 0.01, 45.0);
  v.Field("min_range", c.min_range, "closer returns are dropped [m]", 0.0, 1000.0);
  v.Field("max_range", c.max_range, "farther returns are dropped [m]", 0.01, 10000.0);
  v.Field("range_sigma", c.range_sigma, "range noise sigma (constant) [m]", 0.0, 10.0);
  v.Field("noise_truncation", c.noise_truncation, "noise is a normal truncated here [sigma]", 0.5,
          10.0);
  v.Field("max_incidence_deg", c.max_incidence_deg,
          "returns at a larger angle between ray and surface normal are dropped [deg]", 0.0, 90.0);
  v.Field("dropout_rate", c.dropout_rate, "probability of losing any pixel at random [1]", 0.0, 1.0);
}

std::vector<std::string> ValidateSpherical(const ds::SphericalSimConfig& c) {
  std::vector<std::string> problems;
  if (c.elevation_min_deg >= c.elevation_max_deg) {
    problems.push_back("elevation_min_deg must be below elevation_max_deg");
  }
  if (c.min_range >= c.max_range) problems.push_back("min_range must be below max_range");
  if (static_cast<double>(c.Width()) * c.Height() > 64.0 * 1024 * 1024) {
    problems.push_back("more than 64 Mpx per scan: raise the resolutions");
  }
  return problems;
}

void VisitLidar(FieldVisitor& v, ds::LidarSimConfig& c) {
  v.Field("columns", c.columns, "firings per turn [1] (2083: 0.1728 deg, HDL-64E at 10 Hz)", 1,
          100000);
  v.Field("min_range", c.min_range, "closer returns are dropped [m]", 0.0, 1000.0);
  v.Field("max_range", c.max_range, "farther returns are dropped [m]", 0.01, 10000.0);
  v.Field("range_sigma", c.range_sigma, "range noise sigma (constant) [m]", 0.0, 10.0);
  v.Field("noise_truncation", c.noise_truncation, "noise is a normal truncated here [sigma]", 0.5,
          10.0);
  v.Field("max_incidence_deg", c.max_incidence_deg,
          "returns at a larger angle between ray and surface normal are dropped [deg]", 0.0, 90.0);
  v.Field("dropout_rate", c.dropout_rate, "probability of losing any return at random [1]", 0.0,
          1.0);
  v.Field("motion_distortion", c.motion_distortion,
          "cast each firing from the pose at its own time (points not de-skewed)");
}

std::vector<std::string> ValidateLidar(const ds::LidarSimConfig& c) {
  if (c.min_range >= c.max_range) return {"min_range must be below max_range"};
  return {};
}

PLANESLAM_REGISTER_CONFIG_SECTION(SimulationConfig, "simulation",
                                  "Synthetic world (planeslam simulate, and planeslam run without "
                                  "a sequence)",
                                  &VisitSimulation);
PLANESLAM_REGISTER_CONFIG_SECTION(ds::PinholeSimConfig, "simulation_pinhole",
                                  "Simulated depth camera (TUM fr3 intrinsics, Kinect v1 noise)",
                                  &VisitPinhole, &ValidatePinhole);
PLANESLAM_REGISTER_CONFIG_SECTION(ds::SphericalSimConfig, "simulation_spherical",
                                  "Simulated spherical scanner (rows elevation, columns azimuth)",
                                  &VisitSpherical, &ValidateSpherical);
PLANESLAM_REGISTER_CONFIG_SECTION(ds::LidarSimConfig, "simulation_lidar",
                                  "Simulated rotating LiDAR (HDL-64E elevations, KITTI layout)",
                                  &VisitLidar, &ValidateLidar);

}  // namespace

datasets::SyntheticConfig MakeSyntheticConfig(const std::string& scene, const Config& config) {
  const auto& sim = config.Get<SimulationConfig>("simulation");
  const ds::SceneKind kind = ds::ParseSceneKind(scene.empty() ? sim.scene : scene);
  ds::SyntheticConfig out = ds::SyntheticConfig::ForScene(kind);
  out.seed = static_cast<std::uint64_t>(sim.seed);
  if (sim.sensor != "auto") out.sensor = sim.sensor;
  out.pinhole = config.Get<ds::PinholeSimConfig>("simulation_pinhole");
  out.spherical = config.Get<ds::SphericalSimConfig>("simulation_spherical");
  out.lidar = config.Get<ds::LidarSimConfig>("simulation_lidar");
  out.pinhole.noise = sim.noise;
  out.spherical.noise = sim.noise;
  out.lidar.noise = sim.noise;
  out.trajectory.frames = sim.frames;
  if (sim.rate > 0.0) out.trajectory.rate = sim.rate;
  if (sim.speed > 0.0) out.trajectory.speed = sim.speed;
  if (sim.laps > 0.0) out.trajectory.laps = sim.laps;
  if (sim.length > 0.0) out.trajectory.length = sim.length;
  return out;
}

std::unique_ptr<datasets::SyntheticSequence> MakeSyntheticSequence(const std::string& scene,
                                                                   const Config& config) {
  return std::make_unique<ds::SyntheticSequence>(MakeSyntheticConfig(scene, config));
}

}  // namespace planeslam::app
