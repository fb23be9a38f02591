// PCL baselines for `planeslam bench`, built as the plugin libplaneslam_pcl.so (see baselines.hpp):
// the only translation unit of the app that includes PCL's segmentation/registration headers
// (they take long to compile).
#include "pcl/baselines.hpp"

#include <pcl/console/print.h>
#include <pcl/features/integral_image_normal.h>
#include <pcl/filters/voxel_grid.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/gicp.h>
#include <pcl/segmentation/organized_multi_plane_segmentation.h>

#include <chrono>
#include <cmath>
#include <limits>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/detection/plane_moments.hpp"

namespace planeslam::app::pcl_baselines {
namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

constexpr double kDegToRad = M_PI / 180.0;

/// Organized copy (same grid, NaN for invalid pixels), as OMPS and the integral images need.
pcl::PointCloud<pcl::PointXYZ>::Ptr ToPclOrganized(const datasets::OrganizedCloud& cloud) {
  auto out = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  out->width = static_cast<std::uint32_t>(cloud.width);
  out->height = static_cast<std::uint32_t>(cloud.height);
  out->is_dense = false;
  out->points.resize(cloud.size());
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f& p = cloud.points[i];
    if (datasets::OrganizedCloud::IsValid(p)) {
      out->points[i] = pcl::PointXYZ(p.x(), p.y(), p.z());
    } else {
      out->points[i] = pcl::PointXYZ(nan, nan, nan);
    }
  }
  return out;
}

/// Valid points only (unorganized), optionally range-limited, for voxel downsampling.
pcl::PointCloud<pcl::PointXYZ>::Ptr ToPclValid(const datasets::OrganizedCloud& cloud,
                                               double max_range) {
  auto out = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  out->points.reserve(cloud.size());
  const double max_sq = max_range > 0.0 ? max_range * max_range : 0.0;
  for (const Eigen::Vector3f& p : cloud.points) {
    if (!datasets::OrganizedCloud::IsValid(p)) continue;
    if (max_sq > 0.0 && p.cast<double>().squaredNorm() > max_sq) continue;
    out->points.emplace_back(p.x(), p.y(), p.z());
  }
  out->width = static_cast<std::uint32_t>(out->points.size());
  out->height = 1;
  out->is_dense = true;
  return out;
}

/// GICP with access to the covariances it computed for the source, so they can be handed over as
/// the next frame's target covariances instead of being recomputed.
class ReusingGicp : public pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> {
 public:
  MatricesVectorPtr SourceCovariances() const { return input_covariances_; }
};

}  // namespace

/// OmpsDetector's implementation.
class OmpsPcl : public detection::PlaneDetector {
 public:
  explicit OmpsPcl(OmpsConfig config);
  std::string Name() const override { return "pcl_omps"; }
  detection::Segmentation Detect(const datasets::OrganizedCloud& cloud) const override;

 private:
  OmpsConfig config_;
};

/// GicpOdometry's implementation.
class GicpPcl : public GicpBackend {
 public:
  explicit GicpPcl(GicpConfig config);
  GicpStep Track(const datasets::OrganizedCloud& cloud) override;
  void Reset() override;

 private:
  struct State;
  GicpConfig config_;
  std::unique_ptr<State> state_;
};

OmpsPcl::OmpsPcl(OmpsConfig config) : config_(std::move(config)) {
  PLANESLAM_CHECK(config_.normal_method == "covariance" ||
                      config_.normal_method == "average_3d_gradient",
                  "unknown normal method " << config_.normal_method);
  PLANESLAM_CHECK(config_.min_inliers >= 3, "min_inliers " << config_.min_inliers);
  // PCL prints a warning per call on non-projective (spherical) grids; errors are still shown.
  pcl::console::setVerbosityLevel(pcl::console::L_ERROR);
}

detection::Segmentation OmpsPcl::Detect(const datasets::OrganizedCloud& cloud) const {
  detection::Segmentation seg;
  seg.width = cloud.width;
  seg.height = cloud.height;
  seg.labels.assign(cloud.size(), -1);
  // PCL's integral images need at least a few rows and columns and some valid points.
  if (cloud.width < 3 || cloud.height < 3 || cloud.CountValid() < 3) return seg;

  auto t0 = Clock::now();
  const pcl::PointCloud<pcl::PointXYZ>::Ptr input = ToPclOrganized(cloud);
  seg.timings_ms.emplace_back("convert", MsSince(t0));

  t0 = Clock::now();
  auto normals = std::make_shared<pcl::PointCloud<pcl::Normal>>();
  pcl::IntegralImageNormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
  ne.setNormalEstimationMethod(config_.normal_method == "covariance"
                                   ? ne.COVARIANCE_MATRIX
                                   : ne.AVERAGE_3D_GRADIENT);
  ne.setMaxDepthChangeFactor(static_cast<float>(config_.max_depth_change_factor));
  ne.setNormalSmoothingSize(static_cast<float>(config_.normal_smoothing_size));
  ne.setInputCloud(input);
  ne.compute(*normals);
  seg.timings_ms.emplace_back("normals", MsSince(t0));

  t0 = Clock::now();
  pcl::OrganizedMultiPlaneSegmentation<pcl::PointXYZ, pcl::Normal, pcl::Label> mps;
  mps.setMinInliers(static_cast<unsigned>(config_.min_inliers));
  mps.setAngularThreshold(config_.angular_threshold_deg * kDegToRad);
  mps.setDistanceThreshold(config_.distance_threshold);
  mps.setMaximumCurvature(config_.maximum_curvature);
  mps.setInputNormals(normals);
  mps.setInputCloud(input);
  std::vector<pcl::ModelCoefficients> coefficients;
  std::vector<pcl::PointIndices> inliers;
  mps.segment(coefficients, inliers);
  seg.timings_ms.emplace_back("segment", MsSince(t0));

  // Refit each region in double with our moments: same least-squares plane as PCL's float fit, but
  // with our orientation convention (d >= 0) and the statistics our metrics and map use.
  t0 = Clock::now();
  for (const pcl::PointIndices& region : inliers) {
    detection::PlaneMoments moments;
    bool first = true;
    for (const int idx : region.indices) {
      const Eigen::Vector3f& p = cloud.points[static_cast<std::size_t>(idx)];
      if (!datasets::OrganizedCloud::IsValid(p)) continue;
      if (first) {
        moments = detection::PlaneMoments(p.cast<double>());
        first = false;
      }
      moments.Add(p);
    }
    const detection::PlaneFit fit = moments.Fit();
    if (!fit.valid) continue;
    detection::Plane plane;
    plane.id = static_cast<int>(seg.planes.size()) + 1;
    plane.normal = fit.normal;
    plane.d = fit.d;
    plane.centroid = fit.centroid;
    plane.point_count = moments.count();
    plane.mse = fit.mse;
    plane.eigenvalues = fit.eigenvalues;
    plane.moments = moments;
    for (const int idx : region.indices) seg.labels[static_cast<std::size_t>(idx)] = plane.id;
    seg.planes.push_back(plane);
  }
  seg.timings_ms.emplace_back("output", MsSince(t0));
  return seg;
}

