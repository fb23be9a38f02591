#pragma once
/// Thresholds shared by the region growers (paper: delta, gamma, epsilon, theta, eta) and the two
/// threshold models: the paper's constants, or depth-dependent ones from a sensor noise model.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace planeslam::detection {

enum class ThresholdModel {
  kConstant,  ///< the paper: one gamma, epsilon, delta, eta for the whole image
  kDepth,     ///< scaled by the sensor noise sigma(z) = sigma0 + sigma_z2 z^2 (depth cameras)
};

/// Parses "constant" / "depth"; returns false on anything else.
bool ParseThresholdModel(const std::string& text, ThresholdModel& model);
const char* ToString(ThresholdModel model);

/// Shared thresholds of GBRG and PBRG. Under kConstant the `*_sigmas` factors are ignored and the
/// paper's tests are used unchanged. Under kDepth every threshold gets the sensor noise added.
/// The noise is sigma(z) = sigma0 + sigma_z2 z^2 along the ray (z = depth for a pinhole camera,
/// range for a spherical scanner); what matters for a plane test is its component along the plane
/// normal, sigma_n = sigma(z) |n.p| / z (small on surfaces seen at grazing angles, whose noise lies
/// mostly in the surface), which the moments track exactly (MomentSums::NoiseAlong):
///   gamma(g)   = gamma + gamma_sigmas sigma_n(centre of g)  (a grid's centre of K points is
///                sqrt(K) times less noisy than a point; PBRG tests single points),
///   delta(z)   = delta + delta_sigmas sigma(z),
///   epsilon(R) = (sqrt(epsilon) + (epsilon_sigmas + epsilon_count_sigmas sqrt(2 / K))
///                sigma_n,rms(R))^2 with sigma_n,rms^2 the expected MSE of the region's own K
///                points about its plane (sqrt(2 / K) is the relative spread of the MSE of K
///                points under the model: with epsilon_count_sigmas the bound tightens towards
///                the model's noise as a region grows; 0 by default, as real sensors have
///                roughness the model lacks),
///   eta(g)     = eta + eta_sigmas sigma_n,rms(g) / sqrt(lambda2(g))  (normal noise of a small
///                grid, Var(n) ~ sigma^2 / lambda2 of its scatter; 90 deg or more = no test),
/// and a grid also counts as planar when its MSE is within (planar_sigmas sigma_n,rms)^2 (at 4 m
/// a Kinect's sigma, 2.3 cm, exceeds a 3x3 grid's extent, so the eigenvalue ratio of such a grid
/// is noise, not shape).
struct DetectionParams {
  ThresholdModel model = ThresholdModel::kDepth;
  double eta_deg = 10.0;       ///< max angle between region and grid normals [deg] (eta = cos)
  double gamma = 0.01;         ///< max distance of a grid centre / point to the region plane [m]
  double epsilon = 4e-6;       ///< max region MSE [m^2] (eq. 3); 4e-6 = (2 mm)^2
  double delta = 0.05;         ///< PBRG: max 3D distance between range-image neighbours [m]
  int theta = 400;             ///< min plane size [points]; GBRG uses ceil(theta / k^2) grids
  double sigma0 = 0.0;         ///< sensor noise at zero range [m]
  double sigma_z2 = 1.425e-3;  ///< quadratic depth noise [1/m] (Kinect: Khoshelham & Elberink 2012)
  double gamma_sigmas = 3.0;   ///< depth model: gamma grows by this many sigma(z)
  double delta_sigmas = 8.0;   ///< depth model: delta grows by this many sigma(z)
  double epsilon_sigmas = 1.5;        ///< depth model: sqrt(epsilon) grows by this many sigma_rms
  double epsilon_count_sigmas = 0.0;  ///< depth model: plus this many sqrt(2 / K) (see Epsilon)
  double eta_sigmas = 3.0;            ///< depth model: eta grows by this many normal std devs
  double planar_sigmas =
      1.5;  ///< depth model: grids with rms residual below this many sigma are planar
  bool refine_boundary = true;   ///< give edge pixels of non-planar grids to an adjacent plane
  double refine_sigmas = 3.0;    ///< depth model refinement: max |n.p - d| = this many sigma_n
                                 ///< (constant model: gamma)
  bool merge_regions = true;     ///< merge adjacent regions that describe one surface
  double merge_angle_deg = 5.0;  ///< merge: max angle between the two normals [deg]
  /// Merge also regions that do not touch (a surface seen on both sides of an occluder). Off by
  /// default, as in the paper; on in the Kinect config (the floor on both sides of an object on
  /// it becomes one plane, one landmark for SLAM) and the simulator's (its ground truth counts a
  /// split plane as over-segmented).
  bool merge_disjoint = false;
  /// Final plane of each region fitted along the rays instead of by the paper's eigen fit
  /// (eq. 3-6): weighted least squares of inverse depth 1/s = (n/d).(p/s) over the region's
  /// pixels. A range sensor errs along the ray, so p/s (the pixel's ray) is exact and only 1/s is
  /// noisy: this fit is unbiased, where the eigen fit of a surface seen at a grazing angle is
  /// pulled towards the rays by sigma^2 / lambda2 (with Kinect noise, by up to a degree or so).
  /// Growth is unchanged (the paper's MSE decides every join).
  bool ray_fit = true;

