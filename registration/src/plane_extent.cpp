#include "planeslam/registration/plane_extent.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

#include "planeslam/registration/geometry.hpp"
#include "prior_step.hpp"

namespace planeslam::registration {

std::vector<std::string> PlaneExtentConfig::Validate() const {
  std::vector<std::string> p;
  if (!(sigma0 >= 0) || !(sigma_z2 >= 0)) p.push_back("depth noise must be >= 0");
  if (!(occluder_sigmas > 0)) p.push_back("occluder_sigmas must be > 0");
  if (max_dropout_gap < 0) p.push_back("max_dropout_gap must be >= 0");
  if (!(boundary_correlation >= 1)) p.push_back("boundary_correlation must be >= 1");
  if (!(extent_chi2 > 0)) p.push_back("extent_chi2 must be > 0");
  if (!(max_translation_sigma > 0) || !(max_rotation_sigma > 0)) {
    p.push_back("max sigmas must be > 0");
  }
  if (max_iterations < 1) p.push_back("max_iterations must be >= 1");
  return p;
}

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr int kRowStep[4] = {0, 0, 1, -1};
constexpr int kColStep[4] = {1, -1, 0, 0};

/// Depth a noise model is stated in: optical depth for a pinhole grid, range otherwise.
double Depth(const Eigen::Vector3d& p, datasets::SensorModel model) {
  return model == datasets::SensorModel::kPinhole ? p.z() : p.norm();
}

/// Range along the unit ray r to the plane n.p = d, or a non-positive value when the ray runs
/// parallel to it or meets it behind the sensor.
double RangeToPlane(const detection::Plane& plane, const Eigen::Vector3d& r) {
  const double nr = plane.normal.dot(r);
  return std::abs(nr) < 1e-9 ? -1.0 : plane.d / nr;
}

/// Pass 1: complete[i] for plane index i, and per pixel the count of outline edges (0 inside).
/// The border or an occluder cuts a region at once; invalid pixels only when the surface beyond
/// them lies more than max_dropout_gap pixels away from at least 1 in kGapCutShare of the
/// boundary pixels: a pixel left over on a dropped edge looks along the dropped run, which says
/// nothing about the region.
void MarkCompleteness(const datasets::OrganizedCloud& cloud,
                      const std::vector<std::int32_t>& labels,
                      const std::vector<detection::Plane>& planes, const PlaneExtentConfig& config,
                      std::vector<char>* complete, std::vector<std::uint8_t>* edges) {
  constexpr int kGapCutShare = 20;
  const int w = cloud.width, h = cloud.height;
  const int n = static_cast<int>(planes.size());
  complete->assign(planes.size(), 1);
  edges->assign(cloud.points.size(), 0);
  std::vector<int> boundary(planes.size(), 0), gap_cuts(planes.size(), 0);
  // Most regions reach the image border in their first rows: once none is left, stop.
  int left = n;
  for (int row = 0; row < h && left > 0; ++row) {
    for (int col = 0; col < w; ++col) {
      const std::size_t i = static_cast<std::size_t>(row) * w + col;
      const int label = labels[i];
      if (label < 1 || label > n || !(*complete)[label - 1]) continue;
      const detection::Plane& plane = planes[label - 1];
      bool cut = false, gap = false;
      std::uint8_t outline = 0;
      for (int k = 0; k < 4 && !cut; ++k) {
        for (int step = 1; step <= config.max_dropout_gap + 1; ++step) {
          const int r = row + step * kRowStep[k], c = col + step * kColStep[k];
          if (r < 0 || r >= h || c < 0 || c >= w) {  // the image border cuts the region
            cut = true;
            break;
          }
          const std::size_t j = static_cast<std::size_t>(r) * w + c;
          if (labels[j] == label) break;  // inside, or across a hole of the region itself
          if (step == 1) ++outline;
          if (!cloud.IsValid(j)) {
            if (step == config.max_dropout_gap + 1) gap = true;  // too wide to look across
            continue;
          }
          const Eigen::Vector3d q = cloud.points[j].cast<double>();
          const double range = q.norm();
          const double expected = RangeToPlane(plane, q / range);
          if (expected > 0) {
            const double depth = Depth(q, cloud.model);
            const double sigma = config.sigma0 + config.sigma_z2 * depth * depth;
            // In front of the plane's extension by more than the noise: something hides it.
            if ((expected - range) * depth / range > config.occluder_sigmas * sigma) cut = true;
          }
          break;
        }
      }
      if (cut) {
        (*complete)[label - 1] = 0;
        --left;
      }
      (*edges)[i] = outline;
      boundary[label - 1] += outline > 0 ? 1 : 0;
      gap_cuts[label - 1] += gap ? 1 : 0;
    }
  }
  for (int k = 0; k < n; ++k) {
    if (gap_cuts[k] * kGapCutShare > boundary[k]) (*complete)[k] = 0;
  }
}

/// Unit ray of a valid pixel.
Eigen::Vector3d Ray(const datasets::OrganizedCloud& cloud, std::size_t i) {
  return cloud.points[i].cast<double>().normalized();
}

/// Solid angle of pixel (row, col) from its neighbours' rays (forward or backward differences,
/// whichever neighbour is valid); 0 when neither is, in a direction.
double SolidAngle(const datasets::OrganizedCloud& cloud, int row, int col,
                  const Eigen::Vector3d& ray) {
  auto difference = [&](int dr, int dc, Eigen::Vector3d* out) {
    for (const int sign : {1, -1}) {
      const int r = row + sign * dr, c = col + sign * dc;
      if (r < 0 || r >= cloud.height || c < 0 || c >= cloud.width) continue;
      const std::size_t j = static_cast<std::size_t>(r) * cloud.width + c;
      if (!cloud.IsValid(j)) continue;
      *out = sign * (Ray(cloud, j) - ray);
      return true;
    }
    return false;
  };
  Eigen::Vector3d du, dv;
  if (!difference(0, 1, &du) || !difference(1, 0, &dv)) return 0.0;
  return du.cross(dv).norm();
}

struct BoundarySample {
  Eigen::Vector3d x;
  double weight;  ///< a^2 times the number of outline edges of the pixel
};

/// Pass 2 for one complete plane: moments and outline noise from its region's pixels.
struct Accumulator {
  double area = 0.0;
  Eigen::Vector3d first = Eigen::Vector3d::Zero();
  Eigen::Matrix3d second = Eigen::Matrix3d::Zero();
  std::vector<BoundarySample> boundary;
};

void Finish(const detection::Plane& plane, const Accumulator& acc, double kappa,
            PlaneExtent* out) {
  if (!(acc.area > 0)) {
    out->complete = false;
    return;
  }
  const double A = acc.area;
  out->area = A;
  out->centroid = acc.first / A;
  const Eigen::Matrix3d M = acc.second / A - out->centroid * out->centroid.transpose();
  const Eigen::Matrix<double, 3, 2> U = TangentBasis(plane.normal);
  const Eigen::Matrix2d M2 = U.transpose() * M * U;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(0.5 * (M2 + M2.transpose()));
  out->moment_major = eig.eigenvalues()(1);
  out->moment_minor = eig.eigenvalues()(0);
  out->axis_major = (U * eig.eigenvectors().col(1)).normalized();
  out->axis_minor = (U * eig.eigenvectors().col(0)).normalized();
  double var_area = 0.0, var_major = 0.0, var_minor = 0.0, var_cross = 0.0;
  Eigen::Matrix3d cov_c = Eigen::Matrix3d::Zero();
  for (const BoundarySample& b : acc.boundary) {
    const Eigen::Vector3d v = b.x - out->centroid;
    const double u1 = out->axis_major.dot(v), u2 = out->axis_minor.dot(v);
    var_area += b.weight;
    cov_c += b.weight * v * v.transpose();
    var_major += b.weight * (u1 * u1 - out->moment_major) * (u1 * u1 - out->moment_major);
    var_minor += b.weight * (u2 * u2 - out->moment_minor) * (u2 * u2 - out->moment_minor);
    var_cross += b.weight * u1 * u1 * u2 * u2;
  }
  const double scale = kappa / (A * A);
  out->area_variance = kappa * var_area;
  out->centroid_covariance = scale * cov_c;
  out->moment_major_variance = scale * var_major;
  out->moment_minor_variance = scale * var_minor;
  const double gap = out->moment_major - out->moment_minor;
  out->axis_angle_variance = gap > 0 ? scale * var_cross / (gap * gap) : kInf;
}

}  // namespace

