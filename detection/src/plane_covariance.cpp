#include "planeslam/detection/plane_covariance.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace planeslam::detection {

Eigen::Matrix4d PlaneCovariance(const PlaneMoments& moments, const Eigen::Vector3d& normal,
                                double sigma2) {
  Eigen::Matrix4d cov = Eigen::Matrix4d::Zero();
  const double k = static_cast<double>(moments.count());
  if (k < 1) return cov;
  const Eigen::Vector3d n0 = normal.normalized();
  const Eigen::Matrix3d c = moments.Scatter();
  // Tangent basis: the scatter's two largest eigenvectors, re-orthogonalised against n0 (n0 is
  // the smallest eigenvector up to round-off; this keeps B exactly orthogonal to the given normal).
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(c);
  Eigen::Vector3d b1 = solver.eigenvectors().col(2);
  b1 = (b1 - n0 * n0.dot(b1));
  if (b1.norm() < 1e-6) b1 = n0.unitOrthogonal();
  b1.normalize();
  const Eigen::Vector3d b2 = n0.cross(b1).normalized();
  Eigen::Matrix<double, 3, 2> basis;
  basis.col(0) = b1;
  basis.col(1) = b2;
  // A = B^T C B (diagonal up to round-off when B are eigenvectors; use the full 2x2 anyway).
  Eigen::Matrix2d a = basis.transpose() * c * basis;
  a = 0.5 * (a + a.transpose());
  const double floor = 1e-12;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(a);
  const Eigen::Vector2d ev = es.eigenvalues().cwiseMax(floor);
  const Eigen::Matrix2d a_inv =
      es.eigenvectors() * ev.cwiseInverse().asDiagonal() * es.eigenvectors().transpose();
  const Eigen::Vector2d u = basis.transpose() * moments.Centroid();
  Eigen::Matrix3d cov3;
  cov3.topLeftCorner<2, 2>() = a_inv;
  cov3.topRightCorner<2, 1>() = a_inv * u;
  cov3.bottomLeftCorner<1, 2>() = (a_inv * u).transpose();
  cov3(2, 2) = 1.0 / k + u.dot(a_inv * u);
  cov3 *= std::max(sigma2, 0.0);
  Eigen::Matrix<double, 4, 3> g = Eigen::Matrix<double, 4, 3>::Zero();
  g.topLeftCorner<3, 2>() = basis;
  g(3, 2) = 1.0;
  cov = g * cov3 * g.transpose();
  return 0.5 * (cov + cov.transpose());
}

}  // namespace planeslam::detection
