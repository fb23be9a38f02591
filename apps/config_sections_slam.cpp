// Config sections of the SLAM pipeline: "slam" (keyframes, loop closures) and "run" (what
// `planeslam run` feeds it and writes).
#include "config_sections_slam.hpp"

#include "detector_factory.hpp"

namespace planeslam::app {
namespace {

void VisitSlam(FieldVisitor& v, mapping::SlamConfig& c) {
  v.Field("keyframe_translation", c.keyframe_translation,
          "[m] new keyframe after this motion since the last one", 0.001, 100.0);
  v.Field("keyframe_rotation_deg", c.keyframe_rotation_deg,
          "[deg] new keyframe after this rotation since the last one", 0.01, 180.0);
  v.Field("keyframe_min_matches", c.keyframe_min_matches,
          "[planes] new keyframe when fewer planes match the keyframe (and the frame has planes "
          "it does not match)",
          0, 100);
  v.Field("prior_translation_sigma", c.prior_translation_sigma,
          "[m] 1-sigma of the constant-velocity prediction per frame", 1e-6, 100.0);
  v.Field("prior_rotation_sigma", c.prior_rotation_sigma,
          "[rad] 1-sigma of the constant-velocity prediction per frame", 1e-6, 10.0);
  v.Field("prior_gate_chi2", c.prior_gate_chi2,
          "[-] refuse a tracking result this far (chi-square, 6 dof) from the prior; 0 = off", 0.0,
          1e12);
  v.Field("gate_translation_sigma", c.gate_translation_sigma,
          "[m] the gate's plausible change of velocity per frame (1-sigma)", 1e-6, 100.0);
  v.Field("gate_rotation_sigma", c.gate_rotation_sigma, "[rad] same for rotation", 1e-6, 10.0);
  v.Field("prior_gate_max_refusals", c.prior_gate_max_refusals,
          "[frames] accept the result anyway after this many refusals in a row", 0, 1000000);
  v.Field("hold_velocity_when_degenerate", c.hold_velocity_when_degenerate,
          "keep the last well-determined velocity on degenerate frames");
  v.Field("velocity_window", c.velocity_window,
          "[s] the predicted velocity is the mean of the well-determined motions of this last "
          "span, time the velocity was held not counted (0 = the last motion alone)",
          0.0, 1000.0);
  v.Field("continue_held_turn", c.continue_held_turn,
          "while the planes leave a rotation open, continue the turn along the trend of its "
          "rate (constant angular acceleration) instead of its mean");
  v.Field("point_to_plane_fill", c.point_to_plane_fill,
          "fill directions the planes leave open by point-to-plane alignment of the clouds");
  v.Field("reacquire_translation_sigma", c.reacquire_translation_sigma,
          "[m] once the drift along directions the planes left open exceeds this (1-sigma), new "
          "keyframes are associated with the map under it and pulled back onto the map; 0 = off",
          0.0, 1e3);
  v.Field("depth_map_fill", c.depth_map_fill,
          "depth images: fill directions the planes leave open by aligning the pixels outside "
          "the planes to a fused depth map of recent frames");
  v.Field("plane_landmarks", c.plane_landmarks,
          "optimise the map planes seen from two or more keyframes with the poses");
  v.Field("landmark_normal_sigma", c.landmark_normal_sigma,
          "[rad] floor of a detected plane's normal sigma in the landmark residuals", 1e-6, 1.0);
  v.Field("landmark_offset_sigma", c.landmark_offset_sigma,
          "[m] floor of a detected plane's offset sigma in the landmark residuals", 1e-6, 10.0);
  v.Field("landmark_gate_deg", c.landmark_gate_deg,
          "[deg] a detection joins its map plane's landmark only within this angle", 0.0, 90.0);
  v.Field("landmark_gate_offset", c.landmark_gate_offset,
          "[m] and within this offset (at the current poses)", 0.0, 10.0);
  v.Field("interpolate_frames", c.interpolate_frames,
          "frames between keyframes take their share of the correction of the edge between "
          "those keyframes, stretches tracked on the prior follow the measured motion on both "
          "sides, and a frame or two far off that motion are put back on it (output "
          "trajectory; summary.json outlier_frames)");
  v.Field("loop_closure", c.loop_closure, "search and verify loop closures");
  v.Field("loop_search_radius", c.loop_search_radius,
          "[m] loop candidates are keyframes within this distance", 0.0, 1000.0);
  v.Field("loop_max_angle_deg", c.loop_max_angle_deg,
          "[deg] and within this viewing-direction difference", 0.0, 180.0);
  v.Field("loop_min_keyframe_gap", c.loop_min_keyframe_gap,
          "[keyframes] loop candidates are at least this much older", 1, 1000000);
  v.Field("loop_max_candidates", c.loop_max_candidates,
          "[keyframes] candidates verified per new keyframe, nearest first", 0, 100);
  v.Field("loop_min_matches", c.loop_min_matches,
          "[planes] consistent plane matches a verified closure needs", 3, 100);
  v.Field("loop_max_residual", c.loop_max_residual,
          "[m] RMS plane-offset residual of a verified closure", 0.0, 10.0);
  v.Field("loop_prior_translation_sigma", c.loop_prior_translation_sigma,
          "[m] assumed drift (1-sigma) of the relative pose to a loop candidate", 1e-6, 100.0);
  v.Field("loop_prior_rotation_sigma", c.loop_prior_rotation_sigma, "[rad] same for rotation", 1e-6,
          10.0);
  v.Field("loop_consistency_chi2", c.loop_consistency_chi2,
          "[-] chi-square (6 dof) of the closure tests: against the trajectory, pairwise (PCM), "
          "and the residual after optimisation above which a closure is retracted",
          1e-3, 1e12);
  v.Field("loop_min_support", c.loop_min_support,
          "[closures] a mutually consistent set is accepted once it holds this many", 1, 1000);
  v.Field("loop_window_keyframes", c.loop_window_keyframes,
          "[keyframes] a closure hypothesis waits this long for support", 0, 1000000);
  v.Field("local_window_keyframes", c.local_window_keyframes,
          "[keyframes] after accepted closures optimise this many latest keyframes, the whole "
          "graph only when they leave a closure unsatisfied (0 = always the whole graph)",
          0, 1000000);
  v.Field("inject_false_closures", c.inject_false_closures,
          "[closures] test hook: offer this many seeded wrong loop closures over the run", 0,
          1000000);
  v.Field("inject_seed", c.inject_seed, "[-] test hook: seed of the injected closures", 1,
          1000000);
}

std::vector<std::string> ValidateSlam(const mapping::SlamConfig& c) { return c.Validate(); }

void VisitRun(FieldVisitor& v, RunConfig& c) {
  v.Field("start_at_ground_truth", c.start_at_ground_truth,
          "anchor the first pose at the ground truth's (when known) instead of the identity");
  v.Field("max_frames", c.max_frames, "[frames] stop after this many frames (0 = all)", 0,
          100000000);
  v.Field("frame_stride", c.frame_stride, "[frames] use every n-th frame", 1, 1000);
  v.Field("decimation", c.decimation,
          "[px] detect and track on every n-th row and column (1 = full resolution; "
          "Kinect-class depth: 2)",
          1, 16);
  v.Field("ate_max_time_difference", c.ate_max_time_difference,
          "[s] evo's association window when scoring against ground truth", 0.0, 10.0);
  v.Field("on_bad_frame", c.on_bad_frame,
          "a frame that cannot be read (corrupt, truncated or missing file): skip = warn, leave it "
          "out and carry on (exit 5); stop = end the run there, keeping the frames done (exit 6)",
          {"skip", "stop"});
  v.Field("threads", c.threads,
          "threads reading and detecting frames ahead and writing outputs in parallel; "
          "0 = the machine's cores; the outputs do not depend on it",
          0, 256);
}

PLANESLAM_REGISTER_CONFIG_SECTION(mapping::SlamConfig, "slam",
                                  "SLAM back end: keyframes and loop closures", &VisitSlam,
                                  &ValidateSlam);
PLANESLAM_REGISTER_CONFIG_SECTION(RunConfig, "run", "planeslam run: inputs and optional outputs",
                                  &VisitRun);

}  // namespace

std::unique_ptr<mapping::SlamSystem> MakeSlamSystem(const Config& config) {
  mapping::SlamConfig slam = config.Get<mapping::SlamConfig>("slam");
  // The depth map weights its points by the sensor's noise model, the detector's.
  const detection::DetectionParams& noise = config.Get<DetectionSection>("detection").params;
  if (noise.sigma0 + noise.sigma_z2 > 0) {
    slam.depth_map.sigma0 = noise.sigma0;
    slam.depth_map.sigma_z2 = noise.sigma_z2;
  }
  return std::make_unique<mapping::SlamSystem>(
      slam,
      config.Get<registration::AssociationConfig>("association"),
      config.Get<registration::RegistrationConfig>("registration"),
      config.Get<registration::PointToPlaneConfig>("point_to_plane"),
      config.Get<mapping::PoseGraphConfig>("pose_graph"),
      config.Get<mapping::PlaneMapConfig>("plane_map"));
}

}  // namespace planeslam::app
