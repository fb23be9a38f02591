#include "planeslam/registration/plane_registration.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>

#include "plane_residual.hpp"
#include "planeslam/datasets/errors.hpp"

namespace planeslam::registration {

std::vector<std::string> RegistrationConfig::Validate() const {
  std::vector<std::string> problems;
  if (!(min_normal_sigma >= 0)) problems.push_back("min_normal_sigma must be >= 0");
  if (!(min_offset_sigma >= 0)) problems.push_back("min_offset_sigma must be >= 0");
  if (!(covariance_scale > 0)) problems.push_back("covariance_scale must be > 0");
  if (!(systematic_point_sigma >= 0)) problems.push_back("systematic_point_sigma must be >= 0");
  if (!(fallback_point_sigma > 0)) problems.push_back("fallback_point_sigma must be > 0");
  if (!(max_translation_sigma > 0)) problems.push_back("max_translation_sigma must be > 0");
  if (!(max_rotation_sigma > 0)) problems.push_back("max_rotation_sigma must be > 0");
  if (!(min_eigen_ratio >= 0 && min_eigen_ratio < 1))
    problems.push_back("min_eigen_ratio must be in [0, 1)");
  if (max_iterations < 0) problems.push_back("max_iterations must be >= 0");
  if (!(convergence_step > 0)) problems.push_back("convergence_step must be > 0");
  return problems;
}

namespace {

/// Covariance of (n, d) of a least-squares plane fit to the plane's points (its moments, or its
/// eigenvalues and count) when each errs by sigma2 along the normal.
Eigen::Matrix4d FitCovariance(const detection::Plane& plane, double sigma2) {
  // Linearised least-squares plane fit with isotropic point noise sigma^2: a tilt about the
  // in-plane axis e_k moves points at spread sqrt(lambda_k) (lambda_k = sum of squared distances
  // along e_k), so Var = sigma^2 / lambda_k; the centroid moves by sigma^2 / K along n and
  // d = n.c couples the two (Cov(n, d) = Cov(n) c).
  const Eigen::Vector3d n = plane.normal.allFinite() && plane.normal.norm() > 0.5
                                ? Eigen::Vector3d(plane.normal.normalized())
                                : Eigen::Vector3d::UnitZ();
  Eigen::Matrix3d axes;
  Eigen::Vector3d lambda;
  if (plane.moments.count() >= 3) {
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
    es.computeDirect(plane.moments.Scatter());
    axes = es.eigenvectors();
    lambda = es.eigenvalues();
  } else {
    const Eigen::Matrix<double, 3, 2> u = TangentBasis(n);
    axes << n, u;
    lambda = plane.eigenvalues;
  }
  const double count = static_cast<double>(std::max<std::int64_t>(plane.point_count, 1));
  Eigen::Matrix3d cov_n = Eigen::Matrix3d::Zero();
  constexpr double kUnknownNormalVar = 0.01 * 0.01;  // 0.01 rad when nothing is known
  for (int k = 1; k < 3; ++k) {
    Eigen::Vector3d e = axes.col(k);
    e -= n * n.dot(e);  // keep the covariance orthogonal to n (unit-norm constraint)
    if (e.norm() < 1e-9) continue;
    e.normalize();
    const double var =
        lambda(k) > 1e-12 && std::isfinite(lambda(k)) ? sigma2 / lambda(k) : kUnknownNormalVar;
    cov_n += std::min(var, 1.0) * e * e.transpose();
  }
  const Eigen::Vector3d c =
      plane.centroid.allFinite() ? plane.centroid : Eigen::Vector3d(n * plane.d);
  Eigen::Matrix4d cov = Eigen::Matrix4d::Zero();
  cov.topLeftCorner<3, 3>() = cov_n;
  cov.topRightCorner<3, 1>() = cov_n * c;
  cov.bottomLeftCorner<1, 3>() = (cov_n * c).transpose();
  cov(3, 3) = c.dot(cov_n * c) + sigma2 / count;
  return cov;
}

}  // namespace

Eigen::Matrix4d PlaneCovarianceOrFallback(const detection::Plane& plane,
                                          double fallback_point_sigma) {
  const Eigen::Matrix4d& own = plane.covariance;
  if (own.allFinite() && own.diagonal().sum() > 0.0) return 0.5 * (own + own.transpose());
  const double sigma2 = std::max(std::isfinite(plane.mse) ? plane.mse : 0.0,
                                 fallback_point_sigma * fallback_point_sigma);
  return FitCovariance(plane, sigma2);
}

namespace internal {

bool MakeMatchData(const std::vector<detection::Plane>& prev,
                   const std::vector<detection::Plane>& curr, const PlaneMatch& match,
                   const RegistrationConfig& config, MatchData* out) {
  PLANESLAM_CHECK(match.prev >= 0 && match.prev < static_cast<int>(prev.size()),
                  "match.prev " << match.prev << " out of range " << prev.size());
  PLANESLAM_CHECK(match.curr >= 0 && match.curr < static_cast<int>(curr.size()),
                  "match.curr " << match.curr << " out of range " << curr.size());
  const detection::Plane& a = prev[match.prev];
  const detection::Plane& b = curr[match.curr];
  // A plane without a usable normal is a data condition: it is left out, never a NaN.
  if (!a.normal.allFinite() || !b.normal.allFinite() || !std::isfinite(a.d) ||
      !std::isfinite(b.d) || a.normal.norm() < 0.5 || b.normal.norm() < 0.5) {
    return false;
  }
  MatchData& m = *out;
  m.match = match;
  m.n_a = a.normal.normalized();
  m.d_a = a.d;
  m.n_b = b.normal.normalized();
  m.d_b = b.d;
  if (match.flip_curr) {  // (-n, -d) is the same plane; its covariance is unchanged
    m.n_b = -m.n_b;
    m.d_b = -m.d_b;
  }
  m.cov_a = PlaneCovarianceOrFallback(a, config.fallback_point_sigma) * config.covariance_scale;
  m.cov_b = PlaneCovarianceOrFallback(b, config.fallback_point_sigma) * config.covariance_scale;
  if (config.systematic_point_sigma > 0.0) {
    // An error shared by all K points is not divided by K: the fit covariance of noise s sqrt(K).
    // Only planes whose extent is known (their moments, as the detectors give them).
    const double s2 = config.systematic_point_sigma * config.systematic_point_sigma;
    for (const auto& [plane, cov] : {std::pair{&a, &m.cov_a}, std::pair{&b, &m.cov_b}}) {
      if (plane->moments.count() >= 3) {
        *cov += FitCovariance(*plane, s2 * static_cast<double>(plane->moments.count()));
      }
    }
  }
  m.tangent = TangentBasis(m.n_a);
  return true;
}

Linearized Linearize(const MatchData& m, const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                     const RegistrationConfig& config) {
  Linearized lin;
  const Eigen::Vector3d n_pred = R * m.n_b;
  const Eigen::Matrix<double, 2, 3> ut = m.tangent.transpose();
  // Residual of the measured plane in prev against the current plane moved into prev
  // (geometry.hpp): r = [U^T (n_a - R n_b); d_a - d_b - (R n_b).t]. The normal part is taken in
  // the tangent plane of n_a (2 dof) because the plane covariances are rank 3.
  lin.r.head<2>() = ut * (m.n_a - n_pred);
  lin.r(2) = m.d_a - m.d_b - n_pred.dot(t);
  // With R <- Exp(dtheta) R: R n_b <- R n_b - [R n_b]_x dtheta; with t <- t + dt.
  lin.J.setZero();
  lin.J.block<2, 3>(0, 3) = ut * Skew(n_pred);
  lin.J.block<1, 3>(2, 0) = -n_pred.transpose();
  lin.J.block<1, 3>(2, 3) = t.transpose() * Skew(n_pred);
  // Residual covariance: Sigma_a + J_b Sigma_b J_b^T (first order), projected on the residual
  // basis B = diag(U, 1), plus the configured floors for both planes.
  Pose T = Pose::Identity();
  T.linear() = R;
  T.translation() = t;
  const Eigen::Matrix4d jb = TransformPlaneJacobian(T);
  const Eigen::Matrix4d s = m.cov_a + jb * m.cov_b * jb.transpose();
  Eigen::Matrix<double, 4, 3> b = Eigen::Matrix<double, 4, 3>::Zero();
  b.topLeftCorner<3, 2>() = m.tangent;
  b(3, 2) = 1.0;
  Eigen::Matrix3d sr = b.transpose() * s * b;
  const double fn2 = config.min_normal_sigma * config.min_normal_sigma;
  const double fd2 = config.min_offset_sigma * config.min_offset_sigma;
  sr += Eigen::Vector3d(2 * fn2, 2 * fn2, 2 * fd2).asDiagonal();
  sr = 0.5 * (sr + sr.transpose());
  // A tiny absolute floor keeps noise-free planes (zero covariance) invertible; it only sets
  // the weights, the exact solution does not depend on it.
  sr += Eigen::Matrix3d::Identity() * 1e-18;
  lin.cov = sr;
  return lin;
}

Eigen::Matrix3d ResidualWeight(const Eigen::Matrix3d& cov, const RegistrationConfig& config) {
  const double fn2 = config.min_normal_sigma * config.min_normal_sigma;
  const double fd2 = config.min_offset_sigma * config.min_offset_sigma;
  Eigen::Matrix3d L;
  if (std::min(fn2, fd2) > 1e-12 && Cholesky3(cov, &L)) {
    // Linearize's floors keep every eigenvalue of cov at least 2 min(fn2, fd2): a Cholesky
    // inverse.
    return InverseFromCholesky3(L);
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  es.computeDirect(cov);
  const Eigen::Vector3d ev = es.eigenvalues().cwiseMax(1e-18);
  return es.eigenvectors() * ev.cwiseInverse().asDiagonal() * es.eigenvectors().transpose();
}

}  // namespace internal

namespace {

using internal::Linearized;
using internal::MatchData;

/// Splits R^3 into the eigen-directions of an information matrix H that are determined to better
/// than max_sigma (observable) and the rest (degenerate).
void SplitDirections(const Eigen::Matrix3d& H, double max_sigma, double min_ratio,
                     std::vector<Eigen::Vector3d>* observable,
                     std::vector<Eigen::Vector3d>* degenerate) {
  if (!H.allFinite()) {
    for (int k = 0; k < 3; ++k) degenerate->push_back(Eigen::Vector3d::Unit(k));
    return;
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(0.5 * (H + H.transpose()));
  const Eigen::Vector3d lam = es.eigenvalues();
  const double threshold = std::max(min_ratio * lam(2), 1.0 / (max_sigma * max_sigma));
  // Descending order so the best-determined direction comes first.
  for (int k = 2; k >= 0; --k) {
    if (lam(2) > 0 && lam(k) > threshold) {
      observable->push_back(es.eigenvectors().col(k));
    } else {
      degenerate->push_back(es.eigenvectors().col(k));
    }
  }
}

Matrix6d SanitizedPriorCovariance(const MotionPrior& prior) {
  Matrix6d c = 0.5 * (prior.covariance + prior.covariance.transpose());
  Eigen::SelfAdjointEigenSolver<Matrix6d> es(c);
  if (!c.allFinite() || es.info() != Eigen::Success || !(es.eigenvalues().minCoeff() > 0)) {
    return MotionPrior().covariance;
  }
  return c;
}

struct Accumulated {
  Matrix6d H = Matrix6d::Zero();
  Vector6d g = Vector6d::Zero();
  double chi2 = 0.0;
  double sum_sq_offset = 0.0;
  double sum_sq_angle = 0.0;
};

Accumulated Accumulate(const std::vector<MatchData>& data, const Eigen::Matrix3d& R,
                       const Eigen::Vector3d& t, const RegistrationConfig& config) {
  Accumulated acc;
  for (const MatchData& m : data) {
    const Linearized lin = internal::Linearize(m, R, t, config);
    const Eigen::Matrix3d W = internal::ResidualWeight(lin.cov, config);
    const Eigen::Matrix<double, 6, 3> jtw = lin.J.transpose() * W;
    acc.H.noalias() += jtw * lin.J;
    acc.g.noalias() += jtw * lin.r;
    acc.chi2 += lin.r.dot(W * lin.r);
    acc.sum_sq_offset += lin.r(2) * lin.r(2);
    const double c = std::clamp(m.n_a.dot(R * m.n_b), -1.0, 1.0);
    acc.sum_sq_angle += std::acos(c) * std::acos(c);
  }
  acc.H = 0.5 * (acc.H + acc.H.transpose());
  return acc;
}

Pose MakePose(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Pose T = Pose::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

/// The prior motion, identity when not finite, with its rotation re-orthonormalised so Exp/Log
/// stay exact.
Pose SanitizedPriorPose(const MotionPrior& prior) {
  Pose prior_pose = prior.T_prev_curr;
  if (!prior_pose.matrix().allFinite()) prior_pose = Pose::Identity();
  prior_pose.linear() = Eigen::Quaterniond(prior_pose.linear()).normalized().toRotationMatrix();
  return prior_pose;
}

/// The answer when nothing can be determined: the prior, everything degenerate.
RegistrationResult PriorOnlyResult(const Pose& prior_pose, const Matrix6d& prior_cov) {
  RegistrationResult fallback;
  fallback.T_prev_curr = prior_pose;
  fallback.covariance = prior_cov;
  fallback.degenerate = true;
  fallback.used_prior = true;
  fallback.prior_directions = 6;
  fallback.prior_translations = 3;
  for (int k = 0; k < 6; ++k) fallback.degenerate_directions.push_back(Vector6d::Unit(k));
  return fallback;
}

/// The usable matches in residual form, in the order of `matches`.
std::vector<MatchData> CollectMatchData(const std::vector<detection::Plane>& prev,
                                        const std::vector<detection::Plane>& curr,
                                        const std::vector<PlaneMatch>& matches,
                                        const RegistrationConfig& config) {
  std::vector<MatchData> data;
  data.reserve(matches.size());
  for (const PlaneMatch& match : matches) {
    MatchData m;
    if (internal::MakeMatchData(prev, curr, match, config, &m)) data.push_back(m);
  }
  return data;
}

/// Which translation directions and rotation axes the planes determine, and each match's weight
/// on its normal.
struct Observability {
  std::vector<Eigen::Vector3d> obs_t, null_t, obs_r, null_r;
  std::vector<double> w_normal;  ///< 2 / trace of the normal part of the residual covariance
};

/// Observability from the measured normals in prev (independent of the motion estimate),
/// weighted by the residual covariances at (R, t). Rotation is seen only through normals,
/// translation only through offsets along the normals.
Observability AnalyseObservability(const std::vector<MatchData>& data, const Eigen::Matrix3d& R,
                                   const Eigen::Vector3d& t, const RegistrationConfig& config) {
  Observability o;
  Eigen::Matrix3d h_rot = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d h_trans = Eigen::Matrix3d::Zero();
  o.w_normal.resize(data.size());
  for (std::size_t i = 0; i < data.size(); ++i) {
    const MatchData& m = data[i];
    const Linearized lin = internal::Linearize(m, R, t, config);
    const Eigen::Matrix2d wn = lin.cov.topLeftCorner<2, 2>().inverse();
    const Eigen::Matrix<double, 2, 3> jr = m.tangent.transpose() * Skew(m.n_a);
    h_rot += jr.transpose() * wn * jr;
    h_trans += m.n_a * m.n_a.transpose() / lin.cov(2, 2);
    o.w_normal[i] = 2.0 / lin.cov.topLeftCorner<2, 2>().trace();
  }
  SplitDirections(h_trans, config.max_translation_sigma, config.min_eigen_ratio, &o.obs_t,
                  &o.null_t);
  SplitDirections(h_rot, config.max_rotation_sigma, config.min_eigen_ratio, &o.obs_r, &o.null_r);
  return o;
}

/// Rotation in closed form. With every axis observable: maximise sum w n_a^T R n_b, i.e.
/// R = U diag(1,1,det) V^T from the SVD of M = sum w n_a n_b^T (weighted Kabsch; the determinant
/// fix keeps a proper rotation and also settles the rank-2 case of exactly two distinct normals).
/// With all normals (anti)parallel: the prior rotated minimally so the best plane lines up; the
/// rotation about that normal stays the prior's. Otherwise R is left as it is.
void ClosedFormRotation(const std::vector<MatchData>& data, const Observability& o,
                        Eigen::Matrix3d* R) {
  if (o.null_r.empty()) {
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    for (std::size_t i = 0; i < data.size(); ++i) {
      M += o.w_normal[i] * data[i].n_a * data[i].n_b.transpose();
    }
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
    D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
    const Eigen::Matrix3d r_svd = svd.matrixU() * D * svd.matrixV().transpose();
    if (r_svd.allFinite()) *R = r_svd;
  } else if (o.null_r.size() == 1) {
    const std::vector<double>& w = o.w_normal;
    const std::size_t best = std::max_element(w.begin(), w.end()) - w.begin();
    const Eigen::Quaterniond q =
        Eigen::Quaterniond::FromTwoVectors(*R * data[best].n_b, data[best].n_a);
    if (q.coeffs().allFinite()) *R = q.toRotationMatrix() * *R;
  }
}

/// 6xk bases of the observable (O) and degenerate (N) subspaces; each column is a pure
/// translation or a pure rotation.
void SubspaceBases(const Observability& o, Eigen::MatrixXd* O, Eigen::MatrixXd* N) {
  O->resize(6, o.obs_t.size() + o.obs_r.size());
  N->resize(6, o.null_t.size() + o.null_r.size());
  O->setZero();
  N->setZero();
  int k = 0;
  for (const auto& v : o.obs_t) O->col(k++).head<3>() = v;
  for (const auto& v : o.obs_r) O->col(k++).tail<3>() = v;
  k = 0;
  for (const auto& v : o.null_t) N->col(k++).head<3>() = v;
  for (const auto& v : o.null_r) N->col(k++).tail<3>() = v;
}

/// Translation by weighted least squares on the offsets, only along the observable translation
/// directions; the degenerate ones keep their value: minimise
/// sum w (d_a - d_b - m.(t0 + O_t y))^2 with m = R n_b.
void SolveTranslation(const std::vector<MatchData>& data, const Observability& o,
                      const Eigen::Matrix3d& R, const RegistrationConfig& config,
                      Eigen::Vector3d* t) {
  if (o.obs_t.empty()) return;
  Eigen::MatrixXd ot(3, o.obs_t.size());
  for (std::size_t k = 0; k < o.obs_t.size(); ++k) ot.col(k) = o.obs_t[k];
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const MatchData& m : data) {
    const Linearized lin = internal::Linearize(m, R, *t, config);
    const Eigen::Vector3d n_pred = R * m.n_b;
    const double w = 1.0 / lin.cov(2, 2);
    A += w * n_pred * n_pred.transpose();
    b += w * n_pred * (m.d_a - m.d_b - n_pred.dot(*t));
  }
  const Eigen::MatrixXd a_red = ot.transpose() * A * ot;
  const Eigen::VectorXd y = a_red.ldlt().solve(ot.transpose() * b);
  if (y.allFinite()) *t += ot * y;
}

/// Gauss-Newton over all matched planes, restricted to the observable subspace O; updates
/// (R, t), the iteration count and convergence flag of `res`, and returns the sums at the final
/// estimate.
Accumulated GaussNewton(const std::vector<MatchData>& data, const Eigen::MatrixXd& O,
                        const RegistrationConfig& config, Eigen::Matrix3d* R, Eigen::Vector3d* t,
                        RegistrationResult* res) {
  res->converged = config.max_iterations == 0;
  Accumulated acc = Accumulate(data, *R, *t, config);
  if (O.cols() == 0) {
    res->converged = true;  // nothing to estimate from the planes: the prior is the answer
    return acc;
  }
  for (int it = 0; it < config.max_iterations; ++it) {
    const Eigen::MatrixXd h_red = O.transpose() * acc.H * O;
    const Eigen::VectorXd y = h_red.ldlt().solve(-O.transpose() * acc.g);
    if (!y.allFinite()) break;
    const Vector6d delta = O * y;
    const Pose T_new = BoxPlus(MakePose(*R, *t), delta);
    const Accumulated acc_new = Accumulate(data, T_new.linear(), T_new.translation(), config);
    res->iterations = it + 1;
    if (!(acc_new.chi2 <= acc.chi2 * (1.0 + 1e-12) + 1e-300)) {
      // Not a descent step: the estimate is at the minimum to numerical precision.
      res->converged = true;
      break;
    }
    *R = T_new.linear();
    *t = T_new.translation();
    acc = acc_new;
    if (delta.norm() < config.convergence_step) {
      res->converged = true;
      break;
    }
  }
  return acc;
}

/// Covariance: the planes' inverse information H in the observable subspace O, the prior's
/// marginal in the degenerate one N (they are uncorrelated to first order: a degenerate direction
/// does not move any plane residual).
Matrix6d SubspaceCovariance(const Matrix6d& H, const Eigen::MatrixXd& O, const Eigen::MatrixXd& N,
                            const Matrix6d& prior_cov) {
  Matrix6d cov = Matrix6d::Zero();
  if (O.cols() > 0) {
    const Eigen::MatrixXd h_red = O.transpose() * H * O;
    cov += O * h_red.ldlt().solve(Eigen::MatrixXd::Identity(O.cols(), O.cols())) * O.transpose();
  }
  if (N.cols() > 0) cov += N * (N.transpose() * prior_cov * N) * N.transpose();
  cov = 0.5 * (cov + cov.transpose());
  return cov;
}

/// Fills the pose, covariance, degeneracy and residual statistics of `res`.
void FillResult(const std::vector<MatchData>& data, const Eigen::Matrix3d& R,
                const Eigen::Vector3d& t, const Accumulated& acc, const Matrix6d& cov,
                const Eigen::MatrixXd& N, RegistrationResult* res) {
  res->T_prev_curr = MakePose(R, t);
  res->covariance = cov;
  res->information = acc.H;
  res->degenerate = N.cols() > 0;
  res->used_prior = N.cols() > 0;
  res->prior_directions = static_cast<int>(N.cols());
  for (int k = 0; k < N.cols(); ++k) res->prior_translations += N.col(k).head<3>().norm() > 0.5;
  for (int k = 0; k < N.cols(); ++k) res->degenerate_directions.push_back(N.col(k));
  for (const MatchData& m : data) res->inliers.push_back(m.match);
  const double count = static_cast<double>(data.size());
  res->residual_rms = std::sqrt(acc.sum_sq_offset / count);
  res->normal_residual_rms = std::sqrt(acc.sum_sq_angle / count);
  res->chi2 = acc.chi2;
}

bool AllFinite(const RegistrationResult& res) {
  return res.T_prev_curr.matrix().allFinite() && res.covariance.allFinite() &&
         res.information.allFinite() && std::isfinite(res.chi2);
}

}  // namespace

RegistrationResult RegisterPlanes(const std::vector<detection::Plane>& prev,
                                  const std::vector<detection::Plane>& curr,
                                  const std::vector<PlaneMatch>& matches, const MotionPrior& prior,
                                  const RegistrationConfig& config) {
  return internal::RegisterMatchData(CollectMatchData(prev, curr, matches, config), prior, config);
}

RegistrationResult internal::RegisterMatchData(const std::vector<MatchData>& data,
                                               const MotionPrior& prior,
                                               const RegistrationConfig& config) {
  const Matrix6d prior_cov = SanitizedPriorCovariance(prior);
  const Pose prior_pose = SanitizedPriorPose(prior);
  if (data.empty()) return PriorOnlyResult(prior_pose, prior_cov);

  Eigen::Matrix3d R = prior_pose.linear();
  Eigen::Vector3d t = prior_pose.translation();
  // 1. Observability at the prior; 2. rotation in closed form; 3. translation along the
  // observable directions; 4. Gauss-Newton in the observable subspace; 5. covariance.
  const Observability o = AnalyseObservability(data, R, t, config);
  ClosedFormRotation(data, o, &R);
  Eigen::MatrixXd O, N;
  SubspaceBases(o, &O, &N);
  SolveTranslation(data, o, R, config, &t);
  RegistrationResult res;
  const Accumulated acc = GaussNewton(data, O, config, &R, &t, &res);
  const Matrix6d cov = SubspaceCovariance(acc.H, O, N, prior_cov);
  FillResult(data, R, t, acc, cov, N, &res);
  if (!AllFinite(res)) return PriorOnlyResult(prior_pose, prior_cov);
  return res;
}

double PriorInnovationChi2(const RegistrationResult& result, const MotionPrior& prior) {
  const Vector6d delta = BoxMinus(result.T_prev_curr, prior.T_prev_curr);
  const Matrix6d s = prior.covariance + result.covariance;
  const double chi2 = delta.dot(s.ldlt().solve(delta));
  return std::isfinite(chi2) ? chi2 : std::numeric_limits<double>::infinity();
}

}  // namespace planeslam::registration
