// Config sections of the registration module (see config_sections_registration.hpp).
#include "config_sections_registration.hpp"

namespace planeslam::app {
namespace {

void VisitAssociation(FieldVisitor& v, registration::AssociationConfig& c) {
  v.Field("max_normal_angle_deg", c.max_normal_angle_deg,
          "[deg] gate: angle between a previous normal and a current one moved by the prior", 0.01,
          180.0);
  v.Field("max_offset_difference", c.max_offset_difference,
          "[m] gate: |d_prev - d_curr predicted by the prior motion|", 1e-6, 100.0);
  v.Field("max_extent_ratio", c.max_extent_ratio,
          "[-] gate: larger over smaller in-plane extent (partial views change it); 0 = off", 0.0,
          1e6);
  v.Field("pair_angle_tolerance_deg", c.pair_angle_tolerance_deg,
          "[deg] pairwise consistency: the angle between two normals may change this much "
          "between frames (plus 3 sigma of the planes)",
          1e-6, 90.0);
  v.Field("parallel_angle_deg", c.parallel_angle_deg,
          "[deg] pairs this close to (anti)parallel also compare their offset differences", 0.0,
          89.9);
  v.Field("pair_offset_tolerance", c.pair_offset_tolerance,
          "[m] pairwise consistency of (anti)parallel pairs' offset differences (plus 3 sigma)",
          1e-6, 100.0);
  v.Field("flip_max_offset", c.flip_max_offset,
          "[m] current planes closer than this to the sensor are also tried with the opposite "
          "normal (the orientation of a plane through the origin is arbitrary)",
          0.0, 100.0);
  v.Field("max_candidates_per_plane", c.max_candidates_per_plane,
          "[-] best-gated candidates kept per previous plane", 1, 1000);
  v.Field("max_tied_cliques", c.max_tied_cliques,
          "[-] maximum consistent sets of equal size verified for the tie-break", 1, 100000);
  v.Field("max_search_nodes", c.max_search_nodes, "[-] branch-and-bound node budget", 1, 100000000);
  v.Field("inlier_chi2", c.inlier_chi2,
          "[-] verification gate on a match's whitened residual (3 dof; 16.27 = 99.9%)", 1e-6, 1e9);
  v.Field("prior_gate_chi2", c.prior_gate_chi2,
          "[-] a solution this far from the motion prior (6 dof chi^2; 22.46 = 99.9%) loses to one "
          "that agrees with it; 0 = off",
          0.0, 1e9);
}

std::vector<std::string> ValidateAssociation(const registration::AssociationConfig& c) {
  return c.Validate();
}

void VisitRegistration(FieldVisitor& v, registration::RegistrationConfig& c) {
  v.Field("min_normal_sigma", c.min_normal_sigma,
          "[rad] added in quadrature to every plane's normal sigma (systematic errors a fit's "
          "covariance does not model)",
          0.0, 1.0);
  v.Field("min_offset_sigma", c.min_offset_sigma, "[m] same for the plane offset", 0.0, 10.0);
  v.Field("covariance_scale", c.covariance_scale,
          "[-] multiplies the planes' covariances (> 1 when the detector is overconfident)", 1e-9,
          1e9);
  v.Field("fallback_point_sigma", c.fallback_point_sigma,
          "[m] point noise assumed for planes that carry no covariance", 1e-9, 10.0);
  v.Field("max_translation_sigma", c.max_translation_sigma,
          "[m] a translation direction the planes determine worse than this (1 sigma) is "
          "degenerate and taken from the prior / point-to-plane",
          1e-9, 1e3);
  v.Field("max_rotation_sigma", c.max_rotation_sigma, "[rad] same for a rotation axis", 1e-9, 10.0);
  v.Field("min_eigen_ratio", c.min_eigen_ratio,
          "[-] numerical floor: information eigenvalues below this fraction of the largest are "
          "degenerate",
          0.0, 0.999);
  v.Field("max_iterations", c.max_iterations,
          "[-] Gauss-Newton iterations over all matched planes after the closed form", 0, 1000);
  v.Field("convergence_step", c.convergence_step, "[m, rad] stop when the update is below this",
          1e-15, 1.0);
}

std::vector<std::string> ValidateRegistration(const registration::RegistrationConfig& c) {
  return c.Validate();
}

void VisitPointToPlane(FieldVisitor& v, registration::PointToPlaneConfig& c) {
  v.Field("pixel_stride", c.pixel_stride, "[px] use every k-th row and column of the current cloud",
          1, 64);
  v.Field("normal_pixel_step", c.normal_pixel_step,
          "[px] normal from the neighbours at +-this many pixels", 1, 32);
  v.Field("max_neighbour_distance_ratio", c.max_neighbour_distance_ratio,
          "[-] neighbours farther than this fraction of the range from the centre: depth edge, "
          "no normal",
          1e-6, 10.0);
  v.Field("max_correspondence_distance", c.max_correspondence_distance,
          "[m] point pairs farther apart are rejected", 1e-6, 100.0);
  v.Field("huber_delta", c.huber_delta, "[m] Huber threshold on the point-to-plane residual", 1e-9,
          100.0);
  v.Field("point_sigma", c.point_sigma, "[m] floor on the per-pair residual sigma", 1e-9, 10.0);
  v.Field("max_iterations", c.max_iterations, "[-] iterations (re-association each)", 1, 1000);
  v.Field("convergence_step", c.convergence_step, "[m, rad] stop when the update is below this",
          1e-15, 1.0);
  v.Field("min_correspondences", c.min_correspondences, "[-] fewer pairs: no estimate", 1,
          100000000);
  v.Field("min_support", c.min_support,
          "[-] pairs whose normal faces a direction needed before it counts as determined", 0,
          100000000);
  v.Field("max_translation_sigma", c.max_translation_sigma,
          "[m] a translation direction counts as determined by the points below this 1-sigma", 1e-9,
          100.0);
  v.Field("max_rotation_sigma", c.max_rotation_sigma, "[rad] same for a rotation axis", 1e-9, 10.0);
}

std::vector<std::string> ValidatePointToPlane(const registration::PointToPlaneConfig& c) {
  return c.Validate();
}

void VisitOdometry(FieldVisitor& v, registration::PlaneOdometryConfig& c) {
  v.Field("use_point_to_plane", c.use_point_to_plane,
          "fill the planes' degenerate directions by point-to-plane alignment of the clouds "
          "(pinhole clouds; settings in section point_to_plane)");
  v.Field("prior_translation_sigma", c.prior_translation_sigma,
          "[m] constant-velocity prior: change of the per-frame translation (1 sigma)", 1e-9,
          100.0);
  v.Field("prior_rotation_sigma", c.prior_rotation_sigma,
          "[rad] constant-velocity prior: change of the per-frame rotation (1 sigma)", 1e-9, 10.0);
  v.Field("max_prior_gap", c.max_prior_gap,
          "[s] no velocity extrapolation over longer gaps (prior: no motion, weak)", 1e-9, 1e9);
  v.Field("velocity_window", c.velocity_window,
          "[s] the predicted velocity is the mean of the motions of this last span (0 = the last "
          "motion alone)",
          0.0, 1000.0);
  v.Field("systematic_point_sigma", c.systematic_point_sigma,
          "[m] error of a plane's points that does not average out (depth bias, edge pixels): a "
          "narrow plane is uncertain by this over its width (registration; SLAM tracking uses 0)",
          0.0, 1.0);
  v.Field("decimation", c.decimation,
          "[px] detect and register planes on every n-th row and column (1 = full resolution; "
          "Kinect-class depth: 2)",
          1, 16);
}

std::vector<std::string> ValidateOdometry(const registration::PlaneOdometryConfig& c) {
  // Only the scalar fields live in this section; the nested configs are validated by theirs.
  registration::PlaneOdometryConfig scalars;
  scalars.use_point_to_plane = c.use_point_to_plane;
  scalars.prior_translation_sigma = c.prior_translation_sigma;
  scalars.prior_rotation_sigma = c.prior_rotation_sigma;
  scalars.max_prior_gap = c.max_prior_gap;
  scalars.velocity_window = c.velocity_window;
  scalars.systematic_point_sigma = c.systematic_point_sigma;
  scalars.decimation = c.decimation;
  return scalars.Validate();
}

PLANESLAM_REGISTER_CONFIG_SECTION(registration::AssociationConfig, "association",
                                  "Plane association between frames (Pathak et al. 2010: gated "
                                  "candidates, pairwise rigid consistency, maximum clique)",
                                  &VisitAssociation, &ValidateAssociation);
PLANESLAM_REGISTER_CONFIG_SECTION(registration::RegistrationConfig, "registration",
                                  "Motion from matched planes: closed form + Gauss-Newton, "
                                  "covariance, degenerate directions",
                                  &VisitRegistration, &ValidateRegistration);
PLANESLAM_REGISTER_CONFIG_SECTION(registration::PointToPlaneConfig, "point_to_plane",
                                  "Point-to-plane fallback along directions the planes leave "
                                  "undetermined (projective association on the range image)",
                                  &VisitPointToPlane, &ValidatePointToPlane);
PLANESLAM_REGISTER_CONFIG_SECTION(registration::PlaneOdometryConfig, "odometry",
                                  "Frame-to-frame plane odometry (constant-velocity prior)",
                                  &VisitOdometry, &ValidateOdometry);

}  // namespace
}  // namespace planeslam::app
