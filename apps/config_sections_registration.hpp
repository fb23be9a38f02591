#pragma once
/// Config sections of the registration module: "association" (registration::AssociationConfig),
/// "registration" (registration::RegistrationConfig), "point_to_plane"
/// (registration::PointToPlaneConfig) and "odometry" (the scalar fields of
/// registration::PlaneOdometryConfig; its nested configs come from the three sections above,
/// assembled by OdometryConfigFrom).
#include "config.hpp"
#include "detector_factory.hpp"
#include "planeslam/registration/plane_association.hpp"
#include "planeslam/registration/plane_odometry.hpp"
#include "planeslam/registration/plane_registration.hpp"
#include "planeslam/registration/point_to_plane.hpp"

namespace planeslam::app {

/// The full odometry config: section "odometry" with "association", "registration" and
/// "point_to_plane" filled in.
inline registration::PlaneOdometryConfig OdometryConfigFrom(const Config& config) {
  registration::PlaneOdometryConfig c = config.Get<registration::PlaneOdometryConfig>("odometry");
  c.association = config.Get<registration::AssociationConfig>("association");
  c.registration = config.Get<registration::RegistrationConfig>("registration");
  c.point_to_plane = config.Get<registration::PointToPlaneConfig>("point_to_plane");
  // The depth map weights its points by the sensor's noise model, the detector's.
  const detection::DetectionParams& noise = config.Get<DetectionSection>("detection").params;
  if (noise.sigma0 + noise.sigma_z2 > 0) {
    c.depth_map.sigma0 = noise.sigma0;
    c.depth_map.sigma_z2 = noise.sigma_z2;
  }
  return c;
}

}  // namespace planeslam::app