struct GicpPcl::State {
  pcl::PointCloud<pcl::PointXYZ>::Ptr previous;
  ReusingGicp::MatricesVectorPtr previous_covariances;
  Pose velocity = Pose::Identity();  ///< last T_prev_curr, the constant-velocity prior
};

GicpPcl::GicpPcl(GicpConfig config)
    : config_(config), state_(std::make_unique<State>()) {
  PLANESLAM_CHECK(config_.voxel_size > 0.0, "voxel_size " << config_.voxel_size);
}

void GicpPcl::Reset() { state_ = std::make_unique<State>(); }

GicpStep GicpPcl::Track(const datasets::OrganizedCloud& cloud) {
  GicpStep step;
  const pcl::PointCloud<pcl::PointXYZ>::Ptr valid = ToPclValid(cloud, config_.max_range);
  const auto t0 = Clock::now();
  auto down = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  if (!valid->empty()) {
    pcl::VoxelGrid<pcl::PointXYZ> grid;
    const float leaf = static_cast<float>(config_.voxel_size);
    grid.setLeafSize(leaf, leaf, leaf);
    grid.setInputCloud(valid);
    grid.filter(*down);
  }
  step.source_points = down->size();
  // Too few points for k-neighbour covariances: report a failed step and keep the prior.
  const std::size_t min_points = static_cast<std::size_t>(config_.correspondence_randomness) + 1;
  if (!state_->previous) {
    step.converged = down->size() >= min_points;
    if (step.converged) state_->previous = down;
    step.time_ms = MsSince(t0);
    return step;
  }
  if (down->size() < min_points) {
    step.T_prev_curr = state_->velocity;
    step.converged = false;
    step.time_ms = MsSince(t0);
    return step;
  }

  ReusingGicp gicp;
  gicp.setMaxCorrespondenceDistance(config_.max_correspondence_distance);
  gicp.setMaximumIterations(config_.max_iterations);
  gicp.setTransformationEpsilon(config_.transformation_epsilon);
  gicp.setCorrespondenceRandomness(config_.correspondence_randomness);
  gicp.setInputSource(down);
  gicp.setInputTarget(state_->previous);
  if (state_->previous_covariances) gicp.setTargetCovariances(state_->previous_covariances);
  pcl::PointCloud<pcl::PointXYZ> aligned;
  gicp.align(aligned, state_->velocity.matrix().cast<float>());

  step.converged = gicp.hasConverged();
  step.fitness = gicp.getFitnessScore(config_.max_correspondence_distance);
  Pose T = Pose::Identity();
  const Eigen::Matrix4d m = gicp.getFinalTransformation().cast<double>();
  // Re-orthonormalise the float rotation so the pose stays a proper isometry.
  const Eigen::Quaterniond q(Eigen::Matrix3d(m.block<3, 3>(0, 0)));
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() = m.block<3, 1>(0, 3);
  if (step.converged) {
    step.T_prev_curr = T;
    state_->velocity = T;
  } else {
    step.T_prev_curr = state_->velocity;
  }
  state_->previous = down;
  state_->previous_covariances = gicp.SourceCovariances();
  step.time_ms = MsSince(t0);
  return step;
}

}  // namespace planeslam::app::pcl_baselines

namespace pb = planeslam::app::pcl_baselines;

extern "C" {
__attribute__((visibility("default"))) int planeslam_pcl_plugin_abi() { return pb::kPluginAbi; }

__attribute__((visibility("default"))) planeslam::detection::PlaneDetector*
planeslam_pcl_make_omps(const pb::OmpsConfig* config) {
  return new pb::OmpsPcl(*config);
}

__attribute__((visibility("default"))) pb::GicpBackend* planeslam_pcl_make_gicp(
    const pb::GicpConfig* config) {
  return new pb::GicpPcl(*config);
}
}