std::vector<PlaneExtent> ComputePlaneExtents(const datasets::OrganizedCloud& cloud,
                                             const std::vector<std::int32_t>& labels,
                                             const std::vector<detection::Plane>& planes,
                                             const PlaneExtentConfig& config) {
  std::vector<PlaneExtent> out(planes.size());
  if (planes.empty() || labels.size() != cloud.points.size() || cloud.width < 1) return out;
  std::vector<char> complete;
  std::vector<std::uint8_t> edges;
  MarkCompleteness(cloud, labels, planes, config, &complete, &edges);

  const int n = static_cast<int>(planes.size());
  if (std::none_of(complete.begin(), complete.end(), [](char c) { return c != 0; })) return out;
  std::vector<Accumulator> acc(planes.size());
  for (int row = 0; row < cloud.height; ++row) {
    for (int col = 0; col < cloud.width; ++col) {
      const std::size_t i = static_cast<std::size_t>(row) * cloud.width + col;
      const int label = labels[i];
      if (label < 1 || label > n || !complete[label - 1]) continue;
      PlaneExtent& e = out[label - 1];
      ++e.pixels;
      e.boundary_pixels += edges[i] > 0 ? 1 : 0;
      if (!cloud.IsValid(i)) continue;
      const detection::Plane& plane = planes[label - 1];
      const Eigen::Vector3d ray = Ray(cloud, i);
      const double rho = RangeToPlane(plane, ray);
      const double omega = SolidAngle(cloud, row, col, ray);
      if (!(rho > 0) || !(omega > 0)) continue;
      // Footprint on the plane: the solid angle at range rho, stretched by the incidence.
      const double a = omega * rho * rho / std::abs(plane.normal.dot(ray));
      const Eigen::Vector3d x = rho * ray;
      Accumulator& s = acc[label - 1];
      s.area += a;
      s.first += a * x;
      s.second += a * x * x.transpose();
      if (edges[i] > 0) s.boundary.push_back({x, a * a * edges[i]});
    }
  }
  for (int k = 0; k < n; ++k) {
    out[k].complete = complete[k] && out[k].pixels > 0;
    if (out[k].complete) Finish(planes[k], acc[k], config.boundary_correlation, &out[k]);
  }
  return out;
}

