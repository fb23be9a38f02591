#pragma once
/// Uncertainty of a least-squares plane (n, d) from its moments and the sensor noise.
///
/// Derivation (the Gauss-Newton form of Pathak et al., T-RO 2010, appendix, with equal weights):
/// each point gives a residual r_i = n.p_i - d with variance sigma^2. Parameterise the unit normal
/// on its tangent plane, n = n0 + B a with B = [v2 v3] (the other two eigenvectors of the scatter
/// C, orthonormal and orthogonal to n0), and d = d0 + b. The Jacobian row of r_i is
/// [p_i^T B, -1], so the information of (a, b) is
///   H = 1/sigma^2 [[B^T Q B, -B^T S], [-S^T B, K]],  Q = sum p p^T = C + K m m^T,  S = K m.
/// With u = B^T m and A = B^T C B = diag(l2, l3) the block inverse is closed form:
///   Cov(a)    = sigma^2 A^-1                        (normal tilts: sigma^2 / l2 and / l3)
///   Cov(a, b) = sigma^2 A^-1 u
///   Var(b)    = sigma^2 (1/K + u^T A^-1 u)          (offset: centroid noise + lever arm)
/// and the 4x4 covariance of (n_x, n_y, n_z, d) is G Cov(a, b) G^T with G = [[B, 0], [0, 1]]:
/// symmetric positive semi-definite of rank 3, null along (n0, 0) (the unit-norm constraint),
/// scaling linearly with sigma^2.
#include <Eigen/Core>

#include "planeslam/detection/plane_moments.hpp"

namespace planeslam::detection {

/// Covariance of (n, d) for the plane with unit `normal` fitted to `moments`, with per-point noise
/// variance `sigma2` [m^2] along the normal. Eigenvalues l2, l3 below 1e-12 m^2 are clamped (a
/// degenerate, collinear point set then gets a huge but finite tilt variance).
Eigen::Matrix4d PlaneCovariance(const PlaneMoments& moments, const Eigen::Vector3d& normal,
                                double sigma2);

}  // namespace planeslam::detection
