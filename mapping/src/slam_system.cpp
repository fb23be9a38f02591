#include "planeslam/mapping/slam_system.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <unordered_set>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/mapping/open_stretches.hpp"
#include "slam_internal.hpp"

namespace planeslam::mapping {

using namespace slam_internal;  // NOLINT: the helpers shared with slam_closures.cpp

std::vector<std::string> SlamConfig::Validate() const {
  std::vector<std::string> problems;
  if (!(keyframe_translation > 0)) problems.push_back("keyframe_translation must be > 0");
  if (!(keyframe_rotation_deg > 0)) problems.push_back("keyframe_rotation_deg must be > 0");
  if (!(prior_translation_sigma > 0) || !(prior_rotation_sigma > 0)) {
    problems.push_back("prior sigmas must be > 0");
  }
  if (!(gate_translation_sigma > 0) || !(gate_rotation_sigma > 0)) {
    problems.push_back("gate sigmas must be > 0");
  }
  if (!(loop_prior_translation_sigma > 0) || !(loop_prior_rotation_sigma > 0)) {
    problems.push_back("loop prior sigmas must be > 0");
  }
  if (loop_min_matches < 3) problems.push_back("loop_min_matches must be >= 3");
  if (loop_min_keyframe_gap < 1) problems.push_back("loop_min_keyframe_gap must be >= 1");
  if (!(velocity_window >= 0)) problems.push_back("velocity_window must be >= 0");
  if (!(loop_consistency_chi2 > 0)) problems.push_back("loop_consistency_chi2 must be > 0");
  if (loop_min_support < 1) problems.push_back("loop_min_support must be >= 1");
  if (loop_window_keyframes < 0) problems.push_back("loop_window_keyframes must be >= 0");
  if (local_window_keyframes < 0) problems.push_back("local_window_keyframes must be >= 0");
  if (inject_false_closures < 0) problems.push_back("inject_false_closures must be >= 0");
  if (!(reacquire_translation_sigma >= 0)) {
    problems.push_back("reacquire_translation_sigma must be >= 0");
  }
  for (const auto& p : depth_map.Validate()) problems.push_back("depth_map: " + p);
  return problems;
}

SlamSystem::SlamSystem(const SlamConfig& config, const registration::AssociationConfig& association,
                       const registration::RegistrationConfig& registration,
                       const registration::PointToPlaneConfig& point_to_plane,
                       const PoseGraphConfig& pose_graph, const PlaneMapConfig& plane_map)
    : config_(config),
      association_config_(association),
      registration_config_(registration),
      point_to_plane_config_(point_to_plane),
      pose_graph_config_(pose_graph),
      map_(plane_map),
      velocity_(config.velocity_window) {
  const auto problems = config_.Validate();
  PLANESLAM_CHECK(problems.empty(), problems.front());
  paths_ = std::make_unique<GraphPaths>(graph_, kPathSearchNodes);
}

namespace {
/// The extents' settings: the sensor's noise model (as the depth map's).
registration::PlaneExtentConfig ExtentConfig(const SlamConfig& config) {
  registration::PlaneExtentConfig extent;
  extent.sigma0 = config.depth_map.sigma0;
  extent.sigma_z2 = config.depth_map.sigma_z2;
  return extent;
}

/// The directions the planes and the points left open, from the planes whose whole outline the
/// keyframe and the frame both see (registration/plane_extent.hpp).
void FillFromExtents(const SlamConfig& config,
                     const std::vector<detection::Plane>& keyframe_planes,
                     const std::vector<registration::PlaneExtent>& keyframe_extents,
                     const datasets::OrganizedCloud& cloud,
                     const detection::Segmentation& segmentation,
                     registration::RegistrationResult* reg) {
  if (!reg->converged || !reg->degenerate || reg->used_icp) return;
  // Without a complete outline in the keyframe there is no pair: the frame's extents (a pass
  // over its pixels) are not needed.
  if (std::none_of(keyframe_extents.begin(), keyframe_extents.end(),
                   [](const registration::PlaneExtent& e) { return e.complete; })) {
    return;
  }
  registration::FillDegenerateFromExtents(
      keyframe_planes, keyframe_extents, segmentation.planes,
      registration::ComputePlaneExtents(cloud, segmentation.labels, segmentation.planes,
                                        ExtentConfig(config)),
      ExtentConfig(config), reg);
}

}  // namespace

void SlamSystem::AddKeyframe(std::size_t frame, const Pose& T_world_sensor,
                             const detection::Segmentation& segmentation,
                             const datasets::OrganizedCloud& cloud,
                             const std::vector<registration::ShapedPoint>& structure) {
  Keyframe keyframe;
  keyframe.id = static_cast<std::int64_t>(keyframes_.size());
  keyframe.frame = frame;
  keyframe.planes = segmentation.planes;
  keyframe.extents = registration::ComputePlaneExtents(cloud, segmentation.labels,
                                                       segmentation.planes, ExtentConfig(config_));
  if (local_map_ && config_.loop_closure) {
    keyframe.structure = registration::CompactShapedPoints(
        registration::ThinShapedPoints(structure, kClosureThinning * local_map_->voxel_size()));
  }
  // The first keyframe anchors the world frame (the optimiser holds it fixed).
  graph_.AddNode(keyframe.id, T_world_sensor, /*fixed=*/keyframe.id == 0);
  // About 30,000 of the scan's points: every bin of the view gets several.
  keyframe.view = ViewBins(
      cloud, static_cast<int>(std::lround(std::sqrt(static_cast<double>(cloud.size()) / 3.0e4))));
  keyframes_.push_back(std::move(keyframe));
  keyframe_frames_.push_back(frame);
  // Kept only for the point-to-plane fill of degenerate directions (a full-resolution copy).
  if (config_.point_to_plane_fill) keyframe_cloud_ = cloud;
  ++stats_.keyframes;
  const auto start = std::chrono::steady_clock::now();
  keyframes_.back().map_planes =
      map_.AddFrame(keyframes_.back().id, T_world_sensor, segmentation, cloud).map_ids;
  stats_.time_map_ms += ElapsedMs(start);
}

void SlamSystem::DropImplausibleMatches(const Keyframe& keyframe,
                                        const detection::Segmentation& segmentation,
                                        const registration::MotionPrior& prior,
                                        const registration::MotionPrior& gate_prior,
                                        registration::RegistrationResult* reg) const {
  // Only a result the prediction finds suspect (its innovation beyond the 99 % quantile of
  // chi-square with 6 dof) is checked pair by pair: there one wrong pair, a small plane matched
  // to another, can hold a direction and still pass the 99.9 % gate with its own uncertainty.
  constexpr double kSuspectChi2 = 16.81;
  if (!reg->converged || !(registration::PriorInnovationChi2(*reg, gate_prior) > kSuspectChi2)) {
    return;
  }
  const std::vector<registration::PlaneMatch> plausible = registration::PlausibleMatches(
      keyframe.planes, segmentation.planes, reg->inliers, gate_prior, registration_config_);
  // Where no pair agrees with the prediction, the prediction is the likelier culprit.
  if (plausible.empty() || plausible.size() == reg->inliers.size()) return;
  registration::RegistrationResult again = registration::RegisterPlanes(
      keyframe.planes, segmentation.planes, plausible, prior, registration_config_);
  if (again.converged) *reg = std::move(again);
}

SlamFrameResult SlamSystem::ProcessFrame(double timestamp, const datasets::OrganizedCloud& cloud,
                                         const detection::Segmentation& segmentation) {
  const auto start = std::chrono::steady_clock::now();
  SlamFrameResult result = TrackFrame(timestamp, cloud, segmentation);
  UpdateDepthMap(cloud, segmentation.labels, result.T_world_sensor);
  const double ms = ElapsedMs(start);
  if (stats_.frames <= SlamStats::kTimedFrames) stats_.time_first_frames_ms += ms;
  recent_frame_ms_.push_back(ms);
  stats_.time_last_frames_ms += ms;
  if (recent_frame_ms_.size() > SlamStats::kTimedFrames) {
    stats_.time_last_frames_ms -= recent_frame_ms_.front();
    recent_frame_ms_.pop_front();
  }
  return result;
}

namespace {

/// A frame without a velocity to predict from (the second one): the prior is the coarse-to-fine
/// alignment of its cloud to the first one's, around the constant-velocity guess.
/// Releases `first`.
void BootstrapPrior(datasets::OrganizedCloud* first, const datasets::OrganizedCloud& cloud,
                    double voxel, registration::MotionPrior* prior) {
  const registration::MapAlignmentResult a = registration::AlignScansCoarseToFine(
      *first, cloud, prior->T_prev_curr, registration::MotionPrior{}.covariance, voxel, {});
  if (a.valid && a.converged) {
    prior->T_prev_curr = a.T_prev_curr;
    prior->covariance += a.covariance;
  }
  *first = {};
}

/// Fills the directions the planes leave open from the local map, then refines all six with the
/// points (registration/local_map.hpp). Returns whether the points filled a direction.
bool AlignToLocalMap(const registration::LocalVoxelMap& map, const Pose& T_world_keyframe,
                     const std::vector<registration::ShapedPoint>& structure,
                     registration::RegistrationResult* reg) {
  const std::vector<registration::ShapedPoint> source =
      registration::ThinShapedPoints(structure, 1.5 * map.voxel_size());
  bool filled = false;
  if (reg->degenerate) {
    filled = registration::FillDegenerateFromLocalMap(map, T_world_keyframe, source, {}, reg);
  }
  registration::RefineWithLocalMap(map, T_world_keyframe, source, {}, reg);
  return filled;
}

}  // namespace

void SlamSystem::UpdateDepthMap(const datasets::OrganizedCloud& cloud,
                                const std::vector<std::int32_t>& labels,
                                const Pose& T_world_sensor) {
  if (!config_.depth_map_fill || !intrinsics_) return;
  if (!depth_map_) {
    depth_map_ = std::make_unique<registration::DepthLocalMap>(*intrinsics_, config_.depth_map);
  }
  depth_map_->Insert(cloud, &labels, T_world_sensor);
}

bool SlamSystem::FillFromDepthImage(std::int64_t keyframe_id, const datasets::OrganizedCloud& cloud,
                                    const std::vector<std::int32_t>& labels,
                                    registration::RegistrationResult* reg) const {
  if (!intrinsics_ || !reg->converged || !reg->degenerate) return false;
  if (depth_map_ && registration::FillDegenerateFromDepthMap(*depth_map_, KeyframePose(keyframe_id),
                                                             cloud, &labels, reg)) {
    return true;
  }
  return config_.point_to_plane_fill &&
         registration::FillDegenerateWithPointToPlane(keyframe_cloud_, *intrinsics_, cloud,
                                                      point_to_plane_config_, reg);
}

namespace {

/// The directions tracking left to the prior, in world axes: all of them without a registration,
/// else the planes' open ones unless points or extents filled them all.
Eigen::Matrix<double, 6, Eigen::Dynamic> OpenDirections(bool use_registration,
                                                        const registration::RegistrationResult& reg,
                                                        const Eigen::Matrix3d& R_world_keyframe) {
  Matrix6d R = Matrix6d::Zero();
  R.topLeftCorner<3, 3>() = R.bottomRightCorner<3, 3>() = R_world_keyframe;
  if (!use_registration) return R;
  if (!(reg.used_prior || (reg.degenerate && !reg.used_icp))) {
    return Eigen::Matrix<double, 6, 0>();
  }
  Eigen::Matrix<double, 6, Eigen::Dynamic> open(6, reg.degenerate_directions.size());
  for (std::size_t k = 0; k < reg.degenerate_directions.size(); ++k) {
    open.col(static_cast<Eigen::Index>(k)) = R * reg.degenerate_directions[k];
  }
  return open;
}

}  // namespace

void SlamSystem::AccumulateDrift(const Eigen::Matrix<double, 6, Eigen::Dynamic>& open) {
  // One frame's change of velocity (the prior's sigmas) along those directions; the sigmas are
  // the same on every axis, so the projection commutes with the rotation into the world.
  if (open.cols() == 0) return;
  const Matrix6d P = open * open.transpose();
  drift_covariance_ +=
      P * DiagonalCovariance(config_.prior_translation_sigma, config_.prior_rotation_sigma) * P;
}

void SlamSystem::UpdateVelocity(double timestamp, double dt, std::size_t keyframe_frame,
                                bool use_registration,
                                const registration::RegistrationResult& reg,
                                const Pose& T_keyframe_curr) {
  // An update along directions the planes left open would feed the prior back into itself, so
  // the velocity is held there. Translation and rotation are each held as a whole (an update of
  // some of their directions only would mix a measured rate with a held one), but apart from each
  // other: two walls leave a translation open but fix the rotation, whose rate then keeps
  // following an accelerating turn.
  bool translation_open = !use_registration, rotation_open = !use_registration;
  if (use_registration && reg.used_icp) {  // the points determined some of them
    translation_open = reg.prior_translations > 0;
    rotation_open = reg.prior_directions > reg.prior_translations;
  } else {
    for (const registration::Vector6d& direction : reg.degenerate_directions) {
      (direction.head<3>().squaredNorm() > 0.5 ? translation_open : rotation_open) = true;
    }
  }
  const bool hold = config_.hold_velocity_when_degenerate;
  // The prior's drift since a part was last measured, or since the keyframe the poses are
  // relative to, is spread over those frames (registration/velocity_model.hpp).
  const std::size_t frame = frames_.size();  // this frame's index
  const auto span = [&](std::size_t measured_at) {
    return static_cast<int>(frame - std::max(measured_at, keyframe_frame));
  };
  velocity_.Add(timestamp, dt, T_keyframe_last_.inverse() * T_keyframe_curr,
                !(hold && translation_open), !(hold && rotation_open),
                span(translation_measured_at_), span(rotation_measured_at_));
  if (!(hold && translation_open)) translation_measured_at_ = frame;
  if (!(hold && rotation_open)) rotation_measured_at_ = frame;
}

SlamFrameResult SlamSystem::TrackFrame(double timestamp, const datasets::OrganizedCloud& cloud,
                                       const detection::Segmentation& segmentation) {
  SlamFrameResult result;
  result.index = frames_.size();
  result.timestamp = timestamp;
  result.planes = static_cast<int>(segmentation.planes.size());
  ++stats_.frames;

  // Range images: the frame's structure outside the planes, for the local map.
  if (keyframes_.empty() && cloud.model != datasets::SensorModel::kPinhole) {
    const double reach = registration::ScanReach(cloud);
    if (reach > 0) local_map_ = std::make_unique<registration::LocalVoxelMap>(reach / 100.0, 20);
  }
  const std::vector<registration::ShapedPoint> structure =
      local_map_ ? registration::ScanStructure(cloud, &segmentation.labels,
                                               local_map_->voxel_size())
                 : std::vector<registration::ShapedPoint>{};
  if (keyframes_.empty()) {
    if (cloud.model == datasets::SensorModel::kPinhole) {
      intrinsics_ = registration::EstimatePinholeIntrinsics(cloud);
    }
    if (local_map_) {
      local_map_->Insert(structure, T_world_first_, registration::ScanReach(cloud));
      first_cloud_ = cloud;
    }
    AddKeyframe(result.index, T_world_first_, segmentation, cloud, structure);
    frames_.push_back({timestamp, 0, Pose::Identity()});
    result.T_world_sensor = T_world_first_;
    result.keyframe = true;
    result.tracked = true;
    return result;
  }

  const auto track_start = std::chrono::steady_clock::now();
  const Keyframe& keyframe = keyframes_.back();
  registration::MotionPrior prior;
  const double dt = timestamp - frames_.back().timestamp;
  // Constant velocity; a turn whose rate the planes have stopped measuring continues along its
  // trend (see SlamConfig::continue_held_turn).
  prior.T_prev_curr = T_keyframe_last_ * (config_.continue_held_turn
                                              ? velocity_.PredictContinuingHeldTurn(dt, timestamp)
                                              : velocity_.Predict(dt));
  // The prediction is uncertain by the last frame's own uncertainty relative to the keyframe
  // plus one frame's change of velocity: in directions the planes have left open since the
  // keyframe the prior's error accumulates frame after frame, and the odometry edge must say so.
  prior.covariance = covariance_keyframe_last_ + DiagonalCovariance(config_.prior_translation_sigma,
                                                                    config_.prior_rotation_sigma);
  if (!first_cloud_.empty()) BootstrapPrior(&first_cloud_, cloud, local_map_->voxel_size(), &prior);
  // The change of velocity that is plausible in one frame (gate_*_sigma), not the association's
  // loose prior: the innovation gate below and the check of single pairs use it.
  registration::MotionPrior gate_prior = prior;
  gate_prior.covariance =
      covariance_keyframe_last_ +
      DiagonalCovariance(config_.gate_translation_sigma, config_.gate_rotation_sigma);
  registration::RegistrationResult reg =
      registration::AssociatePlanes(keyframe.planes, segmentation.planes, prior,
                                    association_config_, registration_config_)
          .registration;
  if (config_.prior_gate_chi2 > 0) {
    DropImplausibleMatches(keyframe, segmentation, prior, gate_prior, &reg);
  }
  result.used_point_to_plane = FillFromDepthImage(keyframe.id, cloud, segmentation.labels, &reg);
  FillFromExtents(config_, keyframe.planes, keyframe.extents, cloud, segmentation, &reg);
  if (reg.converged && local_map_ && !structure.empty()) {
    result.used_point_to_plane =
        AlignToLocalMap(*local_map_, KeyframePose(keyframe.id), structure, &reg);
  }
  result.weak_directions = static_cast<int>(reg.degenerate_directions.size());
  result.matches = static_cast<int>(reg.inliers.size());
  result.tracked = reg.converged;
  result.degenerate = reg.degenerate || !reg.converged;
  if (result.used_point_to_plane) ++stats_.point_to_plane_frames;
  if (reg.converged && config_.prior_gate_chi2 > 0) {
    // Innovation of the result against the constant-velocity prediction.
    const double chi2 = registration::PriorInnovationChi2(reg, gate_prior);
    if (!(chi2 <= config_.prior_gate_chi2) &&
        consecutive_refusals_ < config_.prior_gate_max_refusals) {
      result.refused = true;
      result.tracked = false;
      result.degenerate = true;
      ++consecutive_refusals_;
      ++stats_.refused_frames;
    } else {
      consecutive_refusals_ = 0;
    }
  }
  // The registration falls back to the prior itself (whole or per degenerate direction).
  const bool use_registration = reg.converged && !result.refused;
  Pose T_keyframe_curr = use_registration ? reg.T_prev_curr : prior.T_prev_curr;
  Matrix6d covariance = use_registration ? reg.covariance : prior.covariance;
  const Eigen::Matrix<double, 6, Eigen::Dynamic> open =
      OpenDirections(use_registration, reg, KeyframePose(keyframe.id).linear());
  AccumulateDrift(open);
  stats_.time_tracking_ms += ElapsedMs(track_start);
  if (!use_registration) ++stats_.untracked_frames;
  result.constrained_by = use_registration ? registration::ConstraintSource(reg) : "prior";
  if (result.constrained_by.find("prior") != std::string::npos) ++stats_.prior_frames;
  if (result.degenerate) ++stats_.degenerate_frames;

  UpdateVelocity(timestamp, dt, keyframe.frame, use_registration, reg, T_keyframe_curr);
  T_keyframe_last_ = T_keyframe_curr;
  covariance_keyframe_last_ = covariance;
  result.T_world_sensor = KeyframePose(keyframe.id) * T_keyframe_curr;
  if (local_map_) {
    local_map_->Insert(structure, result.T_world_sensor, registration::ScanReach(cloud));
  }

  const bool moved = T_keyframe_curr.translation().norm() > config_.keyframe_translation ||
                     RotationAngle(T_keyframe_curr) > config_.keyframe_rotation_deg * kDegToRad;
  const bool weak = result.matches < config_.keyframe_min_matches && result.matches < result.planes;
  if (!(moved || weak)) {
    frames_.push_back({timestamp, keyframe.id, T_keyframe_curr, open});
    return result;
  }

  Reacquire(segmentation, keyframe.id, &result.T_world_sensor, &T_keyframe_curr, &covariance);
  // New keyframe: node, odometry edge weighted by the registration's uncertainty, map planes.
  const std::int64_t previous_id = keyframe.id;
  AddKeyframe(result.index, result.T_world_sensor, segmentation, cloud, structure);
  const Keyframe& current = keyframes_.back();
  graph_.AddEdge(previous_id, current.id, T_keyframe_curr, InformationFromCovariance(covariance),
                 EdgeKind::kOdometry);
  paths_->AddEdge(graph_.edges().back());
  frames_.push_back({timestamp, current.id, Pose::Identity(), open});
  T_keyframe_last_ = Pose::Identity();
  covariance_keyframe_last_.setZero();
  result.keyframe = true;

  if (config_.loop_closure) {
    const auto loop_start = std::chrono::steady_clock::now();
    SearchLoopClosures(current, &result);
    InjectFalseClosures(current, &result);
    result.loop_closures = DecideClosures(current.id, &result);
    stats_.time_loop_ms += ElapsedMs(loop_start);
    if (result.loop_closures > 0) {
      OptimizeAfterClosures(result.loop_closures, &result);
      result.T_world_sensor = KeyframePose(current.id);
    }
  }
  return result;
}

std::vector<PlaneLandmark> SlamSystem::PlaneLandmarks() const {
  std::vector<PlaneLandmark> landmarks;
  if (!config_.plane_landmarks) return landmarks;
  const double cos_gate = std::cos(config_.landmark_gate_deg * kDegToRad);
  for (const MapPlane& plane : map_.planes()) {
    PlaneLandmark landmark;
    landmark.normal = plane.normal;
    landmark.d = plane.d;
    for (const PlaneObservation& obs : plane.observations) {
      if (obs.keyframe_id < 0 || obs.keyframe_id >= static_cast<std::int64_t>(keyframes_.size())) {
        continue;
      }
      const Keyframe& keyframe = keyframes_[static_cast<std::size_t>(obs.keyframe_id)];
      const int k = obs.detection_id - 1;
      if (k < 0 || k >= static_cast<int>(keyframe.planes.size())) continue;
      const detection::Plane& detected = keyframe.planes[static_cast<std::size_t>(k)];
      // Only detections that agree with the map plane at the current poses (landmark_gate_*):
      // the map's own association is looser.
      const Pose T_world_keyframe = KeyframePose(keyframe.id);
      const Eigen::Vector3d n_predicted = T_world_keyframe.linear().transpose() * plane.normal;
      const double d_predicted = plane.d - plane.normal.dot(T_world_keyframe.translation());
      if (n_predicted.dot(detected.normal) < cos_gate ||
          std::abs(d_predicted - detected.d) > config_.landmark_gate_offset) {
        continue;
      }
      PlaneLandmarkObservation o;
      o.node = keyframe.id;
      o.normal = detected.normal;
      o.d = detected.d;
      const Eigen::Matrix4d& cov = detected.covariance;
      o.normal_sigma =
          std::sqrt(std::max(0.5 * cov.topLeftCorner<3, 3>().trace(),
                             config_.landmark_normal_sigma * config_.landmark_normal_sigma));
      o.offset_sigma = std::sqrt(
          std::max(cov(3, 3), config_.landmark_offset_sigma * config_.landmark_offset_sigma));
      landmark.observations.push_back(o);
    }
    const auto& seen = landmark.observations;
    const bool two_keyframes = std::any_of(
        seen.begin(), seen.end(), [&](const auto& o) { return o.node != seen.front().node; });
    if (two_keyframes) landmarks.push_back(std::move(landmark));
  }
  return landmarks;
}

PoseGraphResult SlamSystem::Optimize(std::int64_t first_free) {
  std::vector<PlaneLandmark> landmarks = PlaneLandmarks();
  std::unordered_set<std::int64_t> free_nodes;
  for (std::int64_t id = std::max<std::int64_t>(first_free, 0);
       first_free >= 0 && id < static_cast<std::int64_t>(keyframes_.size()); ++id) {
    free_nodes.insert(id);
  }
  // The depth map moves with the newest keyframe, near which it was built.
  const Pose T_world_newest_before =
      keyframes_.empty() ? Pose::Identity() : KeyframePose(keyframes_.back().id);
  const PoseGraphResult result = OptimizePoseGraphWindow(
      graph_, first_free >= 0 ? &free_nodes : nullptr, pose_graph_config_, &landmarks);
  if (first_free >= 0) {
    std::unordered_map<std::int64_t, Pose> moved;
    for (std::int64_t id : free_nodes) moved[id] = KeyframePose(id);
    map_.Refit(moved);
    ++stats_.local_optimizations;
  } else {
    map_.Refit(KeyframePoses());
    // The whole graph moved: merges the new poses contradict are undone.
    stats_.map_splits += static_cast<std::size_t>(map_.SplitContradicted());
  }
  if (local_map_) local_map_->Clear();  // its points sit at the poses before the optimisation
  if (depth_map_ && !keyframes_.empty()) {
    depth_map_->SetReferencePose(KeyframePose(keyframes_.back().id) *
                                 T_world_newest_before.inverse() * depth_map_->T_world_ref());
  }
  ++stats_.optimizations;
  return result;
}

PoseGraphResult SlamSystem::Finish() {
  const auto start = std::chrono::steady_clock::now();
  PoseGraphResult result;
  if (!keyframes_.empty() && !pending_.empty()) {
    // The run is over: hypotheses still waiting are decided now, as if their window had passed.
    SlamFrameResult ignored;
    DecideClosures(keyframes_.back().id + config_.loop_window_keyframes + 1, &ignored);
  }
  if (!graph_.edges().empty()) {
    result = Optimize();
    for (int round = 0; round < 3 && RetractOutliers(0, keyframes_.back().frame) > 0; ++round) {
      result = Optimize();
    }
  }
  // The poses are final: coplanar parts become one plane at the loose merge offset (during SLAM
  // only at the tight one, see refit_merge_across_gaps_offset).
  const PlaneMapConfig& map_config = map_.config();
  map_.MergeCoincidentPlanes(map_config.merge_across_gaps
                                 ? map_config.merge_max_offset
                                 : map_config.refit_merge_across_gaps_offset);
  CullUnconfirmedPlanes();
  stats_.time_optimize_ms += ElapsedMs(start);
  return result;
}

datasets::Trajectory SlamSystem::EstimatedTrajectory(std::vector<double>* outliers) const {
  // The measured pose of each keyframe in its predecessor: its odometry edge.
  std::unordered_map<std::int64_t, Pose> measured_in_previous;
  if (config_.interpolate_frames) {
    for (const PoseGraphEdge& edge : graph_.edges()) {
      if (edge.kind == EdgeKind::kOdometry) measured_in_previous[edge.to] = edge.T_a_b();
    }
  }
  std::vector<TrackedPose> poses(frames_.size());
  for (std::size_t f = 0; f < frames_.size(); ++f) {
    const FrameRecord& record = frames_[f];
    const Pose T_world_keyframe = KeyframePose(record.keyframe_id);
    const std::int64_t next_id = record.keyframe_id + 1;
    const auto measured = measured_in_previous.find(next_id);
    poses[f].timestamp = record.timestamp;
    poses[f].open = record.open;
    poses[f].T_world = T_world_keyframe * record.T_keyframe_frame;
    poses[f].keyframe = keyframes_[static_cast<std::size_t>(record.keyframe_id)].frame == f;
    if (measured == measured_in_previous.end()) continue;
    // The optimiser corrects the odometry edge to the next keyframe as a whole:
    // T_keyframe_next = correction * measured. The frames between the two were tracked against
    // this keyframe and drifted along the way, so each takes the share of the correction that
    // matches how far along it is (a keyframe's own frame takes none, the next keyframe all).
    const std::size_t first = keyframes_[static_cast<std::size_t>(record.keyframe_id)].frame;
    const std::size_t last = keyframes_[static_cast<std::size_t>(next_id)].frame;
    const double alpha = static_cast<double>(f - first) / static_cast<double>(last - first);
    const Pose correction =
        T_world_keyframe.inverse() * KeyframePose(next_id) * measured->second.inverse();
    const Pose share = registration::BoxPlus(
        Pose::Identity(), alpha * registration::BoxMinus(correction, Pose::Identity()));
    poses[f].T_world = T_world_keyframe * share * record.T_keyframe_frame;
  }
  if (config_.interpolate_frames) {
    SmoothOpenStretches(&poses, config_.velocity_window);
    for (const std::size_t f : ReinterpolateOutliers(&poses)) {
      if (outliers != nullptr) outliers->push_back(poses[f].timestamp);
    }
  }
  datasets::Trajectory trajectory;
  for (const TrackedPose& pose : poses) trajectory.Add(pose.timestamp, pose.T_world);
  return trajectory;
}

std::unordered_map<std::int64_t, Pose> SlamSystem::KeyframePoses() const {
  std::unordered_map<std::int64_t, Pose> poses;
  for (const Keyframe& keyframe : keyframes_) poses[keyframe.id] = KeyframePose(keyframe.id);
  return poses;
}

}  // namespace planeslam::mapping
