#include "planeslam/registration/plane_odometry.hpp"

#include <chrono>
#include <cmath>

namespace planeslam::registration {

std::vector<std::string> PlaneOdometryConfig::Validate() const {
  std::vector<std::string> p;
  for (const auto& s : association.Validate()) p.push_back("association: " + s);
  for (const auto& s : registration.Validate()) p.push_back("registration: " + s);
  for (const auto& s : point_to_plane.Validate()) p.push_back("point_to_plane: " + s);
  for (const auto& s : local_map.Validate()) p.push_back("local_map: " + s);
  for (const auto& s : depth_map.Validate()) p.push_back("depth_map: " + s);
  if (!(prior_translation_sigma > 0)) p.push_back("prior_translation_sigma must be > 0");
  if (!(prior_rotation_sigma > 0)) p.push_back("prior_rotation_sigma must be > 0");
  if (!(max_prior_gap > 0)) p.push_back("max_prior_gap must be > 0");
  if (!(velocity_window >= 0)) p.push_back("velocity_window must be >= 0");
  if (!(systematic_point_sigma >= 0)) p.push_back("systematic_point_sigma must be >= 0");
  if (decimation < 1 || decimation > 16) p.push_back("decimation must be in [1, 16]");
  return p;
}

PlaneOdometry::PlaneOdometry(PlaneOdometryConfig config, const Pose& T_world_first)
    : config_(std::move(config)),
      T_world_first_(T_world_first),
      T_world_sensor_(T_world_first),
      velocity_(config_.velocity_window) {
  config_.registration.systematic_point_sigma = config_.systematic_point_sigma;
}

void PlaneOdometry::Reset(const Pose& T_world_first) {
  T_world_first_ = T_world_first;
  T_world_sensor_ = T_world_first;
  trajectory_ = {};
  have_prev_ = false;
  prev_planes_.clear();
  prev_cloud_ = {};
  map_.reset();
  depth_map_.reset();
  velocity_.Clear();
  last_dt_ = 0.0;
  frames_ = 0;
}

bool PlaneOdometry::HasVelocity(double timestamp) const {
  const double dt = timestamp - prev_stamp_;
  return !velocity_.empty() && dt > 0 && dt <= config_.max_prior_gap && last_dt_ > 0;
}

MotionPrior PlaneOdometry::Predict(double timestamp) const {
  MotionPrior prior;  // "no motion", weak: used without a velocity or across a long gap
  const double dt = timestamp - prev_stamp_;
  if (!HasVelocity(timestamp)) return prior;
  // Constant velocity, scaled to this interval in the (t, log R) tangent.
  const double ratio = dt / last_dt_;
  prior.T_prev_curr = velocity_.Predict(dt);
  // The velocity may change by about sigma per frame interval of this length.
  const double scale = std::max(ratio, 1e-3);
  Vector6d sig;
  sig << Eigen::Vector3d::Constant(config_.prior_translation_sigma * scale),
      Eigen::Vector3d::Constant(config_.prior_rotation_sigma * scale);
  prior.covariance = sig.array().square().matrix().asDiagonal();
  return prior;
}

OdometryStep PlaneOdometry::Track(double timestamp, const datasets::OrganizedCloud& cloud,
                                  const detection::PlaneDetector& detector) {
  if (config_.decimation == 1) return Process(timestamp, cloud, detector.Detect(cloud));
  datasets::OrganizedCloud decimated = datasets::Decimate(cloud, config_.decimation);
  const detection::Segmentation segmentation = detector.Detect(decimated);
  OdometryStep step = Step(timestamp, segmentation.planes, &decimated, &segmentation.labels);
  prev_cloud_ = std::move(decimated);
  return step;
}

OdometryStep PlaneOdometry::Process(double timestamp, const datasets::OrganizedCloud& cloud,
                                    const detection::Segmentation& segmentation) {
  OdometryStep step = Step(timestamp, segmentation.planes, &cloud, &segmentation.labels);
  prev_cloud_ = cloud;
  return step;
}

OdometryStep PlaneOdometry::Process(double timestamp, const std::vector<detection::Plane>& planes) {
  OdometryStep step = Step(timestamp, planes, nullptr, nullptr);
  prev_cloud_ = {};
  return step;
}

void PlaneOdometry::FillOpenDirections(const datasets::OrganizedCloud& cloud,
                                       const std::vector<std::int32_t>* labels,
                                       const std::vector<ShapedPoint>& structure,
                                       RegistrationResult* reg) {
  if (depth_map_ != nullptr &&
      FillDegenerateFromDepthMap(*depth_map_, T_world_sensor_, cloud, labels, reg)) {
    return;
  }
  // A pinhole pair: projective association with the previous frame's dense image pairs every
  // pixel, where the thinned local map keeps a few points per voxel (on the synthetic corridor's
  // thin pipes the map's fills are the less accurate ones).
  const bool pinhole_pair = cloud.model == datasets::SensorModel::kPinhole &&
                            !prev_cloud_.empty() && prev_cloud_.width == cloud.width &&
                            prev_cloud_.height == cloud.height;
  if (pinhole_pair) {
    if (!intrinsics_ && !intrinsics_estimated_) {
      intrinsics_ = EstimatePinholeIntrinsics(prev_cloud_);
      intrinsics_estimated_ = true;  // one attempt: the grid does not change
    }
    if (intrinsics_) {
      FillDegenerateWithPointToPlane(prev_cloud_, *intrinsics_, cloud, config_.point_to_plane,
                                     reg);
    }
  }
  if (!pinhole_pair && map_ != nullptr && !structure.empty()) {
    FillDegenerateFromLocalMap(*map_, T_world_sensor_, structure, config_.local_map, reg);
  }
}

OdometryStep PlaneOdometry::Step(double timestamp, const std::vector<detection::Plane>& planes,
                                 const datasets::OrganizedCloud* cloud,
                                 const std::vector<std::int32_t>* labels) {
  using Clock = std::chrono::steady_clock;
  OdometryStep step;
  step.frame = frames_++;
  step.timestamp = timestamp;
  step.planes_curr = static_cast<int>(planes.size());
  // The structure outside the planes and the scan's reach, for the local map.
  const auto t_points = Clock::now();
  std::vector<ShapedPoint> structure;
  double reach = 0.0;
  if (config_.use_point_to_plane && cloud != nullptr) {
    reach = ScanReach(*cloud);
    if (map_ == nullptr && reach > 0) {
      const double voxel =
          config_.local_map.voxel_size > 0 ? config_.local_map.voxel_size : reach / 100.0;
      map_ = std::make_unique<LocalVoxelMap>(voxel, config_.local_map.max_points_per_voxel);
    }
    if (map_ != nullptr) structure = ScanStructure(*cloud, labels, map_->voxel_size());
    if (depth_map_ == nullptr && cloud->model == datasets::SensorModel::kPinhole) {
      if (!intrinsics_ && !intrinsics_estimated_) {
        intrinsics_ = EstimatePinholeIntrinsics(*cloud);
        intrinsics_estimated_ = true;  // one attempt: the grid does not change
      }
      if (intrinsics_ && intrinsics_->width == cloud->width &&
          intrinsics_->height == cloud->height) {
        depth_map_ = std::make_unique<DepthLocalMap>(*intrinsics_, config_.depth_map);
      }
    }
  }
  // The alignment's queries, thinned further (KISS-ICP aligns a sparser copy than it maps).
  const std::vector<ShapedPoint> source =
      map_ != nullptr ? ThinShapedPoints(structure, 1.5 * map_->voxel_size()) : structure;
  double points_ms = std::chrono::duration<double, std::milli>(Clock::now() - t_points).count();
  if (!have_prev_) {
    step.first_frame = true;
    step.T_world_sensor = T_world_sensor_;
    step.registration.converged = false;
    step.registration.covariance = Matrix6d::Zero();
  } else {
    step.planes_prev = static_cast<int>(prev_planes_.size());
    step.prior = Predict(timestamp);
    if (!HasVelocity(timestamp) && map_ != nullptr && cloud != nullptr && !prev_cloud_.empty()) {
      // No velocity to predict from: the scans' own alignment is the prior, widened by one
      // frame's change of motion (its pairs are correlated, their covariance optimistic).
      const auto tb = Clock::now();
      const MapAlignmentResult a =
          AlignScansCoarseToFine(prev_cloud_, *cloud, step.prior.T_prev_curr,
                                 step.prior.covariance, map_->voxel_size(), config_.local_map);
      if (a.valid && a.converged) {
        Vector6d sig;
        sig << Eigen::Vector3d::Constant(config_.prior_translation_sigma),
            Eigen::Vector3d::Constant(config_.prior_rotation_sigma);
        step.prior.T_prev_curr = a.T_prev_curr;
        step.prior.covariance = a.covariance + Matrix6d(sig.array().square().matrix().asDiagonal());
        step.bootstrapped = true;
      }
      points_ms += std::chrono::duration<double, std::milli>(Clock::now() - tb).count();
    }
    const auto t0 = Clock::now();
    AssociationResult assoc = AssociatePlanes(prev_planes_, planes, step.prior, config_.association,
                                              config_.registration);
    step.association_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    step.candidates = assoc.candidates;
    RegistrationResult reg = std::move(assoc.registration);
    if (reg.degenerate && config_.use_point_to_plane && cloud != nullptr) {
      const auto t1 = Clock::now();
      FillOpenDirections(*cloud, labels, source, &reg);
      points_ms += std::chrono::duration<double, std::milli>(Clock::now() - t1).count();
    }
    // Range images refine all six directions on the map; depth images keep the planes' estimate
    // where it is determined (their map holds one camera's narrow view of few structure points).
    if (reg.converged && map_ != nullptr && !source.empty() &&
        cloud->model != datasets::SensorModel::kPinhole) {
      const auto t1 = Clock::now();
      RefineWithLocalMap(*map_, T_world_sensor_, source, config_.local_map, &reg);
      points_ms += std::chrono::duration<double, std::milli>(Clock::now() - t1).count();
    }
    step.T_prev_curr = reg.T_prev_curr;
    step.covariance = reg.covariance;
    step.registration = std::move(reg);
    T_world_sensor_ = T_world_sensor_ * step.T_prev_curr;
    // Re-orthonormalise so thousands of products do not drift off SO(3).
    T_world_sensor_.linear() =
        Eigen::Quaterniond(T_world_sensor_.linear()).normalized().toRotationMatrix();
    step.T_world_sensor = T_world_sensor_;
    const double dt = timestamp - prev_stamp_;
    velocity_.Add(timestamp, dt, step.T_prev_curr);
    last_dt_ = dt;
  }
  if (map_ != nullptr && !structure.empty()) {
    const auto t2 = Clock::now();
    map_->Insert(structure, T_world_sensor_, reach);
    points_ms += std::chrono::duration<double, std::milli>(Clock::now() - t2).count();
  }
  if (depth_map_ != nullptr && cloud != nullptr) {
    const auto t3 = Clock::now();
    depth_map_->Insert(*cloud, labels, T_world_sensor_);
    points_ms += std::chrono::duration<double, std::milli>(Clock::now() - t3).count();
  }
  step.point_to_plane_ms = points_ms;
  trajectory_.Add(timestamp, T_world_sensor_);
  have_prev_ = true;
  prev_stamp_ = timestamp;
  prev_planes_ = planes;  // the caller keeps the cloud as prev_cloud_ (Track moves its own)
  return step;
}

}  // namespace planeslam::registration