  /// Sensor noise sigma at depth (or range) z [m].
  double Sigma(double z) const { return sigma0 + sigma_z2 * z * z; }
  /// The same in float, for loops over pixels.
  float Sigma(float z) const {
    return static_cast<float>(sigma0) + static_cast<float>(sigma_z2) * z * z;
  }
  double Sigma2(double z) const {
    const double s = Sigma(z);
    return s * s;
  }
  /// Weight of a point in the ray fit: 1 / Var(1/z) = z^4 / sigma(z)^2 (constant for a
  /// Kinect-type sigma = sigma_z2 z^2; 1 when the model has no noise).
  double InverseDepthWeight(double z) const {
    const double s = Sigma(z);
    return s > 0.0 ? (z * z / s) * (z * z / s) : 1.0;
  }
  /// Weight of a pixel at depth (or range) s in the ray fit. A Kinect-type model (sigma0 = 0)
  /// weighs every pixel alike, which spares two divisions per pixel.
  double RayFitWeight(double s) const { return sigma0 == 0.0 ? 1.0 : InverseDepthWeight(s); }
  /// Weight w = (sigma(z) / z)^2 of a point for the noise moment W (MomentSums::Add).
  double NoiseWeight(double z) const {
    const double r = Sigma(z) / z;
    return r * r;
  }
  /// Coplanarity bound for a point or centre whose noise along the normal is `sigma_n` [m].
  double Gamma(double sigma_n) const {
    return model == ThresholdModel::kDepth ? gamma + gamma_sigmas * sigma_n : gamma;
  }
  double Delta(double z) const {
    return model == ThresholdModel::kDepth ? delta + delta_sigmas * Sigma(z) : delta;
  }
  /// MSE bound for a region whose expected MSE under the noise model is `expected_mse` [m^2].
  double Epsilon(double expected_mse, double k) const {
    if (model != ThresholdModel::kDepth) return epsilon;
    const double r =
        std::sqrt(epsilon) + EpsilonSigmas(k) * std::sqrt(std::max(expected_mse, 0.0));
    return r * r;
  }
  /// Depth model: how many rms sigma_n a region of k points may add to sqrt(epsilon) (Epsilon).
  double EpsilonSigmas(double k) const {
    // The count term costs a sqrt on the growers' hot path: only when it is in use.
    return epsilon_count_sigmas > 0.0
               ? epsilon_sigmas + epsilon_count_sigmas * std::sqrt(2.0 / std::max(k, 1.0))
               : epsilon_sigmas;
  }
  /// Problems with the values (empty when fine).
  std::vector<std::string> Validate() const;
};

}  // namespace planeslam::detection