double ExtentMismatchChi2(const PlaneExtent& a, const PlaneExtent& b) {
  if (!a.complete || !b.complete) return kInf;
  auto term = [](double x, double y, double vx, double vy) {
    const double v = vx + vy;
    return v > 0 ? (x - y) * (x - y) / v : ((x == y) ? 0.0 : kInf);
  };
  return term(a.area, b.area, a.area_variance, b.area_variance) +
         term(a.moment_major, b.moment_major, a.moment_major_variance, b.moment_major_variance) +
         term(a.moment_minor, b.moment_minor, a.moment_minor_variance, b.moment_minor_variance);
}

namespace {

using internal::Chi2Quantile999;
using internal::IsTranslation;

/// A matched pair of complete planes: previous and current extents, previous normal.
struct ExtentPair {
  const PlaneExtent* prev;
  const PlaneExtent* curr;
  Eigen::Vector3d normal;
};

/// Residuals of one pair at T (prev <- curr) and their Jacobian over the tangent (dt, dtheta):
/// the centroids' difference in the previous plane (2) and, when the outline is anisotropic
/// enough to carry it, the principal axes' angle about the normal (1; else zero). Whitened.
/// Returns the number of residuals.
int PairResiduals(const ExtentPair& p, const Pose& T, double max_angle_sigma,
                  Eigen::Matrix<double, 3, 1>* r, Eigen::Matrix<double, 3, 6>* J) {
  const Eigen::Matrix3d& R = T.linear();
  const Eigen::Matrix<double, 3, 2> U = TangentBasis(p.normal);
  const Eigen::Vector3d moved = R * p.curr->centroid;
  const Eigen::Vector2d rc = U.transpose() * (p.prev->centroid - moved - T.translation());
  Eigen::Matrix<double, 2, 6> Jc;
  Jc.leftCols<3>() = -U.transpose();
  Jc.rightCols<3>() = U.transpose() * Skew(moved);
  const Eigen::Matrix2d cov = U.transpose() *
                              (p.prev->centroid_covariance +
                               R * p.curr->centroid_covariance * R.transpose()) *
                              U;
  // Whitening by the inverse Cholesky factor of the 2x2 covariance (a tiny ridge for a region
  // of few pixels, whose outline noise may vanish numerically).
  const Eigen::Matrix2d L =
      (cov + Eigen::Matrix2d::Identity() * 1e-12).llt().matrixL().toDenseMatrix();
  const Eigen::Matrix2d Linv = L.inverse();
  r->head<2>() = Linv * rc;
  J->topRows<2>() = Linv * Jc;
  (*r)(2) = 0.0;
  J->row(2).setZero();
  const double var_angle = p.prev->axis_angle_variance + p.curr->axis_angle_variance;
  if (!(var_angle < max_angle_sigma * max_angle_sigma)) return 2;
  const Eigen::Vector3d e = R * p.curr->axis_major;
  double angle = std::atan2(p.normal.dot(e.cross(p.prev->axis_major)), e.dot(p.prev->axis_major));
  // The axis has no sign: the angle is defined modulo pi.
  if (angle > 0.5 * M_PI) angle -= M_PI;
  if (angle < -0.5 * M_PI) angle += M_PI;
  const double sigma = std::sqrt(var_angle);
  (*r)(2) = angle / sigma;
  J->row(2).tail<3>() = -p.normal.transpose() / sigma;
  return 3;
}

struct ExtentSolve {
  Eigen::VectorXd y;
  Eigen::MatrixXd information;  ///< from the pairs alone (k x k)
  Eigen::MatrixXd covariance;   ///< posterior with the prior (k x k)
  std::vector<double> pair_chi2;
  std::vector<int> pair_dof;
  bool valid = false;
};

/// Gauss-Newton over the coefficients y of D (T = BoxPlus(T0, D y)) with the prior N(0, P).
ExtentSolve Solve(const std::vector<ExtentPair>& pairs, const Pose& T0, const Eigen::MatrixXd& D,
                  const Eigen::MatrixXd& P, const PlaneExtentConfig& config) {
  const int k = static_cast<int>(D.cols());
  ExtentSolve s;
  s.y = Eigen::VectorXd::Zero(k);
  const Eigen::MatrixXd P_inv = P.ldlt().solve(Eigen::MatrixXd::Identity(k, k));
  // Axes that turn by more than this between their noise are no angle measurement.
  const double max_angle_sigma = 0.2;
  for (int it = 0; it < config.max_iterations; ++it) {
    const Pose T = BoxPlus(T0, D * s.y);
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(k, k);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(k);
    s.pair_chi2.clear();
    s.pair_dof.clear();
    for (const ExtentPair& p : pairs) {
      Eigen::Matrix<double, 3, 1> r;
      Eigen::Matrix<double, 3, 6> J;
      const int m = PairResiduals(p, T, max_angle_sigma, &r, &J);
      const Eigen::MatrixXd Jy = J * D;
      H += Jy.transpose() * Jy;
      g += Jy.transpose() * r;
      s.pair_chi2.push_back(r.squaredNorm());
      s.pair_dof.push_back(m);
    }
    s.information = H;
    const Eigen::MatrixXd A = H + P_inv;
    const Eigen::VectorXd step = A.ldlt().solve(-(g + P_inv * s.y));
    if (!step.allFinite()) return s;
    s.y += step;
    s.covariance = A.ldlt().solve(Eigen::MatrixXd::Identity(k, k));
    if (step.norm() < 1e-9) break;
  }
  s.valid = s.y.allFinite() && s.covariance.allFinite();
  return s;
}

}  // namespace

