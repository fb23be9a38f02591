#include "planeslam/registration/point_to_plane.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

#include "prior_step.hpp"

namespace planeslam::registration {

using internal::Chi2Quantile999;
using internal::IsTranslation;

std::vector<std::string> PointToPlaneConfig::Validate() const {
  std::vector<std::string> p;
  if (pixel_stride < 1) p.push_back("pixel_stride must be >= 1");
  if (normal_pixel_step < 1) p.push_back("normal_pixel_step must be >= 1");
  if (!(max_neighbour_distance_ratio > 0)) p.push_back("max_neighbour_distance_ratio must be > 0");
  if (!(max_correspondence_distance > 0)) p.push_back("max_correspondence_distance must be > 0");
  if (!(huber_delta > 0)) p.push_back("huber_delta must be > 0");
  if (!(point_sigma > 0)) p.push_back("point_sigma must be > 0");
  if (max_iterations < 1) p.push_back("max_iterations must be >= 1");
  if (!(convergence_step > 0)) p.push_back("convergence_step must be > 0");
  if (min_correspondences < 1) p.push_back("min_correspondences must be >= 1");
  if (min_support < 0) p.push_back("min_support must be >= 0");
  if (!(max_translation_sigma > 0)) p.push_back("max_translation_sigma must be > 0");
  if (!(max_rotation_sigma > 0)) p.push_back("max_rotation_sigma must be > 0");
  return p;
}

std::optional<datasets::PinholeIntrinsics> EstimatePinholeIntrinsics(
    const datasets::OrganizedCloud& cloud) {
  if (cloud.model != datasets::SensorModel::kPinhole || cloud.empty()) return std::nullopt;
  // Two independent 1D regressions: col = fx (x/z) + cx and row = fy (y/z) + cy.
  const int step = std::max(1, std::min(cloud.width, cloud.height) / 60);
  double n = 0, sa = 0, saa = 0, su = 0, sau = 0, sb = 0, sbb = 0, sv = 0, sbv = 0;
  for (int r = 0; r < cloud.height; r += step) {
    for (int c = 0; c < cloud.width; c += step) {
      const Eigen::Vector3f& p = cloud.at(r, c);
      if (!datasets::OrganizedCloud::IsValid(p) || !(p.z() > 1e-6)) continue;
      const double a = p.x() / p.z(), b = p.y() / p.z();
      n += 1;
      sa += a;
      saa += a * a;
      su += c;
      sau += a * c;
      sb += b;
      sbb += b * b;
      sv += r;
      sbv += b * r;
    }
  }
  if (n < 20) return std::nullopt;
  const double var_a = saa - sa * sa / n, var_b = sbb - sb * sb / n;
  if (!(var_a > 1e-12) || !(var_b > 1e-12)) return std::nullopt;
  datasets::PinholeIntrinsics k;
  k.width = cloud.width;
  k.height = cloud.height;
  k.fx = (sau - sa * su / n) / var_a;
  k.cx = (su - k.fx * sa) / n;
  k.fy = (sbv - sb * sv / n) / var_b;
  k.cy = (sv - k.fy * sb) / n;
  // Check the fit: a pinhole grid reprojects every point onto its own pixel.
  double sq = 0;
  int m = 0;
  for (int r = 0; r < cloud.height; r += step) {
    for (int c = 0; c < cloud.width; c += step) {
      const Eigen::Vector3f& p = cloud.at(r, c);
      if (!datasets::OrganizedCloud::IsValid(p) || !(p.z() > 1e-6)) continue;
      const double du = k.fx * p.x() / p.z() + k.cx - c;
      const double dv = k.fy * p.y() / p.z() + k.cy - r;
      sq += du * du + dv * dv;
      ++m;
    }
  }
  if (!(std::sqrt(sq / m) < 0.5) || !std::isfinite(k.fx) || !std::isfinite(k.fy)) {
    return std::nullopt;
  }
  return k;
}

namespace {

/// Normal of the prev cloud at (row, col) from its 4-neighbourhood at distance `s`, or false.
bool NormalAt(const datasets::OrganizedCloud& cloud, int row, int col, int s, double max_ratio,
              Eigen::Vector3d* n) {
  if (row - s < 0 || row + s >= cloud.height || col - s < 0 || col + s >= cloud.width) return false;
  const Eigen::Vector3f& c = cloud.at(row, col);
  const Eigen::Vector3f& l = cloud.at(row, col - s);
  const Eigen::Vector3f& r = cloud.at(row, col + s);
  const Eigen::Vector3f& u = cloud.at(row - s, col);
  const Eigen::Vector3f& d = cloud.at(row + s, col);
  using datasets::OrganizedCloud;
  if (!OrganizedCloud::IsValid(l) || !OrganizedCloud::IsValid(r) || !OrganizedCloud::IsValid(u) ||
      !OrganizedCloud::IsValid(d)) {
    return false;
  }
  const float md = static_cast<float>(max_ratio) * c.norm();
  if ((l - c).norm() > md || (r - c).norm() > md || (u - c).norm() > md || (d - c).norm() > md) {
    return false;  // a depth edge: the neighbours are on another surface
  }
  const Eigen::Vector3d v = (r - l).cast<double>().cross((d - u).cast<double>());
  const double norm = v.norm();
  if (!(norm > 0)) return false;
  *n = v / norm;
  return true;
}

}  // namespace

PointToPlaneResult AlignPointToPlane(const datasets::OrganizedCloud& prev,
                                     const datasets::PinholeIntrinsics& K,
                                     const datasets::OrganizedCloud& curr, const Pose& T_init,
                                     const Eigen::MatrixXd& D,
                                     const Eigen::MatrixXd& prior_covariance,
                                     const PointToPlaneConfig& config) {
  PointToPlaneResult res;
  res.T_prev_curr = T_init;
  const int k = static_cast<int>(D.cols());
  res.information = Eigen::MatrixXd::Zero(k, k);
  res.covariance = prior_covariance;
  res.support.assign(k, 0);
  if (!internal::DirectionsUsable(D, prior_covariance) || prev.empty() || curr.empty()) return res;
  const Eigen::MatrixXd h_prior = internal::PriorInformation(prior_covariance);
  const int s = config.pixel_stride;
  // Per direction, once: translation or rotation (it decides what "facing" means per pair).
  std::vector<char> is_translation(k);
  for (int i = 0; i < k; ++i) is_translation[i] = IsTranslation(D.col(i));
  Eigen::VectorXd jy(k);  // a pair's Jacobian along the directions, reused (no allocation per pair)
  Eigen::VectorXd y = Eigen::VectorXd::Zero(k);
  for (int it = 0; it < config.max_iterations; ++it) {
    const Pose T = BoxPlus(T_init, D * y);
    const Eigen::Matrix3d R = T.linear();
    const Eigen::Vector3d t = T.translation();
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(k, k);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(k);
    std::vector<int> support(k, 0);
    int count = 0;
    double sum_sq = 0.0;
    for (int row = 0; row < curr.height; row += s) {
      for (int col = 0; col < curr.width; col += s) {
        const Eigen::Vector3f& pf = curr.at(row, col);
        if (!datasets::OrganizedCloud::IsValid(pf)) continue;
        const Eigen::Vector3d rp = R * pf.cast<double>();
        const Eigen::Vector3d q = rp + t;
        if (!(q.z() > 1e-3)) continue;
        const double u = K.fx * q.x() / q.z() + K.cx;
        const double v = K.fy * q.y() / q.z() + K.cy;
        if (!(u > -0.5 && v > -0.5 && u < prev.width - 0.5 && v < prev.height - 0.5)) continue;
        const int pc = static_cast<int>(std::lround(u));
        const int pr = static_cast<int>(std::lround(v));
        const Eigen::Vector3f& pa = prev.at(pr, pc);
        if (!datasets::OrganizedCloud::IsValid(pa)) continue;
        const Eigen::Vector3d diff = q - pa.cast<double>();
        if (diff.norm() > config.max_correspondence_distance) continue;
        Eigen::Vector3d n;
        if (!NormalAt(prev, pr, pc, config.normal_pixel_step, config.max_neighbour_distance_ratio,
                      &n)) {
          continue;
        }
        const double r = n.dot(diff);
        // d r / d(dt, dtheta) with R <- Exp(dtheta) R, t <- t + dt (geometry.hpp).
        Vector6d j6;
        j6.head<3>() = n;
        j6.tail<3>() = rp.cross(n);
        jy.noalias() = D.transpose() * j6;
        const double w = std::abs(r) <= config.huber_delta ? 1.0 : config.huber_delta / std::abs(r);
        const double lever = std::max(rp.norm(), 1e-9);
        for (int i = 0; i < k; ++i) {
          const bool translation = is_translation[i];
          const double facing = translation ? std::abs(jy(i)) : std::abs(jy(i)) / lever;
          if (facing > 0.5) {
            ++support[i];
          } else if (translation) {
            // A pair informs a translation only when its normal faces it. On surfaces parallel
            // to it (a corridor's walls, seen from inside) the noise of the normals gives them
            // a share of it, information without signal that holds the estimate at its start.
            // Rotations keep every pair's information (the facing test only counts support):
            // dropping the others there loses more accuracy than it removes bias.
            jy(i) = 0.0;
          }
        }
        H.noalias() += w * jy * jy.transpose();
        g.noalias() += w * jy * r;
        ++count;
        sum_sq += r * r;
      }
    }
    res.iterations = it + 1;
    if (count < config.min_correspondences) {
      res.valid = false;
      return res;
    }
    res.correspondences = count;
    res.support = support;
    res.residual_rms = std::sqrt(sum_sq / count);
    // Residual sigma: the observed spread, floored (neighbouring pairs are correlated, so the
    // information is optimistic; the floor keeps it in check).
    const double sigma2 = std::max(config.point_sigma * config.point_sigma, sum_sq / count);
    res.information = H / sigma2;
    Eigen::VectorXd step;
    if (!internal::PriorStep(res.information, g / sigma2, h_prior, y, &step, &res.covariance)) {
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

bool FillDegenerateDirections(const DirectionAligner& align, const FillLimits& limits,
                              RegistrationResult* result) {
  const int k = static_cast<int>(result->degenerate_directions.size());
  if (k == 0) return false;
  Eigen::MatrixXd D(6, k);
  for (int i = 0; i < k; ++i) D.col(i) = result->degenerate_directions[i];

  // Decides, per direction, whether the points pin it down: enough facing pairs, and a marginal
  // sigma from the point pairs alone below the limit.
  auto determined = [&](const PointToPlaneResult& icp, const Eigen::MatrixXd& dirs) {
    std::vector<int> keep;
    const int m = static_cast<int>(dirs.cols());
    const Eigen::MatrixXd info =
        icp.information + Eigen::MatrixXd::Identity(m, m) * 1e-12;  // marginals need an inverse
    const Eigen::MatrixXd cov = info.ldlt().solve(Eigen::MatrixXd::Identity(m, m));
    for (int i = 0; i < m; ++i) {
      const double max_sigma =
          IsTranslation(dirs.col(i)) ? limits.max_translation_sigma : limits.max_rotation_sigma;
      if (icp.support[i] >= limits.min_support && std::isfinite(cov(i, i)) &&
          std::sqrt(std::max(cov(i, i), 0.0)) < max_sigma) {
        keep.push_back(i);
      }
    }
    return keep;
  };

  const Pose T_planes = result->T_prev_curr;
  PointToPlaneResult icp = align(D, D.transpose() * result->covariance * D);
  if (!icp.valid) return false;
  std::vector<int> keep = determined(icp, D);
  if (keep.empty()) return false;
  Eigen::MatrixXd Dk = D;
  if (static_cast<int>(keep.size()) < k) {
    // Re-run along the determined directions only, so the others stay exactly at the prior.
    Dk.resize(6, keep.size());
    for (std::size_t i = 0; i < keep.size(); ++i) Dk.col(i) = D.col(keep[i]);
    icp = align(Dk, Dk.transpose() * result->covariance * Dk);
    if (!icp.valid || determined(icp, Dk).size() != keep.size()) return false;
  }
  // A correction the prior finds implausible (beyond its 99.9% region) is more likely a wrong
  // convergence (few facing points, a repetitive structure) than the motion: keep the prior.
  {
    const Vector6d change = BoxMinus(icp.T_prev_curr, T_planes);
    const Eigen::VectorXd y = Dk.transpose() * change;
    const Eigen::MatrixXd prior_y = Dk.transpose() * result->covariance * Dk;
    const double m2 = y.dot(prior_y.ldlt().solve(y));
    if (!(m2 <= Chi2Quantile999(static_cast<double>(y.size())))) return false;
  }
  // Covariance: unchanged outside span(Dk) (the directions are orthonormal), the alignment's
  // posterior inside.
  const Matrix6d P = Dk * Dk.transpose();
  const Matrix6d Q = Matrix6d::Identity() - P;
  Matrix6d cov = Q * result->covariance * Q + Dk * icp.covariance * Dk.transpose();
  cov = 0.5 * (cov + cov.transpose());
  if (!cov.allFinite() || !icp.T_prev_curr.matrix().allFinite()) return false;
  result->T_prev_curr = icp.T_prev_curr;
  result->covariance = cov;
  result->used_icp = true;
  result->used_prior = static_cast<int>(keep.size()) < k;
  result->point_directions = static_cast<int>(keep.size());
  result->prior_directions = k - static_cast<int>(keep.size());
  result->prior_translations = internal::PriorTranslationsAfter(
      result->prior_translations, result->prior_directions, D, keep);
  return true;
}

bool FillDegenerateWithPointToPlane(const datasets::OrganizedCloud& prev,
                                    const datasets::PinholeIntrinsics& K,
                                    const datasets::OrganizedCloud& curr,
                                    const PointToPlaneConfig& config, RegistrationResult* result) {
  const Pose T_planes = result->T_prev_curr;
  const DirectionAligner align = [&](const Eigen::MatrixXd& D, const Eigen::MatrixXd& prior) {
    return AlignPointToPlane(prev, K, curr, T_planes, D, prior, config);
  };
  return FillDegenerateDirections(
      align, {config.min_support, config.max_translation_sigma, config.max_rotation_sigma}, result);
}

}  // namespace planeslam::registration
