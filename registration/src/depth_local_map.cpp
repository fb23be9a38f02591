#include "planeslam/registration/depth_local_map.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

#include "prior_step.hpp"

namespace planeslam::registration {

using internal::IsTranslation;

std::vector<std::string> DepthMapConfig::Validate() const {
  std::vector<std::string> p;
  if (!(sigma0 >= 0) || !(sigma_z2 >= 0) || !(sigma0 + sigma_z2 > 0)) {
    p.push_back("sigma0 and sigma_z2 must be >= 0 and not both 0");
  }
  if (!(sigma_floor > 0)) p.push_back("sigma_floor must be > 0");
  if (insert_stride < 1 || query_stride < 1) p.push_back("strides must be >= 1");
  if (normal_pixel_step < 1) p.push_back("normal_pixel_step must be >= 1");
  if (!(max_neighbour_distance_ratio > 0)) p.push_back("max_neighbour_distance_ratio must be > 0");
  if (!(max_correspondence_distance > 0)) p.push_back("max_correspondence_distance must be > 0");
  if (!(fusion_sigmas > 0)) p.push_back("fusion_sigmas must be > 0");
  if (!(reanchor_distance > 0) || !(reanchor_angle_deg > 0)) {
    p.push_back("reanchor_distance and reanchor_angle_deg must be > 0");
  }
  if (!(huber_sigmas > 0)) p.push_back("huber_sigmas must be > 0");
  if (!(max_whitened_residual > 0)) p.push_back("max_whitened_residual must be > 0");
  if (max_iterations < 1) p.push_back("max_iterations must be >= 1");
  if (!(convergence_step > 0)) p.push_back("convergence_step must be > 0");
  if (min_correspondences < 1) p.push_back("min_correspondences must be >= 1");
  if (min_support < 0) p.push_back("min_support must be >= 0");
  if (!(max_translation_sigma > 0) || !(max_rotation_sigma > 0)) {
    p.push_back("max sigmas must be > 0");
  }
  return p;
}

DepthLocalMap::DepthLocalMap(const datasets::PinholeIntrinsics& intrinsics,
                             const DepthMapConfig& config)
    : K_(intrinsics),
      config_(config),
      depth_(static_cast<std::size_t>(std::max(intrinsics.width, 0)) *
                 static_cast<std::size_t>(std::max(intrinsics.height, 0)),
             0.0f),
      weight_(depth_.size(), 0.0f) {}

void DepthLocalMap::Clear() {
  std::fill(depth_.begin(), depth_.end(), 0.0f);
  std::fill(weight_.begin(), weight_.end(), 0.0f);
  filled_ = 0;
}

void DepthLocalMap::Splat(const Eigen::Vector3d& p, double w) {
  if (!(p.z() > 1e-3) || !(w > 0)) return;
  const double u = K_.fx * p.x() / p.z() + K_.cx;
  const double v = K_.fy * p.y() / p.z() + K_.cy;
  if (!(u > -0.5 && v > -0.5 && u < K_.width - 0.5 && v < K_.height - 0.5)) return;
  const std::size_t i = static_cast<std::size_t>(std::lround(v)) * K_.width + std::lround(u);
  const double z = p.z();
  const double d = depth_[i], W = weight_[i];
  if (!(W > 0)) {
    depth_[i] = static_cast<float>(z);
    weight_[i] = static_cast<float>(w);
    ++filled_;
    return;
  }
  const double gate = config_.fusion_sigmas * std::sqrt(1.0 / w + 1.0 / W);
  if (std::abs(z - d) <= gate) {
    depth_[i] = static_cast<float>((W * d + w * z) / (W + w));
    weight_[i] = static_cast<float>(W + w);
  } else if (z < d) {
    // A nearer surface, or one outlier of the noise: the fused depth loses the sample's weight
    // and is replaced only when that has used it up (an occluder that stays).
    if (W - w > 0) {
      weight_[i] = static_cast<float>(W - w);
    } else {
      depth_[i] = static_cast<float>(z);
      weight_[i] = static_cast<float>(w);
    }
  }
}

bool DepthLocalMap::FusedPoint(int row, int col, Eigen::Vector3d* p, double* weight) const {
  if (row < 0 || col < 0 || row >= K_.height || col >= K_.width) return false;
  const std::size_t i = static_cast<std::size_t>(row) * K_.width + col;
  if (!(weight_[i] > 0)) return false;
  const double z = depth_[i];
  *p = Eigen::Vector3d((col - K_.cx) / K_.fx * z, (row - K_.cy) / K_.fy * z, z);
  *weight = weight_[i];
  return true;
}

bool DepthLocalMap::Normal(int row, int col, Eigen::Vector3d* n) const {
  const int s = config_.normal_pixel_step;
  Eigen::Vector3d c, l, r, u, d;
  double w;
  if (!FusedPoint(row, col, &c, &w) || !FusedPoint(row, col - s, &l, &w) ||
      !FusedPoint(row, col + s, &r, &w) || !FusedPoint(row - s, col, &u, &w) ||
      !FusedPoint(row + s, col, &d, &w)) {
    return false;
  }
  const double md = config_.max_neighbour_distance_ratio * c.norm();
  if ((l - c).norm() > md || (r - c).norm() > md || (u - c).norm() > md || (d - c).norm() > md) {
    return false;  // a depth edge: the neighbours are on another surface
  }
  const Eigen::Vector3d v = (r - l).cross(d - u);
  const double norm = v.norm();
  if (!(norm > 0)) return false;
  *n = v / norm;
  return true;
}

void DepthLocalMap::Reanchor(const Pose& T_world_new) {
  std::vector<float> depth = std::move(depth_), weight = std::move(weight_);
  depth_.assign(depth.size(), 0.0f);
  weight_.assign(depth.size(), 0.0f);
  filled_ = 0;
  const Pose T_new_old = T_world_new.inverse() * T_world_ref_;
  for (int row = 0; row < K_.height; ++row) {
    for (int col = 0; col < K_.width; ++col) {
      const std::size_t i = static_cast<std::size_t>(row) * K_.width + col;
      if (!(weight[i] > 0)) continue;
      const double z = depth[i];
      const Eigen::Vector3d p((col - K_.cx) / K_.fx * z, (row - K_.cy) / K_.fy * z, z);
      Splat(T_new_old * p, weight[i]);
    }
  }
  T_world_ref_ = T_world_new;
}

void DepthLocalMap::Insert(const datasets::OrganizedCloud& cloud,
                           const std::vector<std::int32_t>* labels, const Pose& T_world_sensor) {
  if (cloud.width != K_.width || cloud.height != K_.height) return;
  if (empty()) {
    T_world_ref_ = T_world_sensor;
  } else {
    const Pose T_ref_sensor = T_world_ref_.inverse() * T_world_sensor;
    const double angle = Eigen::AngleAxisd(T_ref_sensor.linear()).angle();
    if (T_ref_sensor.translation().norm() > config_.reanchor_distance ||
        angle > config_.reanchor_angle_deg * M_PI / 180.0) {
      Reanchor(T_world_sensor);
    }
  }
  const Pose T_ref_sensor = T_world_ref_.inverse() * T_world_sensor;
  const bool use_labels = labels != nullptr && labels->size() == cloud.points.size();
  const int s = config_.insert_stride;
  for (int row = 0; row < cloud.height; row += s) {
    for (int col = 0; col < cloud.width; col += s) {
      const std::size_t i = static_cast<std::size_t>(row) * cloud.width + col;
      const Eigen::Vector3f& pf = cloud.points[i];
      if (!datasets::OrganizedCloud::IsValid(pf) || !(pf.z() > 0)) continue;
      if (use_labels && (*labels)[i] >= 1) continue;
      const double sigma = Sigma(pf.z());
      Splat(T_ref_sensor * pf.cast<double>(), 1.0 / (sigma * sigma));
    }
  }
}

namespace {


/// A query pixel: its point (sensor frame), unit ray and depth noise.
struct Query {
  Eigen::Vector3d p;
  Eigen::Vector3d ray;
  double sigma;
};

std::vector<Query> Queries(const DepthLocalMap& map, const datasets::OrganizedCloud& curr,
                           const std::vector<std::int32_t>* labels) {
  const bool use_labels = labels != nullptr && labels->size() == curr.points.size();
  std::vector<Query> out;
  const int s = map.config().query_stride;
  for (int row = 0; row < curr.height; row += s) {
    for (int col = 0; col < curr.width; col += s) {
      const std::size_t i = static_cast<std::size_t>(row) * curr.width + col;
      const Eigen::Vector3f& pf = curr.points[i];
      if (!datasets::OrganizedCloud::IsValid(pf) || !(pf.z() > 0)) continue;
      if (use_labels && (*labels)[i] >= 1) continue;
      const Eigen::Vector3d p = pf.cast<double>();
      out.push_back({p, p / p.norm(), map.Sigma(p.z())});
    }
  }
  return out;
}

}  // namespace

PointToPlaneResult AlignToDepthMap(const DepthLocalMap& map, const Pose& T_world_prev,
                                   const datasets::OrganizedCloud& curr,
                                   const std::vector<std::int32_t>* labels, const Pose& T_init,
                                   const Eigen::MatrixXd& D,
                                   const Eigen::MatrixXd& prior_covariance) {
  const DepthMapConfig& config = map.config();
  const datasets::PinholeIntrinsics& K = map.intrinsics();
  PointToPlaneResult res;
  res.T_prev_curr = T_init;
  const int k = static_cast<int>(D.cols());
  res.information = Eigen::MatrixXd::Zero(k, k);
  res.covariance = prior_covariance;
  res.support.assign(k, 0);
  if (!internal::DirectionsUsable(D, prior_covariance) || map.empty() || curr.empty()) return res;
  const Eigen::MatrixXd h_prior = internal::PriorInformation(prior_covariance);
  const std::vector<Query> queries = Queries(map, curr, labels);
  std::vector<char> is_translation(k);
  for (int i = 0; i < k; ++i) is_translation[i] = IsTranslation(D.col(i));
  const Pose T_ref_prev = map.T_world_ref().inverse() * T_world_prev;
  const Eigen::Matrix3d R_rp = T_ref_prev.linear();
  const double floor2 = config.sigma_floor * config.sigma_floor;
  Eigen::VectorXd jy(k);
  Eigen::VectorXd y = Eigen::VectorXd::Zero(k);
  for (int it = 0; it < config.max_iterations; ++it) {
    const Pose T = BoxPlus(T_init, D * y);
    const Pose T_ref_curr = T_ref_prev * T;
    const Eigen::Matrix3d R = T.linear();
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(k, k);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(k);
    std::vector<int> support(k, 0);
    int count = 0;
    double sum_chi2 = 0.0, sum_sq = 0.0;
    for (const Query& query : queries) {
      const Eigen::Vector3d q = T_ref_curr * query.p;
      if (!(q.z() > 1e-3)) continue;
      const double u = K.fx * q.x() / q.z() + K.cx;
      const double v = K.fy * q.y() / q.z() + K.cy;
      if (!(u > -0.5 && v > -0.5 && u < K.width - 0.5 && v < K.height - 0.5)) continue;
      const int col = static_cast<int>(std::lround(u)), row = static_cast<int>(std::lround(v));
      Eigen::Vector3d m, n;
      double weight = 0.0;
      if (!map.FusedPoint(row, col, &m, &weight)) continue;
      if ((q - m).norm() > config.max_correspondence_distance) continue;
      if (!map.Normal(row, col, &n)) continue;
      const double r = n.dot(q - m);
      const double ray_q = n.dot(T_ref_curr.linear() * query.ray);
      const double ray_m = n.dot(m) / m.norm();
      const double var =
          query.sigma * query.sigma * ray_q * ray_q + ray_m * ray_m / weight + floor2;
      const double z = r / std::sqrt(var);
      if (!(std::abs(z) <= config.max_whitened_residual)) continue;
      // d q_ref / d(dt, dtheta) = R_rp [I, -[R p]_x] (left perturbation in the previous frame).
      const Eigen::Vector3d rp = R * query.p;
      const Eigen::Vector3d n_prev = R_rp.transpose() * n;
      Vector6d j6;
      j6.head<3>() = n_prev;
      j6.tail<3>() = rp.cross(n_prev);
      jy.noalias() = D.transpose() * j6;
      const double lever = std::max(rp.norm(), 1e-9);
      for (int i = 0; i < k; ++i) {
        const double facing = is_translation[i] ? std::abs(jy(i)) : std::abs(jy(i)) / lever;
        if (facing > 0.5) {
          ++support[i];
        } else if (is_translation[i]) {
          // As in AlignPointToPlane: surfaces parallel to a translation give it no signal, only
          // the noise of their normals.
          jy(i) = 0.0;
        }
      }
      const double huber =
          std::abs(z) <= config.huber_sigmas ? 1.0 : config.huber_sigmas / std::abs(z);
      H.noalias() += (huber / var) * jy * jy.transpose();
      g.noalias() += (huber / var) * jy * r;
      ++count;
      sum_chi2 += z * z;
      sum_sq += r * r;
    }
    res.iterations = it + 1;
    if (count < config.min_correspondences) {
      res.valid = false;
      return res;
    }
    res.correspondences = count;
    res.support = support;
    res.residual_rms = std::sqrt(sum_sq / count);
    // The noise model's information, scaled down when the residuals spread wider than it says.
    const double scale = std::max(1.0, sum_chi2 / count);
    res.information = H / scale;
    Eigen::VectorXd step;
    if (!internal::PriorStep(res.information, g / scale, h_prior, y, &step, &res.covariance)) {
      res.valid = false;
      return res;
    }
    y += step;
    if (step.norm() < config.convergence_step) {
      res.converged = true;
      break;
    }
  }
  res.T_prev_curr = BoxPlus(T_init, D * y);
  res.valid = res.T_prev_curr.matrix().allFinite() && res.covariance.allFinite();
  return res;
}

bool FillDegenerateFromDepthMap(const DepthLocalMap& map, const Pose& T_world_prev,
                                const datasets::OrganizedCloud& curr,
                                const std::vector<std::int32_t>* labels,
                                RegistrationResult* result) {
  if (map.empty()) return false;
  const Pose T_planes = result->T_prev_curr;
  const DirectionAligner align = [&](const Eigen::MatrixXd& D, const Eigen::MatrixXd& prior) {
    return AlignToDepthMap(map, T_world_prev, curr, labels, T_planes, D, prior);
  };
  const DepthMapConfig& c = map.config();
  return FillDegenerateDirections(
      align, {c.min_support, c.max_translation_sigma, c.max_rotation_sigma}, result);
}

}  // namespace planeslam::registration