bool FillDegenerateFromExtents(const std::vector<detection::Plane>& prev_planes,
                               const std::vector<PlaneExtent>& prev_extents,
                               const std::vector<detection::Plane>& curr_planes,
                               const std::vector<PlaneExtent>& curr_extents,
                               const PlaneExtentConfig& config, RegistrationResult* result) {
  if (!result->converged || !result->degenerate || result->used_icp) return false;
  const int k = static_cast<int>(result->degenerate_directions.size());
  if (k == 0) return false;
  std::vector<ExtentPair> pairs;
  for (const PlaneMatch& m : result->inliers) {
    if (m.prev < 0 || m.curr < 0 || m.prev >= static_cast<int>(prev_extents.size()) ||
        m.curr >= static_cast<int>(curr_extents.size()) ||
        m.prev >= static_cast<int>(prev_planes.size()) ||
        m.curr >= static_cast<int>(curr_planes.size())) {
      continue;
    }
    const PlaneExtent& a = prev_extents[m.prev];
    const PlaneExtent& b = curr_extents[m.curr];
    if (!(ExtentMismatchChi2(a, b) <= config.extent_chi2)) continue;
    pairs.push_back({&a, &b, prev_planes[m.prev].normal});
  }
  if (pairs.empty()) return false;

  Eigen::MatrixXd D(6, k);
  for (int i = 0; i < k; ++i) D.col(i) = result->degenerate_directions[i];
  const Pose T0 = result->T_prev_curr;
  ExtentSolve s = Solve(pairs, T0, D, D.transpose() * result->covariance * D, config);
  if (!s.valid) return false;
  // Directions the pairs alone pin down below the limits.
  std::vector<int> keep;
  {
    const Eigen::MatrixXd info = s.information + Eigen::MatrixXd::Identity(k, k) * 1e-12;
    const Eigen::MatrixXd cov = info.ldlt().solve(Eigen::MatrixXd::Identity(k, k));
    for (int i = 0; i < k; ++i) {
      const double limit =
          IsTranslation(D.col(i)) ? config.max_translation_sigma : config.max_rotation_sigma;
      if (std::isfinite(cov(i, i)) && std::sqrt(std::max(cov(i, i), 0.0)) < limit) {
        keep.push_back(i);
      }
    }
  }
  if (keep.empty()) return false;
  Eigen::MatrixXd Dk(6, keep.size());
  for (std::size_t i = 0; i < keep.size(); ++i) Dk.col(i) = D.col(keep[i]);
  if (static_cast<int>(keep.size()) < k) {
    // Again along the determined directions only, so the others stay exactly the prior's.
    s = Solve(pairs, T0, Dk, Dk.transpose() * result->covariance * Dk, config);
    if (!s.valid) return false;
  }
  // Each pair must agree with the fit, and the correction with the prior.
  for (std::size_t i = 0; i < s.pair_chi2.size(); ++i) {
    if (!(s.pair_chi2[i] <= Chi2Quantile999(s.pair_dof[i]))) return false;
  }
  const Eigen::MatrixXd prior_y = Dk.transpose() * result->covariance * Dk;
  if (!(s.y.dot(prior_y.ldlt().solve(s.y)) <= Chi2Quantile999(static_cast<double>(s.y.size())))) {
    return false;
  }
  const Pose T = BoxPlus(T0, Dk * s.y);
  // Covariance: unchanged outside span(Dk) (the directions are orthonormal), the posterior in it.
  const Matrix6d Q = Matrix6d::Identity() - Dk * Dk.transpose();
  Matrix6d cov = Q * result->covariance * Q + Dk * s.covariance * Dk.transpose();
  cov = 0.5 * (cov + cov.transpose());
  if (!cov.allFinite() || !T.matrix().allFinite()) return false;
  result->T_prev_curr = T;
  result->covariance = cov;
  result->used_icp = true;
  const int filled = static_cast<int>(keep.size());
  result->extent_directions = filled;
  result->prior_directions = std::max(0, result->prior_directions - filled);
  result->prior_translations = internal::PriorTranslationsAfter(
      result->prior_translations, result->prior_directions, D, keep);
  result->used_prior = result->prior_directions > 0;
  return true;
}

}  // namespace planeslam::registration
