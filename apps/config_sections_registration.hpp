#pragma once
/// Config sections of the registration module: "association" (registration::AssociationConfig),
/// "registration" (registration::RegistrationConfig), "point_to_plane"
/// (registration::PointToPlaneConfig) and "odometry" (the scalar fields of
/// registration::PlaneOdometryConfig; its nested configs come from the three sections above,
/// assembled by OdometryConfigFrom).
#include "config.hpp"
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
  return c;
}

}  // namespace planeslam::app
